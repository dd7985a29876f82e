#include "engine/state_stream.h"

namespace grains {

void StateWriter::text(const std::string& s) {
  value<uint64_t>(s.size());
  put(s.data(), s.size());
}

void StateWriter::put(const void* data, size_t n) {
  bytes_.append(static_cast<const char*>(data), n);
}

}  // namespace grains
