// Where a run's frames go (DESIGN §6): the program hands each particle object's state at the end
// of every frame to a FrameSink. FrameWriter (engine/frame_writer.h), the PLY frames and the CSV
// files of an output folder, is the one the `run` and `cook` commands use; a test or another
// program may keep frames in memory or send them elsewhere through the same seam.
#pragma once
#include <vector>

#include "engine/collider.h"
#include "engine/particles.h"
#include "engine/simulation.h"

namespace grains {

// One particle object at the end of one frame: what a sink may write.
struct FrameOutput {
  int frame = 0;                                   // Houdini's 1-based $F
  const ParticleStore* points = nullptr;           // the object's points and primitives
  const FrameStats* stats = nullptr;               // the frame's diagnostics (stats.csv)
  const std::vector<ColliderState>* colliders = nullptr;  // the solver's colliders, end pose
  bool write_points = true;  // false: a frame between output.every's, points not kept
};

// The object's state after Simulation::step_frame, for frame `frame`.
inline FrameOutput frame_output(int frame, const SimObject& o, bool write_points) {
  return {frame, &o.pts, &o.stats, &o.colliders, write_points};
}

class FrameSink {
 public:
  virtual ~FrameSink() = default;
  // Takes one frame, in frame order. Throws WriteError when it cannot keep it (a failure of the
  // run, exit 1).
  virtual void write(const FrameOutput& frame) = 0;
};

}  // namespace grains
