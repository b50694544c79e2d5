// Kernel bodies, included once per ISA by kernels_isa.cpp. See kernels.hpp.
//
// Everything here has internal linkage: each ISA's object file must keep its
// own instantiations, or the linker would fold them into one (ODR) and every
// ISA would run whichever copy it kept. The material math is force-inlined
// for the same reason (TACTILE_INLINE).
//
// The element pass per block of W elements: load the corners' displacements
// (one vector per lane and corner, transposed into lanes), run the material
// math across lanes (GCC vectorises it from the scalar code in
// core/material.hpp), and add the corner forces back (one vector per lane and
// corner). The loads and adds are written per ISA with intrinsics: GCC's
// generic tuning emulates gathers with scalar extracts, and no compiler
// vectorises a scatter whose lanes may share a node. Lanes that share a node
// simply add in turn.
//
// The choices below that move the step by a few per cent are guarded by
// fem_bench --only=passes (each pass) and --only=isas (the step per ISA
// level); docs/perf.md (The element pass) holds their figures, some from
// timing the kernel alone, where such changes stand out of the host's noise.
#pragma once

// GCC 12's intrinsics headers trip -Wmaybe-uninitialized in their own
// _mm*_undefined_* helpers (GCC bug 105593, fixed in 13): silence that one
// warning for the header only. It must be the first include of the file.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>
#pragma GCC diagnostic pop

#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <utility>

#include "core/kernels/kernels.hpp"
#include "core/quadratic.hpp"

// Everything below is internal and inlined: the ABI of 64-byte vector
// arguments (which -Wpsabi warns about below AVX-512) never applies.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"

namespace tactile::kernel_impl {
namespace {

// ---- subnormals ----------------------------------------------------------------

// Whether model M's stress runs the SVD (material.hpp) on some elements.
constexpr bool uses_svd(MaterialModel m) {
  return m == MaterialModel::Corotational || m == MaterialModel::InvertibleStVK;
}

// Subnormal inputs read as zero and subnormal results written as zero (the
// DAZ and FTZ bits of MXCSR) from engage() to the end of the object's life:
// the SVD's Jacobi sweeps drive entries towards zero, and each operation on
// a subnormal number costs a microcode assist (fem_bench --only=invertible;
// docs/perf.md). Engaged only once a pass meets a lane that takes the SVD,
// so that a pass with none computes exactly what the plain model's does
// (docs/accuracy: invertible StVK has StVK's error). MXCSR is per thread;
// the old value comes back on exit.
class FlushSubnormals {
 public:
  FlushSubnormals() = default;
  void engage() {
    if (on_) return;
    saved_ = _mm_getcsr();
    _mm_setcsr(saved_ | kFlushBits);
    on_ = true;
  }
  ~FlushSubnormals() {
    if (on_) _mm_setcsr(saved_);
  }
  FlushSubnormals(const FlushSubnormals&) = delete;
  FlushSubnormals& operator=(const FlushSubnormals&) = delete;

 private:
  static constexpr unsigned kFlushBits = 0x8040;  // FTZ (bit 15), DAZ (bit 6)
  bool on_ = false;
  unsigned saved_ = 0;
};

// ---- corner loads and force adds ---------------------------------------------

// x[3c + i][l] = u[node[c][l]].v[i]: the displacements of every lane's C
// nodes (4 corners, or a quadratic tet's 10 nodes).
template <int C, class Real>
TACTILE_INLINE void load_nodes(const int32_t (*node4)[kLanes<Real>], const Node4<Real>* u, Real (*x)[kLanes<Real>]) {
  [[maybe_unused]] constexpr int W = kLanes<Real>;
  // u0 + id[l]: corner c of lane l (id is 4 x its node, see ElementBlock).
  const Real* u0 = u[0].v;
#pragma GCC unroll 10
  for (int c = 0; c < C; ++c) {
    const int32_t* id = node4[c];
#if defined(__AVX512F__)
    if constexpr (sizeof(Real) == 4) {
      // Chunk k of r[j] is lane 4k + j; a 4x4 transpose per chunk gives x, y, z in lane order.
      // Each half of r[j] is built in 256 bits and the halves joined: one
      // 512-bit insert instead of three (fem_bench --only=isas; docs/perf.md).
      __m512 r[4];
#pragma GCC unroll 4
      for (int j = 0; j < 4; ++j) {
        const __m256 lo =
            _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_load_ps(u0 + id[j])), _mm_load_ps(u0 + id[4 + j]), 1);
        const __m256 hi =
            _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_load_ps(u0 + id[8 + j])), _mm_load_ps(u0 + id[12 + j]), 1);
        r[j] = _mm512_insertf32x8(_mm512_castps256_ps512(lo), hi, 1);
      }
      const __m512d t0 = _mm512_castps_pd(_mm512_unpacklo_ps(r[0], r[1]));  // x0 x1 y0 y1 per chunk
      const __m512d t1 = _mm512_castps_pd(_mm512_unpackhi_ps(r[0], r[1]));  // z0 z1 0 0
      const __m512d t2 = _mm512_castps_pd(_mm512_unpacklo_ps(r[2], r[3]));  // x2 x3 y2 y3
      const __m512d t3 = _mm512_castps_pd(_mm512_unpackhi_ps(r[2], r[3]));  // z2 z3 0 0
      _mm512_store_ps(x[3 * c], _mm512_castpd_ps(_mm512_unpacklo_pd(t0, t2)));
      _mm512_store_ps(x[3 * c + 1], _mm512_castpd_ps(_mm512_unpackhi_pd(t0, t2)));
      _mm512_store_ps(x[3 * c + 2], _mm512_castpd_ps(_mm512_unpacklo_pd(t1, t3)));
    } else {
      // r[j] holds lane j in its low half and lane j + 4 in its high half.
      __m512d r[4];
#pragma GCC unroll 4
      for (int j = 0; j < 4; ++j)
        r[j] =
            _mm512_insertf64x4(_mm512_castpd256_pd512(_mm256_load_pd(u0 + id[j])), _mm256_load_pd(u0 + id[4 + j]), 1);
      const __m512d t0 = _mm512_unpacklo_pd(r[0], r[1]);  // pairs: x0 x1 | z0 z1 | x4 x5 | z4 z5
      const __m512d t1 = _mm512_unpackhi_pd(r[0], r[1]);  // y0 y1 | 0 0 | y4 y5 | 0 0
      const __m512d t2 = _mm512_unpacklo_pd(r[2], r[3]);  // x2 x3 | z2 z3 | x6 x7 | z6 z7
      const __m512d t3 = _mm512_unpackhi_pd(r[2], r[3]);
      const __m512i even = _mm512_setr_epi64(0, 1, 8, 9, 4, 5, 12, 13);
      const __m512i odd = _mm512_setr_epi64(2, 3, 10, 11, 6, 7, 14, 15);
      _mm512_store_pd(x[3 * c], _mm512_permutex2var_pd(t0, even, t2));
      _mm512_store_pd(x[3 * c + 1], _mm512_permutex2var_pd(t1, even, t3));
      _mm512_store_pd(x[3 * c + 2], _mm512_permutex2var_pd(t0, odd, t2));
    }
