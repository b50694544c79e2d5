// Kernel bodies, included once per ISA by kernels_isa.cpp. See kernels.hpp.
//
// Everything here has internal linkage: each ISA's object file must keep its
// own instantiations, or the linker would fold them into one (ODR) and every
// ISA would run whichever copy it kept. The material math is force-inlined
// for the same reason (TACTILE_INLINE).
#pragma once

#include <cmath>

#include "core/kernels/kernels.hpp"

namespace tactile::kernel_impl {
namespace {

// F = I + [u1-u0, u2-u0, u3-u0] Dm^-1 for lane l. Working with displacements
// rather than positions keeps float accurate for small strains far from the origin.
template <class Real>
inline void deformation_gradient(const ElementBlock<Real>& B, int l, const Real* u, Real* F) {
  const int32_t n0 = 3 * B.node[0][l];
  Real du[3][3];  // du[c][i] = u_{c+1,i} - u_{0,i}
  #pragma GCC unroll 16
  for (int c = 0; c < 3; ++c) {
    const int32_t n = 3 * B.node[c + 1][l];
    #pragma GCC unroll 16
    for (int i = 0; i < 3; ++i) du[c][i] = u[n + i] - u[n0 + i];
  }
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j)
      F[3 * i + j] = (i == j ? Real(1) : Real(0)) + du[0][i] * B.Dinv[j][l] + du[1][i] * B.Dinv[3 + j][l] +
                     du[2][i] * B.Dinv[6 + j][l];
}

template <class Real, MaterialModel M>
ElasticSums forces(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, const Real* u, Real* f) {
  constexpr int W = kLanes<Real>;
  ElasticSums sums;
  for (int32_t b = begin; b < end; ++b) {
    const ElementBlock<Real>& B = blocks[b];
    alignas(64) Real fc[12][W];  // corner forces [N]: fc[3c + i][lane]
    alignas(64) Real psiV[W];    // V psi per lane [J]
    alignas(64) Real J[W];       // det F per lane
    // Per-lane outputs and no OpenMP pragma: GCC's `omp simd` would keep F and
    // P in memory as per-lane arrays; its plain vectoriser does far better.
#pragma GCC ivdep
    for (int l = 0; l < W; ++l) {
      Real F[9], P[9];
      deformation_gradient(B, l, u, F);
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
    Real energy = 0;
    for (int l = 0; l < W; ++l) energy += psiV[l];
    sums.energy += double(energy);
    if constexpr (!can_invert(M)) {
      for (int l = 0; l < W; ++l) sums.inverted += J[l] <= Real(0) ? 1 : 0;
    }
    // Scatter: scalar, so lanes that share a node need no conflict handling.
    for (int l = 0; l < W; ++l) {
      #pragma GCC unroll 16
      for (int c = 0; c < 4; ++c) {
        Real* fn = f + 3 * B.node[c][l];
        fn[0] += fc[3 * c][l];
        fn[1] += fc[3 * c + 1][l];
        fn[2] += fc[3 * c + 2][l];
      }
    }
  }
  return sums;
}

template <class Real, MaterialModel M>
void energy(const ElementBlock<Real>* blocks, int32_t begin, int32_t end, const Real* u, double* out, Real* J) {
  constexpr int W = kLanes<Real>;
  for (int32_t b = begin; b < end; ++b) {
    const ElementBlock<Real>& B = blocks[b];
    for (int l = 0; l < W; ++l) {
      Real F[9], P[9];
      deformation_gradient(B, l, u, F);
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
      Real fj = A.f[j];
      for (int32_t p = 1; p < A.n_parts; ++p) fj += A.f[j + p * A.part_stride];
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
