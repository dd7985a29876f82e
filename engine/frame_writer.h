// The output folder of a run (DESIGN §6, docs/output-format.md): the FrameSink that `grains run`
// and `grains cook` hand their frames to.
#pragma once
#include <set>
#include <string>
#include <vector>

#include "engine/frame_sink.h"
#include "engine/vtk_io.h"

namespace grains {

// The VTK collection a writer with the "vtp" format keeps beside its frames (engine/vtk_io.h).
inline constexpr const char* kVtkCollectionFile = "frames.pvd";

// Which files a frame is written as (a graph's output.formats, checked by the loader): "ply"
// (frame_NNNN.ply, DESIGN §6) and "vtp" (frame_NNNN.vtp, VTK XML PolyData, listed with its
// time in frames.pvd).
struct FrameFormats {
  bool ply = true, vtp = false;
  static FrameFormats from(const std::vector<std::string>& names);
};

// Writes into one folder: each written frame's files (FrameFormats), a row of stats.csv, the rows
// of collider_poses.csv (every collider of the solver, as posed at the frame's end;
// engine/collider_poses.h) and, for frames with collision feedback, rows of colliders.csv
// (frame,time,collider,fx,fy,fz,tx,ty,tz). A frame file (and frames.pvd) is written to a
// temporary name and renamed and each CSV row is appended whole or not at all, so a killed run
// leaves only whole frames and rows, and a collection that lists the .vtp frames it wrote.
class FrameWriter : public FrameSink {
 public:
  // Makes the folder and starts stats.csv and collider_poses.csv (their headers), and with vtp an
  // empty frames.pvd. A folder that cannot be made or written in is bad input (LoadError),
  // refused before any frame runs.
  FrameWriter(std::string dir, std::vector<std::string> attributes, bool all_attributes = false,
              FrameFormats formats = {});
  // Continues the folder of a run resumed after frame `after` (grains run --resume): keeps its
  // frames, frames.pvd entries and CSV rows up to that frame, and removes those after it, which
  // the run wrote before it was stopped. A folder without a run's stats.csv is bad input
  // (LoadError).
  static FrameWriter continuing(std::string dir, std::vector<std::string> attributes, int after,
                                FrameFormats formats = {});
  void write(const FrameOutput& frame) override;
  const std::string& dir() const { return dir_; }

 private:
  FrameWriter() = default;
  std::string dir_;
  std::vector<std::string> attributes_;
  bool all_ = false;
  FrameFormats formats_;
  std::vector<VtkDataSet> collection_;  // the .vtp frames written so far, for frames.pvd
  std::set<std::string> meshes_written_;  // mesh colliders whose collider_NAME.obj is written
};

}  // namespace grains