#elif defined(__AVX2__)
    if constexpr (sizeof(Real) == 4) {
#pragma GCC unroll 2
      for (int h = 0; h < W; h += 8) {
        __m256 r[4];  // lane h + j in the low chunk, h + 4 + j in the high one
#pragma GCC unroll 4
        for (int j = 0; j < 4; ++j)
          r[j] = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_load_ps(u0 + id[h + j])),
                                      _mm_load_ps(u0 + id[h + 4 + j]), 1);
        const __m256d t0 = _mm256_castps_pd(_mm256_unpacklo_ps(r[0], r[1]));
        const __m256d t1 = _mm256_castps_pd(_mm256_unpackhi_ps(r[0], r[1]));
        const __m256d t2 = _mm256_castps_pd(_mm256_unpacklo_ps(r[2], r[3]));
        const __m256d t3 = _mm256_castps_pd(_mm256_unpackhi_ps(r[2], r[3]));
        _mm256_store_ps(x[3 * c] + h, _mm256_castpd_ps(_mm256_unpacklo_pd(t0, t2)));
        _mm256_store_ps(x[3 * c + 1] + h, _mm256_castpd_ps(_mm256_unpackhi_pd(t0, t2)));
        _mm256_store_ps(x[3 * c + 2] + h, _mm256_castpd_ps(_mm256_unpacklo_pd(t1, t3)));
      }
    } else {
#pragma GCC unroll 2
      for (int h = 0; h < W; h += 4) {
        const __m256d r0 = _mm256_load_pd(u0 + id[h]), r1 = _mm256_load_pd(u0 + id[h + 1]);
        const __m256d r2 = _mm256_load_pd(u0 + id[h + 2]), r3 = _mm256_load_pd(u0 + id[h + 3]);
        const __m256d t0 = _mm256_unpacklo_pd(r0, r1), t1 = _mm256_unpackhi_pd(r0, r1);  // x0 x1 | z0 z1; y0 y1 | 0 0
        const __m256d t2 = _mm256_unpacklo_pd(r2, r3), t3 = _mm256_unpackhi_pd(r2, r3);
        _mm256_store_pd(x[3 * c] + h, _mm256_permute2f128_pd(t0, t2, 0x20));
        _mm256_store_pd(x[3 * c + 1] + h, _mm256_permute2f128_pd(t1, t3, 0x20));
        _mm256_store_pd(x[3 * c + 2] + h, _mm256_permute2f128_pd(t0, t2, 0x31));
      }
    }
#else
    for (int l = 0; l < W; ++l) {
      const Real* p = u0 + id[l];
      x[3 * c][l] = p[0];
      x[3 * c + 1][l] = p[1];
      x[3 * c + 2][l] = p[2];
    }
#endif
  }
}

// f[node[c][l]].v[i] += fc[3c + i][l]: one 4-wide add per lane and node,
// its load folded into the add.
template <int C, class Real>
TACTILE_INLINE void add_node_forces(const int32_t (*node4)[kLanes<Real>], const Real (*fc)[kLanes<Real>],
                                    Node4<Real>* f) {
  [[maybe_unused]] constexpr int W = kLanes<Real>;
  Real* f0 = f[0].v;  // f0 + id[l]: corner c of lane l
#pragma GCC unroll 10
  for (int c = 0; c < C; ++c) {
    const int32_t* id = node4[c];
#if defined(__AVX512F__)
    if constexpr (sizeof(Real) == 4) {
      // 4x4 transposes within each 128-bit chunk: chunk k of q[j] is lane 4k + j as (x, y, z, 0).
      const __m512 fx = _mm512_load_ps(fc[3 * c]), fy = _mm512_load_ps(fc[3 * c + 1]);
      const __m512 fz = _mm512_load_ps(fc[3 * c + 2]), zero = _mm512_setzero_ps();
      const __m512d t0 = _mm512_castps_pd(_mm512_unpacklo_ps(fx, fy));
      const __m512d t1 = _mm512_castps_pd(_mm512_unpackhi_ps(fx, fy));
      const __m512d t2 = _mm512_castps_pd(_mm512_unpacklo_ps(fz, zero));
      const __m512d t3 = _mm512_castps_pd(_mm512_unpackhi_ps(fz, zero));
      const __m512 q[4] = {_mm512_castpd_ps(_mm512_unpacklo_pd(t0, t2)), _mm512_castpd_ps(_mm512_unpackhi_pd(t0, t2)),
                           _mm512_castpd_ps(_mm512_unpacklo_pd(t1, t3)), _mm512_castpd_ps(_mm512_unpackhi_pd(t1, t3))};
      auto add = [&](int l, __m128 v) {
        float* p = f0 + id[l];
        _mm_store_ps(p, _mm_add_ps(_mm_load_ps(p), v));
      };
#pragma GCC unroll 4
      for (int j = 0; j < 4; ++j) {
        add(j, _mm512_castps512_ps128(q[j]));
        add(4 + j, _mm512_extractf32x4_ps(q[j], 1));
        add(8 + j, _mm512_extractf32x4_ps(q[j], 2));
        add(12 + j, _mm512_extractf32x4_ps(q[j], 3));
      }
    } else {
      // Pairs within 128-bit chunks, then whole chunks: each 256-bit half of q is one lane.
      const __m512d fx = _mm512_load_pd(fc[3 * c]), fy = _mm512_load_pd(fc[3 * c + 1]);
      const __m512d fz = _mm512_load_pd(fc[3 * c + 2]), zero = _mm512_setzero_pd();
      const __m512d t0 = _mm512_unpacklo_pd(fx, fy), t1 = _mm512_unpackhi_pd(fx, fy);
      const __m512d t2 = _mm512_unpacklo_pd(fz, zero), t3 = _mm512_unpackhi_pd(fz, zero);
      const __m512i lo = _mm512_setr_epi64(0, 1, 8, 9, 2, 3, 10, 11);
      const __m512i hi = _mm512_setr_epi64(4, 5, 12, 13, 6, 7, 14, 15);
      // q[0]: lanes 0, 2; q[1]: 1, 3; q[2]: 4, 6; q[3]: 5, 7.
      const __m512d q[4] = {_mm512_permutex2var_pd(t0, lo, t2), _mm512_permutex2var_pd(t1, lo, t3),
                            _mm512_permutex2var_pd(t0, hi, t2), _mm512_permutex2var_pd(t1, hi, t3)};
      auto add = [&](int l, __m256d v) {
        double* p = f0 + id[l];
        _mm256_store_pd(p, _mm256_add_pd(_mm256_load_pd(p), v));
      };
#pragma GCC unroll 4
      for (int j = 0; j < 4; ++j) {
        const int l = (j & 1) + 4 * (j >> 1);
        add(l, _mm512_castpd512_pd256(q[j]));
        add(l + 2, _mm512_extractf64x4_pd(q[j], 1));
      }
    }
#elif defined(__AVX2__)
    if constexpr (sizeof(Real) == 4) {
#pragma GCC unroll 2
      for (int h = 0; h < W; h += 8) {
        const __m256 fx = _mm256_load_ps(fc[3 * c] + h), fy = _mm256_load_ps(fc[3 * c + 1] + h);
        const __m256 fz = _mm256_load_ps(fc[3 * c + 2] + h), zero = _mm256_setzero_ps();
        const __m256d t0 = _mm256_castps_pd(_mm256_unpacklo_ps(fx, fy));
        const __m256d t1 = _mm256_castps_pd(_mm256_unpackhi_ps(fx, fy));
        const __m256d t2 = _mm256_castps_pd(_mm256_unpacklo_ps(fz, zero));
        const __m256d t3 = _mm256_castps_pd(_mm256_unpackhi_ps(fz, zero));
        const __m256 q[4] = {_mm256_castpd_ps(_mm256_unpacklo_pd(t0, t2)), _mm256_castpd_ps(_mm256_unpackhi_pd(t0, t2)),
                             _mm256_castpd_ps(_mm256_unpacklo_pd(t1, t3)),
                             _mm256_castpd_ps(_mm256_unpackhi_pd(t1, t3))};
        auto add = [&](int l, __m128 v) {
          float* p = f0 + id[h + l];
          _mm_store_ps(p, _mm_add_ps(_mm_load_ps(p), v));
        };
#pragma GCC unroll 4
        for (int j = 0; j < 4; ++j) {
          add(j, _mm256_castps256_ps128(q[j]));
          add(4 + j, _mm256_extractf128_ps(q[j], 1));
        }
      }
    } else {
#pragma GCC unroll 2
      for (int h = 0; h < W; h += 4) {
        const __m256d fx = _mm256_load_pd(fc[3 * c] + h), fy = _mm256_load_pd(fc[3 * c + 1] + h);
        const __m256d fz = _mm256_load_pd(fc[3 * c + 2] + h), zero = _mm256_setzero_pd();
        const __m256d t0 = _mm256_unpacklo_pd(fx, fy), t1 = _mm256_unpackhi_pd(fx, fy);
        const __m256d t2 = _mm256_unpacklo_pd(fz, zero), t3 = _mm256_unpackhi_pd(fz, zero);
        auto add = [&](int l, __m256d v) {
          double* p = f0 + id[h + l];
          _mm256_store_pd(p, _mm256_add_pd(_mm256_load_pd(p), v));
        };
        add(0, _mm256_permute2f128_pd(t0, t2, 0x20));
        add(1, _mm256_permute2f128_pd(t1, t3, 0x20));
        add(2, _mm256_permute2f128_pd(t0, t2, 0x31));
        add(3, _mm256_permute2f128_pd(t1, t3, 0x31));
      }
    }
#else
    for (int l = 0; l < W; ++l) {
      Real* p = f0 + id[l];
      p[0] += fc[3 * c][l];
      p[1] += fc[3 * c + 1][l];
      p[2] += fc[3 * c + 2][l];
    }
#endif
  }
}

