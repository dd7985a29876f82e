#include "engine/checkpoint.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "engine/geometry_io.h"

namespace grains {

namespace {

constexpr const char* kMagic = "grains checkpoint";
constexpr uint32_t kVersion = 1;

uint64_t fnv1a(const char* data, size_t n, uint64_t h = 1469598103934665603ULL) {
  for (size_t k = 0; k < n; ++k) {
    h ^= static_cast<unsigned char>(data[k]);
    h *= 1099511628211ULL;
  }
  return h;
}

std::string read_all(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw StateError(path, "no checkpoint there (a run writes one with --checkpoint-every N)");
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  if (!in.good() && !in.eof()) throw StateError(path, std::string("cannot read (") + std::strerror(errno) + ")");
  return ss.str();
}

}  // namespace

uint64_t file_hash(const std::string& path) {
  const std::string bytes = read_all(path);
  return fnv1a(bytes.data(), bytes.size());
}

void write_checkpoint(const std::string& dir, const RunRecord& record, const Simulation& sim) {
  StateWriter w;
  w.text(kMagic);
  w.value(kVersion);
  w.section("run");
  w.text(record.graph);
  w.value(record.graph_hash);
  w.value<uint64_t>(record.sets.size());
  for (const std::string& s : record.sets) w.text(s);
  w.value(record.frames);
  w.value(record.checkpoint_every);
  w.value(record.max_points);
  w.value(sim.frame());
  StateWriter state;
  sim.save_state(state);
  w.text(state.bytes());
  const std::string& bytes = w.bytes();
  const uint64_t sum = fnv1a(bytes.data(), bytes.size());

  const std::string path = dir + "/" + kCheckpointFile, tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) throw WriteError(tmp + ": cannot write (" + std::strerror(errno) + ")");
  auto put = [&](const char* p, size_t n) {
    while (n > 0) {
      const ssize_t k = ::write(fd, p, n);
      if (k < 0 && errno == EINTR) continue;
      if (k <= 0) return false;
      p += k, n -= static_cast<size_t>(k);
    }
    return true;
  };
  bool ok = put(bytes.data(), bytes.size()) &&
            put(reinterpret_cast<const char*>(&sum), sizeof sum) && ::fsync(fd) == 0;
  const int err = errno;
  ok = ::close(fd) == 0 && ok;
  if (!ok || std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = ok ? errno : err;
    std::remove(tmp.c_str());
    throw WriteError(path + ": cannot write (" + std::strerror(e) + ")");
  }
}

Checkpoint::Checkpoint(const std::string& dir) : path_(dir + "/" + kCheckpointFile) {
  std::string bytes = read_all(path_);
  StateWriter head;
  head.text(kMagic);
  if (bytes.compare(0, head.bytes().size(), head.bytes()) != 0)
    throw StateError(path_, "not a grains checkpoint");
  uint64_t sum = 0;
  if (bytes.size() < head.bytes().size() + sizeof sum) throw StateError(path_, "cut short");
  std::memcpy(&sum, bytes.data() + bytes.size() - sizeof sum, sizeof sum);
  bytes.resize(bytes.size() - sizeof sum);
  if (fnv1a(bytes.data(), bytes.size()) != sum)
    throw StateError(path_, "damaged (its checksum does not match its contents)");
  StateReader r(std::move(bytes), path_);
  r.text();
  if (const uint32_t v = r.value<uint32_t>(); v != kVersion)
    r.fail("a checkpoint of version " + std::to_string(v) + "; this grains reads version " +
           std::to_string(kVersion));
  r.section("run");
  record_.graph = r.text();
  r.value(record_.graph_hash);
  const uint64_t sets = r.value<uint64_t>();
  for (uint64_t k = 0; k < sets; ++k) record_.sets.push_back(r.text());
  // paths and overrides are text: a NUL byte in one would cut every message that quotes it
  if (record_.graph.find('\0') != std::string::npos) r.fail("its graph's path holds a NUL byte");
  for (const std::string& s : record_.sets)
    if (s.find('\0') != std::string::npos) r.fail("a --set it recorded holds a NUL byte");
  r.value(record_.frames);
  r.value(record_.checkpoint_every);
  r.value(record_.max_points);
  r.value(frame_);
  state_ = r.text();
  if (!r.done()) r.fail("bytes after the state");
}

void Checkpoint::restore(Simulation& sim) const {
  StateReader r(state_, path_);
  sim.load_state(r);
  if (!r.done()) r.fail("bytes after the simulation's state: written by another version of its nodes");
  if (sim.frame() != frame_) r.fail("its frame count disagrees with its state");
}

}  // namespace grains
