// Compiled once per ISA level (CMake defines TACTILE_ISA and -march).
//
// The kernels pass 64-byte vectors between inlined internal functions; below
// AVX-512, GCC warns at the end of the file that such a call's ABI differs.
// No such call crosses this file, so the warning says nothing here.
#pragma GCC diagnostic ignored "-Wpsabi"

#include "core/kernels/kernels_impl.hpp"

#define TACTILE_CAT2(a, b) a##b
#define TACTILE_CAT(a, b) TACTILE_CAT2(a, b)

namespace tactile {
extern const KernelTable<float> TACTILE_CAT(kKernelsFloat_, TACTILE_ISA);
extern const KernelTable<double> TACTILE_CAT(kKernelsDouble_, TACTILE_ISA);
const KernelTable<float> TACTILE_CAT(kKernelsFloat_, TACTILE_ISA) = kernel_impl::make_table<float>();
const KernelTable<double> TACTILE_CAT(kKernelsDouble_, TACTILE_ISA) = kernel_impl::make_table<double>();
}  // namespace tactile