// ---- element math ------------------------------------------------------------

// One block's lanes as GCC vector types, for the per-lane sums: written as
// loops, GCC converts psiV to double lane by lane.
template <class Real>
TACTILE_INLINE void load_corners(const ElementBlock<Real>& B, const Node4<Real>* u, Real (*x)[kLanes<Real>]) {
  load_nodes<4, Real>(B.node4, u, x);
}
template <class Real>
TACTILE_INLINE void add_corner_forces(const ElementBlock<Real>& B, const Real (*fc)[kLanes<Real>], Node4<Real>* f) {
  add_node_forces<4, Real>(B.node4, fc, f);
}

template <class Real>
struct LaneVectors;
template <>
struct LaneVectors<float> {
  typedef float RealW __attribute__((vector_size(64)));
  typedef float RealWU __attribute__((vector_size(64), aligned(4)));  // for unaligned loads and stores
  typedef double DoubleW __attribute__((vector_size(128)));
  typedef int32_t MaskW __attribute__((vector_size(64)));  // what RealW <= RealW gives
};
template <>
struct LaneVectors<double> {
  typedef double RealW __attribute__((vector_size(64)));
  typedef double RealWU __attribute__((vector_size(64), aligned(8)));
  typedef double DoubleW __attribute__((vector_size(64)));
  typedef int64_t MaskW __attribute__((vector_size(64)));
};

// F = I + [x1-x0, x2-x0, x3-x0] Dm^-1 for lane l, from corner displacements
// x[3c + i][l]. Working with displacements rather than positions keeps float
// accurate for small strains far from the origin.
template <class Real>
TACTILE_INLINE void deformation_gradient(const ElementBlock<Real>& B, int l, const Real (*x)[kLanes<Real>], Real* F) {
  Real du[3][3];  // du[c][i] = u_{c+1,i} - u_{0,i}
#pragma GCC unroll 16
  for (int c = 0; c < 3; ++c)
#pragma GCC unroll 16
    for (int i = 0; i < 3; ++i) du[c][i] = x[3 * (c + 1) + i][l] - x[i][l];
#pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
#pragma GCC unroll 16
    for (int j = 0; j < 3; ++j)
      F[3 * i + j] = (i == j ? Real(1) : Real(0)) + du[0][i] * B.Dinv[j][l] + du[1][i] * B.Dinv[3 + j][l] +
                     du[2][i] * B.Dinv[6 + j][l];
}

// Lanes the material math runs at once. With AVX2's 16 registers, one
// register's worth: GCC otherwise interleaves a block's two halves and spills.
// Below AVX2 the whole block, which runs no slower there (fem_bench
// --only=isas and --only=passes; docs/perf.md).
#if defined(__AVX2__) && !defined(__AVX512F__)
template <class Real>
inline constexpr int kMathLanes = 32 / int(sizeof(Real));
#else
template <class Real>
inline constexpr int kMathLanes = kLanes<Real>;
#endif

// Where the element pass adds the previous block's corner forces (see
// forces()): after this block's deformation gradients with AVX-512, after
// its stresses below it; each ISA level keeps the place that runs faster on
// it (fem_bench --only=isas; docs/perf.md).
#if defined(__AVX512F__)
inline constexpr bool kAddsAfterF = true;
#else
inline constexpr bool kAddsAfterF = false;
#endif

// A block with at most this many lanes near the floor takes the SVD lane by
// lane, scalar; one with more, across all its lanes at once, paired with the
// next such block (fem_bench --only=invertible; docs/perf.md).
inline constexpr int kScalarNearLanes = 2;

// How many blocks ahead the element pass prefetches (see forces()).
constexpr int32_t kPrefetchBlocks = 4;

// Whether any of a block's W values is above t: one compare and mask test
// per vector, not a chain of scalar adds on every block
// (fem_bench --only=invertible; docs/perf.md).
template <class Real>
TACTILE_INLINE bool any_above(const Real* v, Real t) {
  [[maybe_unused]] constexpr int W = kLanes<Real>;
#if defined(__AVX512F__)
  if constexpr (sizeof(Real) == 4) {
    return _mm512_cmp_ps_mask(_mm512_load_ps(v), _mm512_set1_ps(t), _CMP_GT_OQ) != 0;
  } else {
    return _mm512_cmp_pd_mask(_mm512_load_pd(v), _mm512_set1_pd(t), _CMP_GT_OQ) != 0;
  }
#elif defined(__AVX2__)
  if constexpr (sizeof(Real) == 4) {
    const __m256 tv = _mm256_set1_ps(t);
    return (_mm256_movemask_ps(_mm256_cmp_ps(_mm256_load_ps(v), tv, _CMP_GT_OQ)) |
            _mm256_movemask_ps(_mm256_cmp_ps(_mm256_load_ps(v + 8), tv, _CMP_GT_OQ))) != 0;
  } else {
    const __m256d tv = _mm256_set1_pd(t);
    return (_mm256_movemask_pd(_mm256_cmp_pd(_mm256_load_pd(v), tv, _CMP_GT_OQ)) |
            _mm256_movemask_pd(_mm256_cmp_pd(_mm256_load_pd(v + 4), tv, _CMP_GT_OQ))) != 0;
  }
#else
  bool any = false;
  for (int l = 0; l < W; ++l) any = any || v[l] > t;
  return any;
#endif
}

// ---- the SVD's lanes (invertible StVK and corotational) --------------------------
//
// Both models run a cheap form on every lane (StVK's stress; Newton's polar
// iteration) and flag the lanes that may be near the floor, where only the
// SVD will do (near[l] = 1). Those lanes get their stress and energy from
// material::stress<M>, which runs the SVD. A block with a lane or two near
// takes them one at a time; one with more is held until the next such block
// comes, and the two run the SVD together, two elements in one instruction
// stream (material::Pair): the SVD is a chain of dependent operations, and
// two chains keep the core busy where one leaves it waiting. The functions
// are out of line: inlined, their code slows the element pass on every
// block, also where no lane is near (fem_bench --only=invertible;
// docs/perf.md).

// Whether a flagged lane with deformation F takes the SVD one by one:
// invertible StVK is plain StVK down to the floor, which reaches_floor finds
// exactly, sparing the SVD. Where the SVD runs on a whole block anyway, its
// flagged lanes all take its result (the same as plain StVK's to rounding,
// and the exact test is some 30 operations a lane).
template <MaterialModel M, class T>
TACTILE_INLINE bool takes_svd(const T* F) {
  if constexpr (M == MaterialModel::InvertibleStVK) return material::reaches_floor(F);
  return true;
}

// What one block holds between its stresses and its corner forces.
template <class Real>
struct BlockStress {
  alignas(64) Real F[9][kLanes<Real>];  // deformation gradient per lane: F[3i + j][lane]
  alignas(64) Real P[9][kLanes<Real>];  // V P per lane [N/m^2 m^3]: P[3i + j][lane]
  alignas(64) Real psiV[kLanes<Real>];  // V psi per lane [J]
  alignas(64) Real near[kLanes<Real>];  // 1 where the SVD may be needed, else 0
};

template <class Real>
int count_near(const Real* near) {
  int n = 0;
  for (int l = 0; l < kLanes<Real>; ++l) n += near[l] != Real(0);
  return n;
}

// The flagged lanes of one block, one at a time.
template <class Real, MaterialModel M>
__attribute__((noinline)) void svd_lanes_one_by_one(const Real* V, Real lambda, Real mu, BlockStress<Real>& s) {
  for (int l = 0; l < kLanes<Real>; ++l) {
    if (s.near[l] == Real(0)) continue;
    Real Fl[9], Pl[9];
    for (int k = 0; k < 9; ++k) Fl[k] = s.F[k][l];
    if (!takes_svd<M>(Fl)) continue;
    s.psiV[l] = material::stress<M>(Fl, lambda * V[l], mu * V[l], Pl);
    for (int k = 0; k < 9; ++k) s.P[k][l] = Pl[k];
  }
}

