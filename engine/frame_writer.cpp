#include "engine/frame_writer.h"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "engine/collider_poses.h"
#include "engine/geometry_io.h"
#include "engine/graph.h"
#include "engine/mesh_shape.h"

namespace grains {

namespace {

// Appends `text` to the file at `path` (created when `fresh`), all of it or nothing: a failed
// write (disk full, ...) cuts the file back to its old length and throws WriteError.
void append_text(const std::string& path, const std::string& text, bool fresh) {
  std::error_code ec;
  const auto old_size = fresh ? std::uintmax_t(0) : std::filesystem::file_size(path, ec);
  FILE* f = std::fopen(path.c_str(), fresh ? "w" : "a");
  if (!f) throw WriteError(path + ": cannot write (" + std::strerror(errno) + ")");
  bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
  int err = ok ? 0 : errno;
  if (std::fclose(f) != 0 && ok) {
    ok = false;
    err = errno;
  }
  if (ok) return;
  if (!ec) std::filesystem::resize_file(path, old_size, ec);
  throw WriteError(path + ": cannot write (" + std::strerror(err) + ")");
}

std::string format(const char* fmt, auto... args) {
  int n = std::snprintf(nullptr, 0, fmt, args...);
  std::string out(static_cast<size_t>(n), '\0');
  std::snprintf(out.data(), out.size() + 1, fmt, args...);
  return out;
}

// A CSV float as %.<digits>g, but always readable as a float: "0" and "2" become "0.0" and
// "2.0", so a reader that infers column types (pandas) never takes an all-zero or whole-valued
// column for integers. "1e-05", "0.5", "nan" and "inf" stay as they are.
std::string csv_float(double v, int digits) {
  std::string s = format("%.*g", digits, v);
  if (s.find_first_of(".eEnN") == std::string::npos) s += ".0";
  return s;
}

}  // namespace

FrameFormats FrameFormats::from(const std::vector<std::string>& names) {
  FrameFormats f;
  f.ply = f.vtp = false;
  for (const std::string& name : names) {
    f.ply = f.ply || name == "ply";
    f.vtp = f.vtp || name == "vtp";
  }
  return f;
}

FrameWriter::FrameWriter(std::string dir, std::vector<std::string> attributes, bool all,
                         FrameFormats formats)
    : dir_(std::move(dir)), attributes_(std::move(attributes)), all_(all), formats_(formats) {
  // a folder the user named that cannot be made or written in is bad input, refused before any
  // frame runs; a write that fails later (disk full) is a failure of the run
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  if (ec) throw LoadError(dir_, "", "cannot make the output folder (" + ec.message() + ")");
  if (access(dir_.c_str(), W_OK | X_OK) != 0)
    throw LoadError(dir_, "", std::string("cannot write in the output folder (") +
                                  std::strerror(errno) + ")");
  append_text(dir_ + "/stats.csv",
              "frame,time,points,constraints,wall_ms,max_penetration,mean_penetration,max_strain,"
              "kinetic_energy,substeps,error\n",
              true);
  append_text(dir_ + "/" + kColliderPosesFile, collider_poses_header(), true);
  std::filesystem::remove(dir_ + "/colliders.csv", ec);  // written from the first frame with feedback
  if (formats_.vtp) write_pvd(dir_ + "/" + kVtkCollectionFile, collection_);
}

namespace {

// Keeps the header and the rows of a CSV whose first field (the frame) is at most `after`,
// through a temporary file renamed over it.
void keep_rows_up_to(const std::string& path, int after) {
  std::ifstream in(path);
  std::string line, kept;
  for (bool header = true; std::getline(in, line); header = false)
    if (header || std::atoi(line.c_str()) <= after) kept += line + "\n";
  in.close();
  append_text(path + ".tmp", kept, true);
  std::error_code ec;
  std::filesystem::rename(path + ".tmp", path, ec);
  if (ec) throw WriteError(path + ": cannot write (" + ec.message() + ")");
}

}  // namespace

FrameWriter FrameWriter::continuing(std::string dir, std::vector<std::string> attributes,
                                    int after, FrameFormats formats) {
  namespace fs = std::filesystem;
  FrameWriter w;
  w.dir_ = std::move(dir);
  w.attributes_ = std::move(attributes);
  w.formats_ = formats;
  std::error_code ec;
  if (!fs::is_regular_file(w.dir_ + "/stats.csv", ec))
    throw LoadError(w.dir_, "", "not the folder of a run (it has no stats.csv)");
  if (access(w.dir_.c_str(), W_OK | X_OK) != 0)
    throw LoadError(w.dir_, "", std::string("cannot write in the output folder (") +
                                    std::strerror(errno) + ")");
  for (const char* csv : {"stats.csv", kColliderPosesFile, "colliders.csv"})
    if (fs::is_regular_file(w.dir_ + "/" + csv, ec)) keep_rows_up_to(w.dir_ + "/" + csv, after);
  for (const auto& e : fs::directory_iterator(w.dir_, ec)) {
    const std::string name = e.path().filename().string();
    const bool tmp = name.ends_with(".ply.tmp") || name.ends_with(".vtp.tmp");
    const bool frame = name.ends_with(".ply") || name.ends_with(".vtp");
    if (name.starts_with("frame_") && (tmp || (frame && std::atoi(name.c_str() + 6) > after)))
      fs::remove(e.path(), ec);
  }
  // the collection keeps the frames it listed up to `after` (their files are kept above)
  const std::string pvd = w.dir_ + "/" + kVtkCollectionFile;
  fs::remove(pvd + ".tmp", ec);
  if (w.formats_.vtp || fs::exists(pvd, ec)) {
    for (const VtkDataSet& d : read_pvd(pvd))
      if (d.file.starts_with("frame_") && std::atoi(d.file.c_str() + 6) <= after &&
          fs::exists(w.dir_ + "/" + d.file, ec))
        w.collection_.push_back(d);
    write_pvd(pvd, w.collection_);
  }
  return w;
}

void FrameWriter::write(const FrameOutput& out) {
  const FrameStats& s = *out.stats;
  // the poses first: a frame's PLY never exists without them, even when the run is killed
  // and a mesh collider's triangles before its first row (collider_mesh_file)
  if (out.colliders)
    for (const ColliderState& c : *out.colliders)
      if (c.shape.kind == ShapeKind::Mesh && c.shape.mesh && meshes_written_.insert(c.name).second)
        write_obj(dir_ + "/" + collider_mesh_file(c.name), c.shape.mesh->mesh());
  if (out.colliders && !out.colliders->empty())
    append_text(dir_ + "/" + kColliderPosesFile,
                collider_poses_rows(out.frame, s.time, *out.colliders), false);
  if (out.write_points && formats_.ply) {
    char name[64];
    std::snprintf(name, sizeof name, "/frame_%04d.ply", out.frame);
    if (all_)
      write_ply_all(dir_ + name, *out.points);
    else
      write_ply(dir_ + name, *out.points, attributes_);
  }
  // the .vtp, then the collection that lists it: a killed run's frames.pvd names whole files
  if (out.write_points && formats_.vtp) {
    char name[64];
    std::snprintf(name, sizeof name, "frame_%04d.vtp", out.frame);
    write_vtp(dir_ + "/" + name, *out.points, attributes_, all_, s.time);
    collection_.push_back({s.time, name});
    write_pvd(dir_ + "/" + kVtkCollectionFile, collection_);
  }
  append_text(dir_ + "/stats.csv",
              format("%d,%s,%zu,%zu,%.3f,%s,%s,%s,%s,%d,%s\n", s.frame,
                     csv_float(s.time, 6).c_str(), s.points, s.constraints, s.wall_ms,
                     csv_float(s.max_penetration, 6).c_str(),
                     csv_float(s.mean_penetration, 6).c_str(), csv_float(s.max_strain, 6).c_str(),
                     csv_float(s.kinetic_energy, 9).c_str(), s.substeps,
                     csv_float(s.error, 6).c_str()),
              false);
  if (s.colliders.empty()) return;
  const std::string path = dir_ + "/colliders.csv";
  const bool fresh = !std::filesystem::exists(path);
  std::string rows = fresh ? "frame,time,collider,fx,fy,fz,tx,ty,tz\n" : "";
  for (const auto& c : s.colliders)
    rows += format("%d,%s,%s,%s,%s,%s,%s,%s,%s\n", s.frame, csv_float(s.time, 6).c_str(),
                   c.name.c_str(), csv_float(c.force.x, 9).c_str(), csv_float(c.force.y, 9).c_str(),
                   csv_float(c.force.z, 9).c_str(), csv_float(c.torque.x, 9).c_str(),
                   csv_float(c.torque.y, 9).c_str(), csv_float(c.torque.z, 9).c_str());
  append_text(path, rows, fresh);
}

}  // namespace grains
