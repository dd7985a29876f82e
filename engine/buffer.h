// Sizing scratch buffers whose contents are rebuilt on every use.
#pragma once
#include <cstddef>
#include <vector>

namespace grains {

// Resizes v to `size` for contents about to be rewritten: its old contents are not kept. A
// std::vector that grows doubles its capacity, so a buffer one element past its capacity would
// take twice what it needs, and it never gives memory back. Here growth frees the old block
// first and takes 1/16 more than asked (so slow growth from substep to substep reallocates
// rarely), and a capacity more than twice the size (a transient's peak) is given back.
template <class T>
void resize_for_rewrite(std::vector<T>& v, size_t size) {
  if (size > v.capacity() || v.capacity() > 2 * size + 4096) {
    std::vector<T>().swap(v);
    v.reserve(size + size / 16);
  }
  v.resize(size);
}

}  // namespace grains