// Every lane of one block through the SVD; the flagged ones keep its result.
template <class Real, MaterialModel M>
__attribute__((noinline)) void svd_lanes_of_block(const Real* V, Real lambda, Real mu, BlockStress<Real>& s) {
  constexpr int W = kLanes<Real>;
#pragma GCC unroll 1
  for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
    for (int l = h; l < h + kMathLanes<Real>; ++l) {
      Real Fl[9], Pl[9];
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) Fl[k] = s.F[k][l];
      const Real psi = material::stress<M>(Fl, lambda * V[l], mu * V[l], Pl);
      const bool take = s.near[l] != Real(0);
      s.psiV[l] = take ? psi : s.psiV[l];
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) s.P[k][l] = take ? Pl[k] : s.P[k][l];
    }
}

// Two blocks' lanes through the SVD at once, lane l of each in one Pair.
template <class Real, MaterialModel M>
__attribute__((noinline)) void svd_lanes_of_pair(const ElementBlock<Real>& A, BlockStress<Real>& s,
                                                 const ElementBlock<Real>& B, BlockStress<Real>& t, Real lambda,
                                                 Real mu) {
  using Two = material::Pair<Real>;
  constexpr int W = kLanes<Real>;
#pragma GCC unroll 1
  for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
    for (int l = h; l < h + kMathLanes<Real>; ++l) {
      Two Fl[9], Pl[9];
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) Fl[k] = Two(s.F[k][l], t.F[k][l]);
      const Two psi = material::stress<M>(Fl, Two(lambda * A.V[l], lambda * B.V[l]), Two(mu * A.V[l], mu * B.V[l]), Pl);
      const bool take_a = s.near[l] != Real(0);
      const bool take_b = t.near[l] != Real(0);
      s.psiV[l] = take_a ? psi.a : s.psiV[l];
      t.psiV[l] = take_b ? psi.b : t.psiV[l];
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) {
        s.P[k][l] = take_a ? Pl[k].a : s.P[k][l];
        t.P[k][l] = take_b ? Pl[k].b : t.P[k][l];
      }
    }
}

// Corotational on lanes away from the floor: R by Newton's polar iteration
// (material::polar_newton_step), every lane at once, until every lane has
// converged; lanes that may be near the floor (may_reach_floor), or that
// have not converged after kPolarSteps, are flagged for the SVD.
template <class Real>
inline constexpr int kPolarSteps = sizeof(Real) == 4 ? 8 : 10;

template <class Real>
TACTILE_INLINE void corotational_stresses(const Real* V, Real lambda, Real mu, BlockStress<Real>& s) {
  constexpr int W = kLanes<Real>;
  alignas(64) Real X[9][W];    // the iterate, per lane
  alignas(64) Real change[W];  // |X_new - X|^2 of the last step, per lane
#pragma GCC unroll 1
  for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
    for (int l = h; l < h + kMathLanes<Real>; ++l) {
      Real Fl[9];
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) Fl[k] = s.F[k][l];
      const Real near = material::may_reach_floor(Fl);
      s.near[l] = near;
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) X[k][l] = near != Real(0) ? (k % 4 == 0 ? Real(1) : Real(0)) : Fl[k];
    }
  constexpr Real kConverged = std::numeric_limits<Real>::epsilon();
  for (int step = 0; step < kPolarSteps<Real>; ++step) {
#pragma GCC unroll 1
    for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
      for (int l = h; l < h + kMathLanes<Real>; ++l) {
        Real Xl[9];
#pragma GCC unroll 16
        for (int k = 0; k < 9; ++k) Xl[k] = X[k][l];
        change[l] = material::polar_newton_step(Xl);
#pragma GCC unroll 16
        for (int k = 0; k < 9; ++k) X[k][l] = Xl[k];
      }
    if (!any_above(change, kConverged)) break;
  }
#pragma GCC unroll 1
  for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
    for (int l = h; l < h + kMathLanes<Real>; ++l) {
      Real Fl[9], Rl[9], Pl[9];
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) {
        Fl[k] = s.F[k][l];
        Rl[k] = X[k][l];
      }
      s.psiV[l] = material::stress_corotational_of(Fl, Rl, lambda * V[l], mu * V[l], Pl);
      s.near[l] = change[l] > kConverged ? Real(1) : s.near[l];
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) s.P[k][l] = Pl[k];
    }
}

// V P and V psi of every lane of a block from its F (s.F), V per lane: the
// cheap form for the SVD models, with their lanes near the floor flagged
// (s.near) for the SVD. P and psi are linear in (lambda, mu) at a fixed
// ratio, so passing (lambda V, mu V) gives V P and V psi. (One volume a lane
// and the group's lambda and mu, rather than lambda V and mu V a lane: 4
// bytes a tet less to stream, and a load fewer; fem_bench --only=passes.)
template <class Real, MaterialModel M>
TACTILE_INLINE void block_stresses(const Real* V, Real lambda, Real mu, BlockStress<Real>& s) {
  constexpr int W = kLanes<Real>;
  if constexpr (M == MaterialModel::Corotational) {
    corotational_stresses(V, lambda, mu, s);
  } else {
#pragma GCC unroll 1
    for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
      for (int l = h; l < h + kMathLanes<Real>; ++l) {
        Real Fl[9], Pl[9];
#pragma GCC unroll 16
        for (int k = 0; k < 9; ++k) Fl[k] = s.F[k][l];
        if constexpr (M == MaterialModel::InvertibleStVK) {
          s.psiV[l] = material::stress_stvk_near(Fl, lambda * V[l], mu * V[l], Pl, s.near[l]);
        } else {
          s.psiV[l] = material::stress<M>(Fl, lambda * V[l], mu * V[l], Pl);
        }
#pragma GCC unroll 16
        for (int k = 0; k < 9; ++k) s.P[k][l] = Pl[k];
      }
  }
}

// [f1 f2 f3] = -V P Dm^-T, f0 = -(f1 + f2 + f3): the corner forces [N] of a
// block's lanes, g[3c + i][lane].
template <class Real>
TACTILE_INLINE void corner_forces(const ElementBlock<Real>& B, const Real (*P)[kLanes<Real>], Real (*g)[kLanes<Real>]) {
  constexpr int W = kLanes<Real>;
#pragma GCC unroll 1
  for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
    for (int l = h; l < h + kMathLanes<Real>; ++l) {
// (Negated products: fused negating multiply-adds, no negation of their own.)
#pragma GCC unroll 16
      for (int i = 0; i < 3; ++i) {
        Real sum = 0;
#pragma GCC unroll 16
        for (int c = 0; c < 3; ++c) {
          const Real fa = -(P[3 * i][l] * B.Dinv[3 * c][l]) - P[3 * i + 1][l] * B.Dinv[3 * c + 1][l] -
                          P[3 * i + 2][l] * B.Dinv[3 * c + 2][l];
          g[3 * (c + 1) + i][l] = fa;
          sum = c == 0 ? fa : sum + fa;
        }
        g[i][l] = -sum;
      }
    }
}

