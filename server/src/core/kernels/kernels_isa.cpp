// Compiled once per ISA level (CMake defines TACTILE_ISA and -march).
#include "core/kernels/kernels_impl.hpp"

#define TACTILE_CAT2(a, b) a##b
#define TACTILE_CAT(a, b) TACTILE_CAT2(a, b)

namespace tactile {
extern const KernelTable<float> TACTILE_CAT(kKernelsFloat_, TACTILE_ISA);
extern const KernelTable<double> TACTILE_CAT(kKernelsDouble_, TACTILE_ISA);
const KernelTable<float> TACTILE_CAT(kKernelsFloat_, TACTILE_ISA) = kernel_impl::make_table<float>();
const KernelTable<double> TACTILE_CAT(kKernelsDouble_, TACTILE_ISA) = kernel_impl::make_table<double>();
}  // namespace tactile
