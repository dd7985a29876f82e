// Checkpoints of `grains run` (--checkpoint-every N, --resume DIR; docs/output-format.md): the
// run's whole state at the end of a frame, with how the run was started, in one file of its
// output folder. A run killed after it can be continued from it, and the frames it then writes
// are bit for bit those of a run that was never stopped.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "engine/simulation.h"
#include "engine/state_stream.h"

namespace grains {

constexpr const char* kCheckpointFile = "checkpoint.grains";

// How a run was started: what --resume needs to start it again.
struct RunRecord {
  std::string graph;       // the graph file, as an absolute path
  uint64_t graph_hash = 0;  // of the file's bytes: a graph changed since is refused
  std::vector<std::string> sets;  // the --set overrides
  int frames = 0;            // the frames the run was to make
  int checkpoint_every = 0;  // frames between checkpoints
  uint64_t max_points = 0;   // --max-points
};

// A hash of a file's bytes (FNV-1a, 64 bits); throws StateError when it cannot be read.
uint64_t file_hash(const std::string& path);

// Writes dir/checkpoint.grains: the record and the simulation's state. It is written to a
// temporary name, flushed to the disk and renamed over the last one, so a run killed at any
// moment leaves the last whole checkpoint. Throws WriteError when the file cannot be written.
void write_checkpoint(const std::string& dir, const RunRecord& record, const Simulation& sim);

// The checkpoint of dir, read and checked (its version and its checksum); throws StateError.
class Checkpoint {
 public:
  explicit Checkpoint(const std::string& dir);
  const RunRecord& record() const { return record_; }
  int frame() const { return frame_; }  // the frames it had made
  const std::string& path() const { return path_; }
  // Reads the state into a simulation of the record's graph (Simulation::load_state).
  void restore(Simulation& sim) const;

 private:
  std::string path_;
  RunRecord record_;
  int frame_ = 0;
  std::string state_;  // the bytes of the simulation's state
};

}  // namespace grains