template <class Real, MaterialModel M>
ElasticSums forces(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, Real lambda, Real mu,
                   const Node4<Real>* u, Node4<Real>* f) {
  constexpr int W = kLanes<Real>;
  FlushSubnormals flush;
  using RealW = typename LaneVectors<Real>::RealW;
  using DoubleW = typename LaneVectors<Real>::DoubleW;
  using MaskW = typename LaneVectors<Real>::MaskW;
  // Sums kept per lane across blocks (in double, so that a million elements
  // sum as accurately as a hundred), folded once at the end.
  DoubleW energy = {};
  MaskW inverted = {};
  // Corner forces [N], fc[k][3c + i][lane], of this block (k = b & 1) and
  // the last one before it (block `queued`), whose adds into f wait until
  // this block's math is under way (kAddsAfterF): a block is some 800
  // instructions, more than the core reorders at once, so in block order the
  // adds and the stress math would run one after the other; placed inside
  // the math, they overlap (AVX2 and AVX-512; the SSE4.2 fallback loses a
  // little; fem_bench --only=isas; docs/perf.md). Its adds always come before
  // this block's forces are written, so the two may share a slot.
  alignas(64) Real fc[2][12][W];
  int32_t queued = -1;
  // This block's stresses, and (the SVD's models) a block held for the SVD
  // until the next block that needs it for more than a lane or two comes.
  // (Held by a copy: this block's arrays stay at fixed places on the stack,
  // which the double kernel needs to keep its speed with nothing near the
  // floor; fem_bench --only=invertible.)
  BlockStress<Real> s;
  [[maybe_unused]] BlockStress<Real> held_stress;
  int32_t held = -1;
  // The held block through the SVD (with `other`, or alone), its forces
  // added at once.
  auto finish_held = [&](const ElementBlock<Real>* B, BlockStress<Real>* other) {
    if constexpr (uses_svd(M)) {
      BlockStress<Real>& h = held_stress;
      if (other) {
        svd_lanes_of_pair<Real, M>(blocks[held], h, *B, *other, lambda, mu);
      } else {
        svd_lanes_of_block<Real, M>(blocks[held].V, lambda, mu, h);
      }
      alignas(64) Real g[12][W];
      corner_forces(blocks[held], h.P, g);
      add_corner_forces(blocks[held], g, f);
      energy += __builtin_convertvector(*reinterpret_cast<const RealW*>(h.psiV), DoubleW);
      held = -1;
    }
  };
  for (int32_t b = begin; b < end; ++b) {
    const ElementBlock<Real>& B = blocks[b];
    // The blocks stream in order, but the hardware prefetcher alone leaves
    // the pass waiting on memory once they outgrow the caches. The blocks
    // only: a prefetch per corner node (64 a block) costs more than it saves,
    // and the node arrays stream in order (model.cpp). Non-temporal
    // (prefetchnta): a block is read once a step, and kept out of L2 and L3
    // it leaves them to the node arrays, which the node passes read next.
    // Guarded by fem_bench --large --only=passes (docs/perf.md).
    if (b + kPrefetchBlocks < end) {
      const char* next = reinterpret_cast<const char*>(blocks + b + kPrefetchBlocks);
#pragma GCC unroll 16
      for (size_t o = 0; o < sizeof(ElementBlock<Real>); o += 64) __builtin_prefetch(next + o, 0, 0);
    }
    alignas(64) Real x[12][W];  // corner displacements [m]: x[3c + i][lane]
    alignas(64) Real J[W];      // det F per lane
    load_corners(B, u, x);
// Per-lane outputs and no OpenMP pragma: GCC's `omp simd` would keep F and
// P in memory as per-lane arrays; its plain vectoriser does far better.
#pragma GCC unroll 1
    for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
      for (int l = h; l < h + kMathLanes<Real>; ++l) {
        Real Fl[9];
        deformation_gradient(B, l, x, Fl);
        if constexpr (!can_invert(M)) J[l] = material::det(Fl);
#pragma GCC unroll 16
        for (int k = 0; k < 9; ++k) s.F[k][l] = Fl[k];
      }
    if (kAddsAfterF && queued >= 0) add_corner_forces(blocks[queued], fc[queued & 1], f);
    block_stresses<Real, M>(B.V, lambda, mu, s);
    if constexpr (uses_svd(M)) {
      if (any_above(s.near, Real(0))) {
        flush.engage();
        if (count_near(s.near) <= kScalarNearLanes) {
          svd_lanes_one_by_one<Real, M>(B.V, lambda, mu, s);
        } else if (held < 0) {
          // Held for a partner; its forces come with the partner's SVD.
          if (kAddsAfterF) queued = -1;
          held = b;
          held_stress = s;
          continue;
        } else {
          finish_held(&B, &s);
        }
      }
    }
    if (queued >= 0 && !kAddsAfterF) add_corner_forces(blocks[queued], fc[queued & 1], f);
    corner_forces(B, s.P, fc[b & 1]);
    queued = b;
    energy += __builtin_convertvector(*reinterpret_cast<const RealW*>(s.psiV), DoubleW);
    if constexpr (!can_invert(M)) inverted -= *reinterpret_cast<const RealW*>(J) <= Real(0);  // true is -1
  }
  if (queued >= 0) add_corner_forces(blocks[queued], fc[queued & 1], f);
  if (held >= 0) finish_held(nullptr, nullptr);  // (never for the other models)
  ElasticSums sums;
  for (int l = 0; l < W; ++l) {
    sums.energy += energy[l];
    sums.inverted += int32_t(inverted[l]);
  }
  return sums;
}

// ---- quadratic tets (core/quadratic.hpp) ---------------------------------------------------
//
// Per block: the ten nodes' displacements of every lane, then per quadrature
// point q, across lanes, D = sum_a x_a g_aq^T with g_aq the reference
// gradients (constants: the multiplications by 0 and 1 fold away),
// F = I + D Dm^-1, the stress of V/4 (each point stands for a quarter of a
// straight tet), and the nodes' forces f_a -= (P Dm^-T) g_aq. The models
// without the SVD run the four points in one pass across lanes; the SVD's
// take each point as the linear kernel takes a block, the SVD on the lanes
// flagged near the floor only (fem_bench --only=quadratic; docs/perf.md).

// One quadrature point q of a block: F per lane from the nodes'
// displacements x (F = I + D Dm^-1, D = sum_a x_a g_aq^T).
template <class Real, int q>
TACTILE_INLINE void quadratic_point_gradient(const QuadraticBlock<Real>& B, int l, const Real (*x)[kLanes<Real>],
                                             Real* F) {
  Real D[9] = {};
#pragma GCC unroll 10
  for (int a = 0; a < 10; ++a)
#pragma GCC unroll 3
    for (int k = 0; k < 3; ++k) {
      const double g = kP2PointGradients.g[q][a][k];
      if (g == 0) continue;
#pragma GCC unroll 3
      for (int i = 0; i < 3; ++i) D[3 * i + k] += x[3 * a + i][l] * Real(g);
    }
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i)
#pragma GCC unroll 3
    for (int j = 0; j < 3; ++j)
      F[3 * i + j] = (i == j ? Real(1) : Real(0)) + D[3 * i] * B.Dinv[j][l] + D[3 * i + 1] * B.Dinv[3 + j][l] +
                     D[3 * i + 2] * B.Dinv[6 + j][l];
}

// The nodes' forces of point q from its stress P (already times V/4):
// f_a -= (P Dm^-T) g_aq, into fl[3a + i].
template <class Real, int q>
TACTILE_INLINE void quadratic_point_forces(const QuadraticBlock<Real>& B, int l, const Real* P, Real* fl) {
  Real H[9];  // P Dm^-T
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i)
#pragma GCC unroll 3
    for (int k = 0; k < 3; ++k)
      H[3 * i + k] =
          P[3 * i] * B.Dinv[3 * k][l] + P[3 * i + 1] * B.Dinv[3 * k + 1][l] + P[3 * i + 2] * B.Dinv[3 * k + 2][l];
#pragma GCC unroll 10
  for (int a = 0; a < 10; ++a)
#pragma GCC unroll 3
    for (int k = 0; k < 3; ++k) {
      const double g = kP2PointGradients.g[q][a][k];
      if (g == 0) continue;
#pragma GCC unroll 3
      for (int i = 0; i < 3; ++i) fl[3 * a + i] -= H[3 * i + k] * Real(g);
    }
}

// A quadratic block's lane of a model without the SVD: the four points in
// one pass, F and P in registers.
template <class Real, MaterialModel M, int q = 0>
TACTILE_INLINE void quadratic_points_plain(const QuadraticBlock<Real>& B, int l, const Real (*x)[kLanes<Real>], Real lq,
                                           Real mq, Real* fl, Real& e, Real& neg) {
  Real F[9], P[9];
  quadratic_point_gradient<Real, q>(B, l, x, F);
  if constexpr (!can_invert(M)) neg = material::det(F) <= Real(0) ? Real(1) : neg;
  e += material::stress<M>(F, lq, mq, P);
  quadratic_point_forces<Real, q>(B, l, P, fl);
  if constexpr (q < 3) quadratic_points_plain<Real, M, q + 1>(B, l, x, lq, mq, fl, e, neg);
}

