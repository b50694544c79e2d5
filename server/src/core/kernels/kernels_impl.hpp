// Kernel bodies, included once per ISA by kernels_isa.cpp. See kernels.hpp.
//
// Everything here has internal linkage: each ISA's object file must keep its
// own instantiations, or the linker would fold them into one (ODR) and every
// ISA would run whichever copy it kept. The material math is force-inlined
// for the same reason (TACTILE_INLINE).
#pragma once

// GCC 12's intrinsics headers trip -Wmaybe-uninitialized in their own
// _mm*_undefined_* helpers (GCC bug 105593, fixed in 13): silence that one
// warning for the header only. It must be the first include of the file.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>
#pragma GCC diagnostic pop

#include <cmath>

#include "core/kernels/kernels.hpp"

namespace tactile::kernel_impl {
namespace {

// ---- corner gather and force scatter ----------------------------------------
// The material math vectorises across lanes by itself; the memory traffic
// around it does not (GCC's generic tuning emulates gathers with scalar
// extracts, and no compiler vectorises a scatter whose lanes may share a
// node). These do it explicitly per ISA, with a scalar version for the rest.

// x[3c + i][l] = u[3 node[c][l] + i]: corner displacements of every lane.
template <class Real>
TACTILE_INLINE void gather_corners(const ElementBlock<Real>& B, const Real* u, Real (*x)[kLanes<Real>]) {
  [[maybe_unused]] constexpr int W = kLanes<Real>;
#if defined(__AVX512F__)
  #pragma GCC unroll 4
  for (int c = 0; c < 4; ++c) {
    if constexpr (sizeof(Real) == 4) {
      const __m512i id = _mm512_load_si512(B.node[c]);
      const __m512i i3 = _mm512_add_epi32(_mm512_add_epi32(id, id), id);
      _mm512_store_ps(x[3 * c], _mm512_i32gather_ps(i3, u, 4));
      _mm512_store_ps(x[3 * c + 1], _mm512_i32gather_ps(i3, u + 1, 4));
      _mm512_store_ps(x[3 * c + 2], _mm512_i32gather_ps(i3, u + 2, 4));
    } else {
      const __m256i id = _mm256_load_si256(reinterpret_cast<const __m256i*>(B.node[c]));
      const __m256i i3 = _mm256_add_epi32(_mm256_add_epi32(id, id), id);
      _mm512_store_pd(x[3 * c], _mm512_i32gather_pd(i3, u, 8));
      _mm512_store_pd(x[3 * c + 1], _mm512_i32gather_pd(i3, u + 1, 8));
      _mm512_store_pd(x[3 * c + 2], _mm512_i32gather_pd(i3, u + 2, 8));
    }
  }
#elif defined(__AVX2__)
  #pragma GCC unroll 4
  for (int c = 0; c < 4; ++c) {
    if constexpr (sizeof(Real) == 4) {
      #pragma GCC unroll 2
      for (int h = 0; h < W; h += 8) {
        const __m256i id = _mm256_load_si256(reinterpret_cast<const __m256i*>(B.node[c] + h));
        const __m256i i3 = _mm256_add_epi32(_mm256_add_epi32(id, id), id);
        _mm256_store_ps(x[3 * c] + h, _mm256_i32gather_ps(u, i3, 4));
        _mm256_store_ps(x[3 * c + 1] + h, _mm256_i32gather_ps(u + 1, i3, 4));
        _mm256_store_ps(x[3 * c + 2] + h, _mm256_i32gather_ps(u + 2, i3, 4));
      }
    } else {
      #pragma GCC unroll 2
      for (int h = 0; h < W; h += 4) {
        const __m128i id = _mm_load_si128(reinterpret_cast<const __m128i*>(B.node[c] + h));
        const __m128i i3 = _mm_add_epi32(_mm_add_epi32(id, id), id);
        _mm256_store_pd(x[3 * c] + h, _mm256_i32gather_pd(u, i3, 8));
        _mm256_store_pd(x[3 * c + 1] + h, _mm256_i32gather_pd(u + 1, i3, 8));
        _mm256_store_pd(x[3 * c + 2] + h, _mm256_i32gather_pd(u + 2, i3, 8));
      }
    }
  }
#else
  for (int c = 0; c < 4; ++c)
    for (int l = 0; l < W; ++l) {
      const Real* p = u + 3 * B.node[c][l];
      x[3 * c][l] = p[0];
      x[3 * c + 1][l] = p[1];
      x[3 * c + 2][l] = p[2];
    }
#endif
}

// f[node[c][l]][i] += fc[3c + i][l], f padded to 4 per node: each lane adds
// one 4-wide vector per corner, and lanes that share a node simply add in
// turn (no conflict detection needed).
template <class Real>
TACTILE_INLINE void scatter_corners(const ElementBlock<Real>& B, const Real (*fc)[kLanes<Real>], Real (*f)[4]) {
  [[maybe_unused]] constexpr int W = kLanes<Real>;
#if defined(__AVX512F__)
  #pragma GCC unroll 4
  for (int c = 0; c < 4; ++c) {
    const int32_t* id = B.node[c];
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
        float* p = f[id[l]];
        _mm_storeu_ps(p, _mm_add_ps(_mm_loadu_ps(p), v));
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
      const __m512d q[4] = {_mm512_permutex2var_pd(t0, lo, t2), _mm512_permutex2var_pd(t1, lo, t3),
                            _mm512_permutex2var_pd(t0, hi, t2), _mm512_permutex2var_pd(t1, hi, t3)};
      auto add = [&](int l, __m256d v) {
        double* p = f[id[l]];
        _mm256_storeu_pd(p, _mm256_add_pd(_mm256_loadu_pd(p), v));
      };
      // q[0]: lanes 0, 2; q[1]: 1, 3; q[2]: 4, 6; q[3]: 5, 7.
      #pragma GCC unroll 4
      for (int j = 0; j < 4; ++j) {
        const int l = (j & 1) + 4 * (j >> 1);
        add(l, _mm512_castpd512_pd256(q[j]));
        add(l + 2, _mm512_extractf64x4_pd(q[j], 1));
      }
    }
  }
#elif defined(__AVX2__)
  #pragma GCC unroll 4
  for (int c = 0; c < 4; ++c) {
    if constexpr (sizeof(Real) == 4) {
      #pragma GCC unroll 2
      for (int h = 0; h < W; h += 8) {
        const int32_t* id = B.node[c] + h;
        const __m256 fx = _mm256_load_ps(fc[3 * c] + h), fy = _mm256_load_ps(fc[3 * c + 1] + h);
        const __m256 fz = _mm256_load_ps(fc[3 * c + 2] + h), zero = _mm256_setzero_ps();
        const __m256d t0 = _mm256_castps_pd(_mm256_unpacklo_ps(fx, fy));
        const __m256d t1 = _mm256_castps_pd(_mm256_unpackhi_ps(fx, fy));
        const __m256d t2 = _mm256_castps_pd(_mm256_unpacklo_ps(fz, zero));
        const __m256d t3 = _mm256_castps_pd(_mm256_unpackhi_ps(fz, zero));
        const __m256 q[4] = {_mm256_castpd_ps(_mm256_unpacklo_pd(t0, t2)), _mm256_castpd_ps(_mm256_unpackhi_pd(t0, t2)),
                             _mm256_castpd_ps(_mm256_unpacklo_pd(t1, t3)), _mm256_castpd_ps(_mm256_unpackhi_pd(t1, t3))};
        auto add = [&](int l, __m128 v) {
          float* p = f[id[l]];
          _mm_storeu_ps(p, _mm_add_ps(_mm_loadu_ps(p), v));
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
        const int32_t* id = B.node[c] + h;
        const __m256d fx = _mm256_load_pd(fc[3 * c] + h), fy = _mm256_load_pd(fc[3 * c + 1] + h);
        const __m256d fz = _mm256_load_pd(fc[3 * c + 2] + h), zero = _mm256_setzero_pd();
        const __m256d t0 = _mm256_unpacklo_pd(fx, fy), t1 = _mm256_unpackhi_pd(fx, fy);
        const __m256d t2 = _mm256_unpacklo_pd(fz, zero), t3 = _mm256_unpackhi_pd(fz, zero);
        auto add = [&](int l, __m256d v) {
          double* p = f[id[l]];
          _mm256_storeu_pd(p, _mm256_add_pd(_mm256_loadu_pd(p), v));
        };
        add(0, _mm256_permute2f128_pd(t0, t2, 0x20));
        add(1, _mm256_permute2f128_pd(t1, t3, 0x20));
        add(2, _mm256_permute2f128_pd(t0, t2, 0x31));
        add(3, _mm256_permute2f128_pd(t1, t3, 0x31));
      }
    }
  }
#else
  for (int l = 0; l < W; ++l)
    for (int c = 0; c < 4; ++c) {
      Real* p = f[B.node[c][l]];
      p[0] += fc[3 * c][l];
      p[1] += fc[3 * c + 1][l];
      p[2] += fc[3 * c + 2][l];
    }
#endif
}

// ---- element math ------------------------------------------------------------

// One block's lanes as GCC vector types, for the per-lane sums: written as
// loops, GCC converts psiV to double lane by lane.
template <class Real>
struct LaneVectors;
template <>
struct LaneVectors<float> {
  typedef float RealW __attribute__((vector_size(64)));
  typedef double DoubleW __attribute__((vector_size(128)));
  typedef int32_t MaskW __attribute__((vector_size(64)));  // what RealW <= RealW gives
};
template <>
struct LaneVectors<double> {
  typedef double RealW __attribute__((vector_size(64)));
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

template <class Real, MaterialModel M>
ElasticSums forces(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, const Real* u, Real (*f)[4]) {
  constexpr int W = kLanes<Real>;
  using RealW = typename LaneVectors<Real>::RealW;
  using DoubleW = typename LaneVectors<Real>::DoubleW;
  using MaskW = typename LaneVectors<Real>::MaskW;
  // Sums kept per lane across blocks (in double, so that a million elements
  // sum as accurately as a hundred), folded once at the end.
  DoubleW energy = {};
  MaskW inverted = {};
  for (int32_t b = begin; b < end; ++b) {
    const ElementBlock<Real>& B = blocks[b];
    alignas(64) Real x[12][W];   // corner displacements [m]: x[3c + i][lane]
    alignas(64) Real fc[12][W];  // corner forces [N]: fc[3c + i][lane]
    alignas(64) Real psiV[W];    // V psi per lane [J]
    alignas(64) Real J[W];       // det F per lane
    gather_corners(B, u, x);
    // Per-lane outputs and no OpenMP pragma: GCC's `omp simd` would keep F and
    // P in memory as per-lane arrays; its plain vectoriser does far better.
#pragma GCC ivdep
    for (int l = 0; l < W; ++l) {
      Real F[9], P[9];
      deformation_gradient(B, l, x, F);
      if constexpr (!can_invert(M)) J[l] = material::det(F);
      // P and psi are linear in (lambda, mu) at a fixed ratio, so passing
      // (lambda V, mu V) gives V P and V psi.
      psiV[l] = material::stress<M>(F, B.lambdaV[l], B.muV[l], P);
      // [f1 f2 f3] = -V P Dm^-T, f0 = -(f1 + f2 + f3).
      #pragma GCC unroll 16
      for (int i = 0; i < 3; ++i) {
        Real sum = 0;
        #pragma GCC unroll 16
        for (int c = 0; c < 3; ++c) {
          const Real h = -(P[3 * i] * B.Dinv[3 * c][l] + P[3 * i + 1] * B.Dinv[3 * c + 1][l] +
                           P[3 * i + 2] * B.Dinv[3 * c + 2][l]);
          fc[3 * (c + 1) + i][l] = h;
          sum += h;
        }
        fc[i][l] = -sum;
      }
    }
    energy += __builtin_convertvector(*reinterpret_cast<const RealW*>(psiV), DoubleW);
    if constexpr (!can_invert(M)) inverted -= *reinterpret_cast<const RealW*>(J) <= Real(0);  // true is -1
    scatter_corners(B, fc, f);
  }
  ElasticSums sums;
  for (int l = 0; l < W; ++l) {
    sums.energy += energy[l];
    sums.inverted += inverted[l];
  }
  return sums;
}

template <class Real, MaterialModel M>
void energy(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, const Real* u, double* out, Real* J) {
  constexpr int W = kLanes<Real>;
  for (int32_t b = begin; b < end; ++b) {
    const ElementBlock<Real>& B = blocks[b];
    alignas(64) Real x[12][W];
    gather_corners(B, u, x);
    for (int l = 0; l < W; ++l) {
      Real F[9], P[9];
      deformation_gradient(B, l, x, F);
      out[static_cast<int64_t>(b - begin) * W + l] = material::stress<M>(F, B.lambdaV[l], B.muV[l], P);
      if (J) J[static_cast<int64_t>(b - begin) * W + l] = material::det(F);
    }
  }
}

template <class Real>
void predict(int32_t begin, int32_t end, Real dt, Real* u, Real* v, const Real* a) {
  const Real half_dt2 = Real(0.5) * dt * dt;
  const Real half_dt = Real(0.5) * dt;
#pragma GCC ivdep
  for (int64_t k = 3 * int64_t(begin); k < 3 * int64_t(end); ++k) {
    u[k] += dt * v[k] + half_dt2 * a[k];  // eq. (7)
    v[k] += half_dt * a[k];               // first half of eq. (9)
  }
}

template <class Real, bool kGravity, bool kDamping>
CorrectSums correct(const CorrectArgs<Real>& A) {
  constexpr int W = kLanes<Real>;
  const Real half_dt = Real(0.5) * A.dt;
  // eq. (10): q = m (1 + alpha dt / 2) is diagonal, so a is a division per node.
  const Real q_inv = kDamping ? Real(1) / (Real(1) + A.alpha * half_dt) : Real(1);
  // Sums kept per lane (no reassociation needed to vectorise), folded at the end.
  alignas(64) Real abs_a[W] = {}, mv2[W] = {}, mgu[W] = {}, ma2[W] = {};
  auto node = [&](int32_t i, int l) {
    Real node_v2 = 0, node_gu = 0, node_a2 = 0;
    for (int k = 0; k < 3; ++k) {
      const int64_t j = 3 * int64_t(i) + k;
      Real fj = A.f[4 * int64_t(i) + k];
      for (int32_t p = 1; p < A.n_parts; ++p) fj += A.f[4 * int64_t(i) + k + p * A.part_stride];
      Real acc = fj * A.inv_m[i];
      if constexpr (kGravity) {
        acc += A.g[k];
        node_gu += A.g[k] * A.u[j];
      }
      if constexpr (kDamping) acc -= A.alpha * A.v[j];  // d = alpha m (v + a dt/2), eq. (8)
      acc *= q_inv;
      const Real v_new = A.v[j] + half_dt * acc;  // second half of eq. (9)
      A.v[j] = v_new;
      A.a[j] = acc;
      abs_a[l] += std::fabs(acc);
      node_v2 += v_new * v_new;
      node_a2 += acc * acc;
    }
    mv2[l] += A.m[i] * node_v2;
    ma2[l] += A.m[i] * node_a2;
    if constexpr (kGravity) mgu[l] += A.m[i] * node_gu;
  };
  int32_t i = A.begin;
  for (; i + W <= A.end; i += W) {
#pragma GCC ivdep
    for (int l = 0; l < W; ++l) node(i + l, l);
  }
  for (int l = 0; i < A.end; ++i, ++l) node(i, l);
  CorrectSums out;
  for (int l = 0; l < W; ++l) {
    out.abs_a += double(abs_a[l]);
    out.mv2 += double(mv2[l]);
    out.mgu += double(mgu[l]);
    out.ma2 += double(ma2[l]);
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
  t.energy[int(MaterialModel::Linear)] = &energy<Real, MaterialModel::Linear>;
  t.energy[int(MaterialModel::StVK)] = &energy<Real, MaterialModel::StVK>;
  t.energy[int(MaterialModel::Corotational)] = &energy<Real, MaterialModel::Corotational>;
  t.energy[int(MaterialModel::NeoHookean)] = &energy<Real, MaterialModel::NeoHookean>;
  t.predict = &predict<Real>;
  t.correct[0][0] = &correct<Real, false, false>;
  t.correct[0][1] = &correct<Real, false, true>;
  t.correct[1][0] = &correct<Real, true, false>;
  t.correct[1][1] = &correct<Real, true, true>;
  return t;
}

}  // namespace
}  // namespace tactile::kernel_impl
