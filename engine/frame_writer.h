// The output folder of a run (DESIGN §6, docs/output-format.md): the FrameSink that `grains run`
// and `grains cook` hand their frames to.
#pragma once
#include <string>
#include <vector>

#include "engine/frame_sink.h"

namespace grains {

// Writes into one folder: frame_NNNN.ply (the points, when the frame keeps them), a row of
// stats.csv, the rows of collider_poses.csv (every collider of the solver, as posed at the frame's
// end; engine/collider_poses.h) and, for frames with collision feedback, rows of colliders.csv
// (frame,time,collider,fx,fy,fz,tx,ty,tz). A PLY is written to a temporary name and renamed and
// each CSV row is appended whole or not at all, so a killed run leaves only whole frames and rows.
class FrameWriter : public FrameSink {
 public:
  // Makes the folder and starts stats.csv and collider_poses.csv (their headers). A folder that
  // cannot be made or written in is bad input (LoadError), refused before any frame runs.
  FrameWriter(std::string dir, std::vector<std::string> attributes, bool all_attributes = false);
  // Continues the folder of a run resumed after frame `after` (grains run --resume): keeps its
  // frames and CSV rows up to that frame, and removes those after it, which the run wrote before
  // it was stopped. A folder without a run's stats.csv is bad input (LoadError).
  static FrameWriter continuing(std::string dir, std::vector<std::string> attributes, int after);
  void write(const FrameOutput& frame) override;
  const std::string& dir() const { return dir_; }

 private:
  FrameWriter() = default;
  std::string dir_;
  std::vector<std::string> attributes_;
  bool all_ = false;
};

}  // namespace grains