// A quadratic block of an SVD model, point by point as the linear kernel
// takes a block: the cheap form on every lane (StVK's stress below the
// floor, Newton's polar iteration), the SVD on the lanes flagged only.
template <class Real, MaterialModel M, int q = 0>
TACTILE_INLINE void quadratic_points_svd(const QuadraticBlock<Real>& B, const Real (*x)[kLanes<Real>], const Real* Vq,
                                         Real lambda, Real mu, Real (*fc)[kLanes<Real>], Real* psiV,
                                         FlushSubnormals& flush) {
  constexpr int W = kLanes<Real>;
  BlockStress<Real> s;
#pragma GCC unroll 1
  for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
    for (int l = h; l < h + kMathLanes<Real>; ++l) {
      Real Fl[9];
      quadratic_point_gradient<Real, q>(B, l, x, Fl);
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) s.F[k][l] = Fl[k];
    }
  block_stresses<Real, M>(Vq, lambda, mu, s);
  if (any_above(s.near, Real(0))) {
    flush.engage();
    if (count_near(s.near) <= kScalarNearLanes) {
      svd_lanes_one_by_one<Real, M>(Vq, lambda, mu, s);
    } else {
      svd_lanes_of_block<Real, M>(Vq, lambda, mu, s);
    }
  }
#pragma GCC unroll 1
  for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
    for (int l = h; l < h + kMathLanes<Real>; ++l) {
      Real Pl[9], fl[30];
#pragma GCC unroll 16
      for (int k = 0; k < 9; ++k) Pl[k] = s.P[k][l];
#pragma GCC unroll 30
      for (int k = 0; k < 30; ++k) fl[k] = fc[k][l];
      quadratic_point_forces<Real, q>(B, l, Pl, fl);
#pragma GCC unroll 30
      for (int k = 0; k < 30; ++k) fc[k][l] = fl[k];
      psiV[l] += s.psiV[l];
    }
  if constexpr (q < 3) quadratic_points_svd<Real, M, q + 1>(B, x, Vq, lambda, mu, fc, psiV, flush);
}

template <class Real, MaterialModel M>
ElasticSums quadratic_forces(const QuadraticBlock<Real>* blocks, int32_t begin, int32_t end, Real lambda, Real mu,
                             const Node4<Real>* u, Node4<Real>* f) {
  constexpr int W = kLanes<Real>;
  FlushSubnormals flush;
  double energy = 0;
  int32_t inverted = 0;
  for (int32_t b = begin; b < end; ++b) {
    const QuadraticBlock<Real>& B = blocks[b];
    if (b + kPrefetchBlocks < end) {
      const char* next = reinterpret_cast<const char*>(blocks + b + kPrefetchBlocks);
#pragma GCC unroll 16
      for (size_t o = 0; o < sizeof(QuadraticBlock<Real>); o += 64) __builtin_prefetch(next + o, 0, 0);
    }
    alignas(64) Real x[30][W];   // node displacements [m]: x[3a + i][lane]
    alignas(64) Real fc[30][W];  // node forces [N]
    alignas(64) Real psiV[W];
    alignas(64) Real bad[W];
    load_nodes<10, Real>(B.node4, u, x);
    if constexpr (uses_svd(M)) {
      alignas(64) Real Vq[W];  // each point stands for a quarter of the volume
      for (int l = 0; l < W; ++l) {
        Vq[l] = Real(0.25) * B.V[l];
        psiV[l] = 0;
        bad[l] = 0;
        for (int k = 0; k < 30; ++k) fc[k][l] = 0;
      }
      quadratic_points_svd<Real, M>(B, x, Vq, lambda, mu, fc, psiV, flush);
    } else {
#pragma GCC unroll 1
      for (int h = 0; h < W; h += kMathLanes<Real>)
#pragma GCC ivdep
        for (int l = h; l < h + kMathLanes<Real>; ++l) {
          Real fl[30] = {};
          Real e = 0, neg = 0;
          quadratic_points_plain<Real, M>(B, l, x, lambda * Real(0.25) * B.V[l], mu * Real(0.25) * B.V[l], fl, e, neg);
#pragma GCC unroll 30
          for (int k = 0; k < 30; ++k) fc[k][l] = fl[k];
          psiV[l] = e;
          bad[l] = neg;
        }
    }
    add_node_forces<10, Real>(B.node4, fc, f);
    for (int l = 0; l < W; ++l) {
      energy += double(psiV[l]);
      inverted += bad[l] != Real(0);
    }
  }
  return {energy, inverted};
}

// x[3c + i][l] = u[3 node + i] for displacements u in the state's layout
// (n x 3): for the passes that are not hot (energies, the critical step).
template <class Real>
TACTILE_INLINE void gather_corners(const ElementBlock<Real>& B, const Real* u, Real (*x)[kLanes<Real>]) {
  for (int c = 0; c < 4; ++c)
    for (int l = 0; l < kLanes<Real>; ++l)
      for (int i = 0; i < 3; ++i) x[3 * c + i][l] = u[3 * int64_t(B.node4[c][l] / 4) + i];
}

template <class Real, MaterialModel M>
void energy(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, Real lambda, Real mu, const Real* u,
            double* out, Real* J) {
  constexpr int W = kLanes<Real>;
  FlushSubnormals flush;
  for (int32_t b = begin; b < end; ++b) {
    const ElementBlock<Real>& B = blocks[b];
    alignas(64) Real x[12][W];
    gather_corners(B, u, x);
    for (int l = 0; l < W; ++l) {
      Real F[9], P[9];
      deformation_gradient(B, l, x, F);
      // (Invertible StVK: the SVD only where F reaches the floor, as in forces().)
      constexpr MaterialModel kFast = M == MaterialModel::InvertibleStVK ? MaterialModel::StVK : M;
      const bool svd =
          M == MaterialModel::Corotational || (M == MaterialModel::InvertibleStVK && material::reaches_floor(F));
      if (svd) flush.engage();
      out[static_cast<int64_t>(b - begin) * W + l] = svd ? material::stress<M>(F, lambda * B.V[l], mu * B.V[l], P)
                                                         : material::stress<kFast>(F, lambda * B.V[l], mu * B.V[l], P);
      if (J) J[static_cast<int64_t>(b - begin) * W + l] = material::det(F);
    }
  }
}

// How far an element's critical step falls at deformation F (see CriticalFn):
// its smallest altitude over the rest one, clamped to [0.05, 1], over the
// square root of its material's stiffening. g[f] are the rest gradients of
// its shape functions (the rows of Dm^-1, and minus their sum for corner 0):
// the altitude over face f is 1 / |grad N_f|, and a deformation turns
// grad N into F^-T grad N = cof(F) grad N / J. So the ratio comes from F and
// Dm^-1 alone, with one square root: |J| max|g| / max|cof(F) g|.
template <MaterialModel M, class T>
TACTILE_INLINE T critical_factor(const T* F, const T (*g)[3]) {
  T C[9];
  material::cofactor(F, C);
  const T J = F[0] * C[0] + F[1] * C[1] + F[2] * C[2];
  T cg[4][3];
#pragma GCC unroll 4
  for (int f = 1; f < 4; ++f)
#pragma GCC unroll 3
    for (int i = 0; i < 3; ++i) cg[f][i] = C[3 * i] * g[f][0] + C[3 * i + 1] * g[f][1] + C[3 * i + 2] * g[f][2];
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) cg[0][i] = -(cg[1][i] + cg[2][i] + cg[3][i]);
  T rest2 = 0, now2 = 0;  // max |g|^2, max |cof(F) g|^2
#pragma GCC unroll 4
  for (int f = 0; f < 4; ++f) {
    const T r = g[f][0] * g[f][0] + g[f][1] * g[f][1] + g[f][2] * g[f][2];
    const T n = cg[f][0] * cg[f][0] + cg[f][1] * cg[f][1] + cg[f][2] * cg[f][2];
    rest2 = r > rest2 ? r : rest2;
    now2 = n > now2 ? n : now2;
  }
  const T absJ = J < T(0) ? -J : J;
  // now2 = 0 only with F of rank one or less: no altitude left.
  T ratio = now2 > T(0) ? absJ * std::sqrt(rest2 / now2) : T(0);
  ratio = ratio < T(1) ? ratio : T(1);
  ratio = ratio > T(0.05) ? ratio : T(0.05);  // a flat element is the guards' job, not a zero step's
  return ratio / std::sqrt(material::stiffening(M, F));
}

