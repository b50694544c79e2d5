// Picks the kernel table for the best ISA level the CPU runs.
#include <atomic>

#include "core/kernels/kernels.hpp"

namespace tactile {

extern const KernelTable<float> kKernelsFloat_baseline;
extern const KernelTable<double> kKernelsDouble_baseline;
extern const KernelTable<float> kKernelsFloat_v3;
extern const KernelTable<double> kKernelsDouble_v3;
extern const KernelTable<float> kKernelsFloat_v4;
extern const KernelTable<double> kKernelsDouble_v4;

namespace {

enum Isa : int { kBaseline = 0, kV3 = 1, kV4 = 2 };

bool cpu_has(Isa isa) {
  __builtin_cpu_init();
  switch (isa) {
    case kBaseline: return __builtin_cpu_supports("x86-64-v2");
    case kV3: return __builtin_cpu_supports("x86-64-v3");
    case kV4: return __builtin_cpu_supports("x86-64-v4");
  }
  return false;
}

Isa best_isa() {
  if (cpu_has(kV4)) return kV4;
  if (cpu_has(kV3)) return kV3;
  return kBaseline;
}

std::atomic<int>& current() {
  static std::atomic<int> isa{best_isa()};
  return isa;
}

}  // namespace

template <>
const KernelTable<float>& kernels<float>() {
  switch (current().load(std::memory_order_relaxed)) {
    case kV4: return kKernelsFloat_v4;
    case kV3: return kKernelsFloat_v3;
    default: return kKernelsFloat_baseline;
  }
}

template <>
const KernelTable<double>& kernels<double>() {
  switch (current().load(std::memory_order_relaxed)) {
    case kV4: return kKernelsDouble_v4;
    case kV3: return kKernelsDouble_v3;
    default: return kKernelsDouble_baseline;
  }
}

template <>
const KernelTable<float>* kernels_for<float>(std::string_view isa) {
  if ((isa == "baseline" || isa == "v2") && cpu_has(kBaseline)) return &kKernelsFloat_baseline;
  if (isa == "v3" && cpu_has(kV3)) return &kKernelsFloat_v3;
  if (isa == "v4" && cpu_has(kV4)) return &kKernelsFloat_v4;
  return nullptr;
}

template <>
const KernelTable<double>* kernels_for<double>(std::string_view isa) {
  if ((isa == "baseline" || isa == "v2") && cpu_has(kBaseline)) return &kKernelsDouble_baseline;
  if (isa == "v3" && cpu_has(kV3)) return &kKernelsDouble_v3;
  if (isa == "v4" && cpu_has(kV4)) return &kKernelsDouble_v4;
  return nullptr;
}

std::string_view kernel_isa() {
  switch (current().load(std::memory_order_relaxed)) {
    case kV4: return "x86-64-v4 (AVX-512)";
    case kV3: return "x86-64-v3 (AVX2, FMA)";
    default: return "x86-64-v2 (SSE4.2)";
  }
}

bool select_isa(std::string_view name) {
  Isa isa;
  if (name == "baseline" || name == "v2")
    isa = kBaseline;
  else if (name == "v3")
    isa = kV3;
  else if (name == "v4")
    isa = kV4;
  else
    return false;
  if (!cpu_has(isa)) return false;
  current().store(isa, std::memory_order_relaxed);
  return true;
}

}  // namespace tactile
