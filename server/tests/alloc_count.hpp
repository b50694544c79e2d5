// Counts heap allocations, for test and benchmark binaries that check "no
// allocation inside a step". It replaces malloc and its relatives (operator
// new calls malloc), so: include it in exactly one file of such a binary,
// never in a library.
//
// Counted while `alloc_count::all` is set (any thread), or on a thread that
// has set its own `alloc_count::here`.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>

namespace tactile::alloc_count {
inline std::atomic<bool> all{false};
inline thread_local bool here = false;
inline std::atomic<int64_t> count{0};
inline void note() {
  if (here || all.load(std::memory_order_relaxed)) count.fetch_add(1, std::memory_order_relaxed);
}
}  // namespace tactile::alloc_count

extern "C" {
void* __libc_malloc(size_t);
void* __libc_calloc(size_t, size_t);
void* __libc_realloc(void*, size_t);
void* __libc_memalign(size_t, size_t);
void* malloc(size_t n) {
  tactile::alloc_count::note();
  return __libc_malloc(n);
}
void* calloc(size_t n, size_t size) {
  tactile::alloc_count::note();
  return __libc_calloc(n, size);
}
void* realloc(void* p, size_t n) {
  tactile::alloc_count::note();
  return __libc_realloc(p, n);
}
void* memalign(size_t alignment, size_t n) {
  tactile::alloc_count::note();
  return __libc_memalign(alignment, n);
}
void* aligned_alloc(size_t alignment, size_t n) {
  tactile::alloc_count::note();
  return __libc_memalign(alignment, n);
}
int posix_memalign(void** p, size_t alignment, size_t n) {
  tactile::alloc_count::note();
  *p = __libc_memalign(alignment, n);
  return *p ? 0 : 12;  // ENOMEM
}
}