template <class Real, MaterialModel M>
double critical(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, const Real* u, const double* lane_dt) {
  constexpr int W = kLanes<Real>;
  double best = std::numeric_limits<double>::infinity();
  // Small strain (eqs. 2-3) has one stiffness K for every configuration: the rest step holds.
  if constexpr (M == MaterialModel::Linear) return best;
  for (int32_t b = begin; b < end; ++b) {
    const ElementBlock<Real>& B = blocks[b];
    alignas(64) Real x[12][W];
    gather_corners(B, u, x);
    alignas(64) Real factor[W];
    for (int l = 0; l < W; ++l) {
      Real F[9], g[4][3];
      deformation_gradient(B, l, x, F);
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) g[r + 1][c] = B.Dinv[3 * r + c][l];
      for (int c = 0; c < 3; ++c) g[0][c] = -(g[1][c] + g[2][c] + g[3][c]);
      factor[l] = critical_factor<M>(F, g);
    }
    const double* dt = lane_dt + int64_t(b) * W;
    for (int l = 0; l < W; ++l) {
      const double d = dt[l] * double(factor[l]);
      best = d < best ? d : best;  // a NaN lane (non-finite u) is the guards' to report
    }
  }
  return best;
}

// ---- node passes -------------------------------------------------------------
//
// Node arrays come in two layouts: the state's (n x 3) and the element pass's
// Node4 (n x 4). The node passes run W nodes at a time as 3 vectors of
// components (flat, so every entry is one lane) and convert to and from the
// 4 vectors of Node4 with constant shuffles of whole vectors.
//
// The vectors are the hardware's width, not the element blocks' 64 bytes:
// below AVX-512 GCC lowers a two-input shuffle of 64-byte vectors lane by lane
// through the stack, where one of 32 bytes is two permutes and a blend
// (fem_bench --only=passes, the predict and correct columns; docs/perf.md).

// At least 4 lanes (first4 and first3 below need them): double below AVX2
// keeps 64 bytes, which runs faster there than 32 (fem_bench --only=isas).
#if defined(__AVX512F__)
inline constexpr int kNodeBytes = 64, kNodeBytesDouble = 64;
#elif defined(__AVX2__)
inline constexpr int kNodeBytes = 32, kNodeBytesDouble = 32;
#else
inline constexpr int kNodeBytes = 16, kNodeBytesDouble = 64;
#endif

template <class Real>
struct NodeLanes;
template <>
struct NodeLanes<float> {
  static constexpr int kBytes = kNodeBytes;
  typedef float V __attribute__((vector_size(kBytes)));
  typedef float VU __attribute__((vector_size(kBytes), aligned(4)));
  typedef int32_t M __attribute__((vector_size(kBytes)));
  typedef double D __attribute__((vector_size(2 * kBytes)));
};
template <>
struct NodeLanes<double> {
  static constexpr int kBytes = kNodeBytesDouble;
  typedef double V __attribute__((vector_size(kBytes)));
  typedef double VU __attribute__((vector_size(kBytes), aligned(8)));
  typedef int64_t M __attribute__((vector_size(kBytes)));
  typedef double D __attribute__((vector_size(kBytes)));
};

template <class Real>
struct NodeVectors {
  static constexpr int W = NodeLanes<Real>::kBytes / static_cast<int>(sizeof(Real));
  // first4 and first3 below assume a component vector spans at most two Node4
  // vectors and the other way round, which holds from 4 lanes up.
  static_assert(W >= 4 && W % 4 == 0);
  using V = typename NodeLanes<Real>::V;
  using VU = typename NodeLanes<Real>::VU;
  using M = typename NodeLanes<Real>::M;
  using D = typename NodeLanes<Real>::D;
  // Every bit of a lane but its sign bit.
  static constexpr auto kNoSign = std::numeric_limits<std::conditional_t<sizeof(Real) == 4, int32_t, int64_t>>::max();

  // A constant mask vector, lane e = f(e).
  template <class F>
  static TACTILE_INLINE M mask(F f) {
    return [&]<size_t... E>(std::index_sequence<E...>) { return M{f(int(E))...}; }
    (std::make_index_sequence<W>{});
  }
  // Component vector r, lane e: entry (r W + e) % 3 of node (r W + e) / 3.
  // Its Node4 lanes lie in Node4 vectors first4(r) and first4(r) + 1.
  static constexpr int first4(int r) { return 4 * ((r * W) / 3) / W; }
  // Node4 vector k, lane e: entry e % 4 of node k W / 4 + e / 4. Its
  // component lanes lie in component vectors first3(k) and first3(k) + 1.
  static constexpr int first3(int k) { return 3 * (k * W / 4) / W; }

  // Component vector r from the Node4 vectors q[0..3].
  template <int R>
  static TACTILE_INLINE V unpack(const V* q) {
    const M m = mask([](int e) {
      const int p = R * W + e;
      return 4 * (p / 3) + p % 3 - first4(R) * W;
    });
    return __builtin_shuffle(q[first4(R)], q[first4(R) + 1], m);
  }
  // Component vector r of a per-node scalar s (W nodes): s of each lane's node.
  template <int R>
  static TACTILE_INLINE V spread(const V& s) {
    return __builtin_shuffle(s, mask([](int e) { return (R * W + e) / 3; }));
  }
  // Node4 vector k from the component vectors c[0..2], 4th entries 0.
  template <int K>
  static TACTILE_INLINE V pack(const V* c) {
    constexpr int a = first3(K), b = a + 1 < 3 ? a + 1 : 2;
    const M m = mask([](int e) { return e % 4 == 3 ? 0 : 3 * (K * W / 4 + e / 4) + e % 4 - first3(K) * W; });
    const V q = __builtin_shuffle(c[a], c[b], m);
    return mask([](int e) { return e % 4 == 3 ? 0 : -1; }) ? q : V{};
  }
};

template <class Real>
void pad(int32_t begin, int32_t end, const Real* u, Node4<Real>* u4) {
  using N = NodeVectors<Real>;
  using V = typename N::V;
  using VU = typename N::VU;
  constexpr int W = N::W;
  int64_t i = begin;
  for (; i + W <= end; i += W) {
    const VU* in = reinterpret_cast<const VU*>(u + 3 * i);
    const V c[3] = {in[0], in[1], in[2]};
    VU* out = reinterpret_cast<VU*>(u4[i].v);
    out[0] = N::template pack<0>(c);
    out[1] = N::template pack<1>(c);
    out[2] = N::template pack<2>(c);
    out[3] = N::template pack<3>(c);
  }
  for (; i < end; ++i) u4[i] = Node4<Real>{{u[3 * i], u[3 * i + 1], u[3 * i + 2], Real(0)}};
}

template <class Real>
void predict(int32_t begin, int32_t end, Real dt, Real* u, Real* v, const Real* a, Node4<Real>* u4) {
  using N = NodeVectors<Real>;
  using V = typename N::V;
  using VU = typename N::VU;
  constexpr int W = N::W;
  const Real half_dt2 = Real(0.5) * dt * dt;
  const Real half_dt = Real(0.5) * dt;
  int64_t i = begin;
  // A node group's three component vectors stay in registers for the pad.
  for (; i + W <= end; i += W) {
    VU* ui = reinterpret_cast<VU*>(u + 3 * i);
    VU* vi = reinterpret_cast<VU*>(v + 3 * i);
    const VU* ai = reinterpret_cast<const VU*>(a + 3 * i);
    V c[3];
#pragma GCC unroll 3
    for (int r = 0; r < 3; ++r) {
      c[r] = ui[r] + dt * vi[r] + half_dt2 * ai[r];  // eq. (7)
      ui[r] = c[r];
      vi[r] = vi[r] + half_dt * ai[r];  // first half of eq. (9)
    }
    VU* out = reinterpret_cast<VU*>(u4[i].v);
    out[0] = N::template pack<0>(c);
    out[1] = N::template pack<1>(c);
    out[2] = N::template pack<2>(c);
    out[3] = N::template pack<3>(c);
  }
  for (int64_t k = 3 * i; k < 3 * int64_t(end); ++k) {
    u[k] += dt * v[k] + half_dt2 * a[k];
    v[k] += half_dt * a[k];
  }
  pad(int32_t(i), end, u, u4);
}

