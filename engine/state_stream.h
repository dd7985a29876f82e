// The binary stream a run's state is checkpointed in (grains run --checkpoint-every, --resume;
// docs/output-format.md "checkpoint.grains"). Values are written as their bytes on this machine
// (little-endian x86-64 and arm64 alike), so a checkpoint is read back bit for bit; a checkpoint
// moves between machines of the same byte order only. Each part of the state opens with a
// named section, which the reader checks, so that a state read by code that writes another
// fails at the part that differs rather than reading garbage.
#pragma once
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "engine/graph.h"

namespace grains {

// A checkpoint that cannot be read: missing, cut short, of another version or another graph.
// Bad input, like a graph that cannot be loaded (exit 2).
struct StateError : LoadError {
  StateError(std::string file, std::string message)
      : LoadError(std::move(file), "", std::move(message)) {}
};

class StateWriter {
 public:
  void section(const char* name) { text(name); }
  template <class T>
  void value(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    put(&v, sizeof(T));
  }
  void text(const std::string& s);
  template <class T>
  void array(const std::vector<T>& a) {
    static_assert(std::is_trivially_copyable_v<T>);
    value<uint64_t>(a.size());
    put(a.data(), a.size() * sizeof(T));
  }
  const std::string& bytes() const { return bytes_; }

 private:
  void put(const void* data, size_t n);  // appends n bytes
  std::string bytes_;
};

class StateReader {
 public:
  // `where` names the source in errors (the checkpoint's path)
  StateReader(std::string bytes, std::string where)
      : bytes_(std::move(bytes)), where_(std::move(where)) {}

  // Reads a section's name and throws unless it is `name`.
  void section(const char* name) {
    const size_t at = pos_;
    const std::string got = text();
    if (got != name)
      fail("expected the section '" + std::string(name) + "' at byte " + std::to_string(at) +
           ", found '" + got.substr(0, 40) + "'");
  }
  template <class T>
  T value() {
    static_assert(std::is_trivially_copyable_v<T>);
    need(sizeof(T));
    T v;
    std::memcpy(&v, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  template <class T>
  void value(T& v) {
    v = value<T>();
  }
  std::string text() {
    const uint64_t n = value<uint64_t>();
    need(n);
    std::string s = bytes_.substr(pos_, n);
    pos_ += n;
    return s;
  }
  template <class T>
  void array(std::vector<T>& a) {
    static_assert(std::is_trivially_copyable_v<T>);
    const uint64_t n = value<uint64_t>();
    if (n > (bytes_.size() - pos_) / sizeof(T)) fail("an array runs past the end of the file");
    a.resize(n);
    if (n) std::memcpy(a.data(), bytes_.data() + pos_, n * sizeof(T));
    pos_ += n * sizeof(T);
  }
  bool done() const { return pos_ == bytes_.size(); }
  [[noreturn]] void fail(const std::string& what) const { throw StateError(where_, what); }

 private:
  void need(uint64_t n) const {
    if (n > bytes_.size() - pos_) fail("cut short at byte " + std::to_string(pos_));
  }
  std::string bytes_;
  std::string where_;
  size_t pos_ = 0;
};

}  // namespace grains