template <class Real, bool kGravity, bool kDamping>
CorrectSums correct(const CorrectArgs<Real>& A) {
  using N = NodeVectors<Real>;
  using V = typename N::V;
  using VU = typename N::VU;
  constexpr int W = N::W;
  const Real half_dt = Real(0.5) * A.dt;
  // eq. (10): q = m (1 + alpha dt / 2) is diagonal, so a is a division per node.
  const Real q_inv = kDamping ? Real(1) / (Real(1) + A.alpha * half_dt) : Real(1);
  // g along the components of a node group.
  V gc[3];
  for (int r = 0; r < 3; ++r)
    for (int e = 0; e < W; ++e) gc[r][e] = A.g[(r * W + e) % 3];
  // Sums per lane of a node group, added to per-lane sums in double (so that
  // a million nodes sum as accurately as a hundred), folded at the end.
  using D = typename N::D;
  V abs_a, mv2, mgu, ma2;
  D abs_a_d{}, mv2_d{}, mgu_d{}, ma2_d{};
  // One component vector r of the update: f, 1/m and m per lane in; v, a out.
  auto update = [&](const V& f, const V& inv_m, const V& m, const V& gr, const V& u, V& v, V& a) {
    V acc = f * inv_m;
    if constexpr (kGravity) {
      acc += gr;
      mgu += m * gr * u;
    }
    if constexpr (kDamping) acc -= A.alpha * v;  // d = alpha m (v + a dt/2), eq. (8)
    acc *= q_inv;
    v = v + half_dt * acc;  // second half of eq. (9)
    a = acc;
    // |acc| by clearing the sign bits (a vector ? : is a compare and a blend at best)
    abs_a += (V)((typename N::M)acc & N::kNoSign);
    mv2 += m * v * v;
    ma2 += m * acc * acc;
  };
  int64_t i = A.begin;
  for (; i + W <= A.end; i += W) {
    abs_a = mv2 = mgu = ma2 = V{};
    V q[4] = {};
    const int64_t g = i / 16;  // W divides 16
    for (int32_t r = A.group_begin[g]; r < A.group_begin[g + 1]; ++r) {
      VU* fp = reinterpret_cast<VU*>(A.f[A.group_offset[r] + i].v);
#pragma GCC unroll 4
      for (int k = 0; k < 4; ++k) {
        q[k] += fp[k];
        fp[k] = V{};  // cleared for the next element pass
      }
    }
    const V inv_m = *reinterpret_cast<const VU*>(A.inv_m + i), m = *reinterpret_cast<const VU*>(A.m + i);
    VU* vi = reinterpret_cast<VU*>(A.v + 3 * i);
    VU* ai = reinterpret_cast<VU*>(A.a + 3 * i);
    const VU* ui = reinterpret_cast<const VU*>(A.u + 3 * i);
    V vr, ar;
    vr = vi[0];
    update(N::template unpack<0>(q), N::template spread<0>(inv_m), N::template spread<0>(m), gc[0],
           kGravity ? V(ui[0]) : V{}, vr, ar);
    vi[0] = vr;
    ai[0] = ar;
    vr = vi[1];
    update(N::template unpack<1>(q), N::template spread<1>(inv_m), N::template spread<1>(m), gc[1],
           kGravity ? V(ui[1]) : V{}, vr, ar);
    vi[1] = vr;
    ai[1] = ar;
    vr = vi[2];
    update(N::template unpack<2>(q), N::template spread<2>(inv_m), N::template spread<2>(m), gc[2],
           kGravity ? V(ui[2]) : V{}, vr, ar);
    vi[2] = vr;
    ai[2] = ar;
    abs_a_d += __builtin_convertvector(abs_a, D);
    mv2_d += __builtin_convertvector(mv2, D);
    ma2_d += __builtin_convertvector(ma2, D);
    if constexpr (kGravity) mgu_d += __builtin_convertvector(mgu, D);
  }
  CorrectSums out;
  for (int l = 0; l < W; ++l) {
    out.abs_a += abs_a_d[l];
    out.mv2 += mv2_d[l];
    out.mgu += mgu_d[l];
    out.ma2 += ma2_d[l];
  }
  // The last nodes (fewer than W) one by one.
  for (; i < A.end; ++i) {
    Real fi[3] = {0, 0, 0};
    for (int32_t r = A.group_begin[i / 16]; r < A.group_begin[i / 16 + 1]; ++r) {
      Node4<Real>& fp = A.f[A.group_offset[r] + i];
      for (int k = 0; k < 3; ++k) fi[k] += fp.v[k];
      fp = Node4<Real>{};
    }
    for (int k = 0; k < 3; ++k) {
      const int64_t j = 3 * i + k;
      Real acc = fi[k] * A.inv_m[i];
      if constexpr (kGravity) {
        acc += A.g[k];
        out.mgu += double(A.m[i] * A.g[k] * A.u[j]);
      }
      if constexpr (kDamping) acc -= A.alpha * A.v[j];
      acc *= q_inv;
      A.v[j] = A.v[j] + half_dt * acc;
      A.a[j] = acc;
      out.abs_a += double(std::fabs(acc));
      out.mv2 += double(A.m[i] * A.v[j] * A.v[j]);
      out.ma2 += double(A.m[i] * acc * acc);
    }
  }
  return out;
}

template <class Real>
constexpr KernelTable<Real> make_table() {
  KernelTable<Real> t{};
  t.forces[int(MaterialModel::Linear)] = &forces<Real, MaterialModel::Linear>;
  t.forces[int(MaterialModel::StVK)] = &forces<Real, MaterialModel::StVK>;
  t.forces[int(MaterialModel::Corotational)] = &forces<Real, MaterialModel::Corotational>;
  t.forces[int(MaterialModel::NeoHookean)] = &forces<Real, MaterialModel::NeoHookean>;
  t.forces[int(MaterialModel::InvertibleStVK)] = &forces<Real, MaterialModel::InvertibleStVK>;
  t.quadratic_forces[int(MaterialModel::Linear)] = &quadratic_forces<Real, MaterialModel::Linear>;
  t.quadratic_forces[int(MaterialModel::StVK)] = &quadratic_forces<Real, MaterialModel::StVK>;
  t.quadratic_forces[int(MaterialModel::Corotational)] = &quadratic_forces<Real, MaterialModel::Corotational>;
  t.quadratic_forces[int(MaterialModel::NeoHookean)] = &quadratic_forces<Real, MaterialModel::NeoHookean>;
  t.quadratic_forces[int(MaterialModel::InvertibleStVK)] = &quadratic_forces<Real, MaterialModel::InvertibleStVK>;
  t.energy[int(MaterialModel::Linear)] = &energy<Real, MaterialModel::Linear>;
  t.energy[int(MaterialModel::StVK)] = &energy<Real, MaterialModel::StVK>;
  t.energy[int(MaterialModel::Corotational)] = &energy<Real, MaterialModel::Corotational>;
  t.energy[int(MaterialModel::NeoHookean)] = &energy<Real, MaterialModel::NeoHookean>;
  t.energy[int(MaterialModel::InvertibleStVK)] = &energy<Real, MaterialModel::InvertibleStVK>;
  t.critical[int(MaterialModel::Linear)] = &critical<Real, MaterialModel::Linear>;
  t.critical[int(MaterialModel::StVK)] = &critical<Real, MaterialModel::StVK>;
  t.critical[int(MaterialModel::Corotational)] = &critical<Real, MaterialModel::Corotational>;
  t.critical[int(MaterialModel::NeoHookean)] = &critical<Real, MaterialModel::NeoHookean>;
  t.critical[int(MaterialModel::InvertibleStVK)] = &critical<Real, MaterialModel::InvertibleStVK>;
  t.predict = &predict<Real>;
  t.pad = &pad<Real>;
  t.correct[0][0] = &correct<Real, false, false>;
  t.correct[0][1] = &correct<Real, false, true>;
  t.correct[1][0] = &correct<Real, true, false>;
  t.correct[1][1] = &correct<Real, true, true>;
  return t;
}

}  // namespace
}  // namespace tactile::kernel_impl

#pragma GCC diagnostic pop
