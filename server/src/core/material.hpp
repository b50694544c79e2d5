// Hyperelastic materials on the deformation gradient F of a linear tet.
//
// Each model gives an energy density psi(F) [J/m^3] and the first
// Piola-Kirchhoff stress P = d psi / dF [Pa]. The functions are scalar,
// branch-light and inline so that the element kernels (core/kernels/) can run
// them across SIMD lanes; the tests call the very same functions.
//
// Matrices are row-major 3x3 arrays: F[3*i + j] = F_ij.
#pragma once

#include <cmath>
#include <cstdint>
#include <string_view>

// Force-inlined: the kernels are compiled once per ISA, and an out-of-line
// copy would be shared between them by the linker.
#define TACTILE_INLINE inline __attribute__((always_inline))

namespace tactile {

enum class MaterialModel : uint8_t {
  Linear,        // small strain, eqs. (2)-(3): the paper's baseline; distorts under rotation
  StVK,          // St. Venant-Kirchhoff on Green strain, eqs. (5)-(6): the paper's model
  Corotational,  // linear stress in the rotated frame of the polar decomposition
  NeoHookean,    // stable Neo-Hookean, Smith, de Goes and Kim 2018
};
inline constexpr int kMaterialModelCount = 4;

std::string_view to_string(MaterialModel m);
// Parses "linear", "stvk", "corotational", "neohookean"; false if unknown.
bool parse_material_model(std::string_view s, MaterialModel* out);

// Whether an element of this model may pass through an inverted state
// (det F <= 0) and recover. StVK cannot: past ~42 % compression its
// resistance falls to zero and inverted elements stay inverted.
constexpr bool can_invert(MaterialModel m) { return m != MaterialModel::StVK; }

struct Lame {
  double lambda;  // first Lame parameter [Pa]
  double mu;      // shear modulus [Pa]
};
inline Lame compute_lame(double E, double nu) {
  return {E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))};
}

namespace material {

// ---- small 3x3 helpers (row-major) -------------------------------------------

template <class T>
TACTILE_INLINE T trace(const T* A) {
  return A[0] + A[4] + A[8];
}
template <class T>
TACTILE_INLINE T det(const T* A) {
  return A[0] * (A[4] * A[8] - A[5] * A[7]) - A[1] * (A[3] * A[8] - A[5] * A[6]) +
         A[2] * (A[3] * A[7] - A[4] * A[6]);
}
// cof(A) = d det(A) / dA (for invertible A, det(A) A^-T).
template <class T>
TACTILE_INLINE void cofactor(const T* A, T* C) {
  C[0] = A[4] * A[8] - A[5] * A[7];
  C[1] = A[5] * A[6] - A[3] * A[8];
  C[2] = A[3] * A[7] - A[4] * A[6];
  C[3] = A[2] * A[7] - A[1] * A[8];
  C[4] = A[0] * A[8] - A[2] * A[6];
  C[5] = A[1] * A[6] - A[0] * A[7];
  C[6] = A[1] * A[5] - A[2] * A[4];
  C[7] = A[2] * A[3] - A[0] * A[5];
  C[8] = A[0] * A[4] - A[1] * A[3];
}
// C = A^T B
template <class T>
TACTILE_INLINE void mul_tn(const T* A, const T* B, T* C) {
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j) C[3 * i + j] = A[i] * B[j] + A[3 + i] * B[3 + j] + A[6 + i] * B[6 + j];
}
// C = A B
template <class T>
TACTILE_INLINE void mul_nn(const T* A, const T* B, T* C) {
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j)
      C[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
}

// ---- linear (small strain) ---------------------------------------------------
// eps = sym(F) - I, sigma = lambda tr(eps) I + 2 mu eps; P = sigma.
template <class T>
TACTILE_INLINE T stress_linear(const T* F, T lambda, T mu, T* P) {
  T eps[9];
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j) eps[3 * i + j] = T(0.5) * (F[3 * i + j] + F[3 * j + i]) - (i == j ? T(1) : T(0));
  const T tr = trace(eps);
  T ee = 0;
  #pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) {
    P[k] = T(2) * mu * eps[k];
    ee += eps[k] * eps[k];
  }
  P[0] += lambda * tr;
  P[4] += lambda * tr;
  P[8] += lambda * tr;
  return mu * ee + T(0.5) * lambda * tr * tr;  // psi
}

// ---- St. Venant-Kirchhoff ----------------------------------------------------
// E = (F^T F - I)/2 (eqs. 5-6), S = lambda tr(E) I + 2 mu E, P = F S.
template <class T>
TACTILE_INLINE T stress_stvk(const T* F, T lambda, T mu, T* P) {
  T E[9];
  mul_tn(F, F, E);
  E[0] -= T(1);
  E[4] -= T(1);
  E[8] -= T(1);
  T ee = 0;
  #pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) {
    E[k] *= T(0.5);
    ee += E[k] * E[k];
  }
  const T tr = trace(E);
  T S[9];
  #pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) S[k] = T(2) * mu * E[k];
  S[0] += lambda * tr;
  S[4] += lambda * tr;
  S[8] += lambda * tr;
  mul_nn(F, S, P);
  return mu * ee + T(0.5) * lambda * tr * tr;
}

// ---- rotation of the polar decomposition, inversion-aware --------------------
// R = U V^T from the SVD of F, with the sign of the smallest singular value
// flipped when det F < 0 (Irving, Teran and Fedkiw 2004), so R is always a
// proper rotation. The eigenvectors of F^T F come from cyclic Jacobi sweeps.
template <class T>
TACTILE_INLINE void rotation_of(const T* F, T* R) {
  T A[9];
  mul_tn(F, F, A);  // A = F^T F, symmetric
  T V[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  constexpr int kSweeps = sizeof(T) == 4 ? 4 : 6;
  #pragma GCC unroll 16
  for (int sweep = 0; sweep < kSweeps; ++sweep) {
    #pragma GCC unroll 16
    for (int pair = 0; pair < 3; ++pair) {
      const int p = pair == 2 ? 1 : 0;
      const int q = pair == 0 ? 1 : 2;
      const T apq = A[3 * p + q];
      const T app = A[3 * p + p];
      const T aqq = A[3 * q + q];
      // Rutishauser's rotation: t = sign(theta) / (|theta| + sqrt(theta^2 + 1)).
      const T scale = std::fabs(app) + std::fabs(aqq) + T(1e-30);
      const bool active = std::fabs(apq) > scale * T(sizeof(T) == 4 ? 1e-9 : 1e-18);
      const T theta = active ? (aqq - app) / (T(2) * apq) : T(0);
      const T t = active ? std::copysign(T(1), theta) / (std::fabs(theta) + std::sqrt(theta * theta + T(1))) : T(0);
      const T c = T(1) / std::sqrt(t * t + T(1));
      const T s = t * c;
      // A <- J^T A J, V <- V J with J the (p,q) rotation.
      #pragma GCC unroll 16
      for (int k = 0; k < 3; ++k) {
        const T akp = A[3 * k + p];
        const T akq = A[3 * k + q];
        A[3 * k + p] = c * akp - s * akq;
        A[3 * k + q] = s * akp + c * akq;
      }
      #pragma GCC unroll 16
      for (int k = 0; k < 3; ++k) {
        const T apk = A[3 * p + k];
        const T aqk = A[3 * q + k];
        A[3 * p + k] = c * apk - s * aqk;
        A[3 * q + k] = s * apk + c * aqk;
      }
      #pragma GCC unroll 16
      for (int k = 0; k < 3; ++k) {
        const T vkp = V[3 * k + p];
        const T vkq = V[3 * k + q];
        V[3 * k + p] = c * vkp - s * vkq;
        V[3 * k + q] = s * vkp + c * vkq;
      }
    }
  }
  // Order the eigenpairs so column 2 has the smallest eigenvalue.
  int lo = 0;
  if (A[4] < A[3 * lo + lo]) lo = 1;
  if (A[8] < A[3 * lo + lo]) lo = 2;
  const int a = lo == 0 ? 1 : 0;
  const int b = lo == 2 ? 1 : 2;
  T v0[3] = {V[a], V[3 + a], V[6 + a]};
  T v1[3] = {V[b], V[3 + b], V[6 + b]};
  // v2 = v0 x v1 makes V a proper rotation.
  T v2[3] = {v0[1] * v1[2] - v0[2] * v1[1], v0[2] * v1[0] - v0[0] * v1[2], v0[0] * v1[1] - v0[1] * v1[0]};
  // u0 = F v0 / |F v0|; u1 = F v1 orthogonalised against u0; u2 = u0 x u1.
  T u0[3], u1[3];
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i) {
    u0[i] = F[3 * i] * v0[0] + F[3 * i + 1] * v0[1] + F[3 * i + 2] * v0[2];
    u1[i] = F[3 * i] * v1[0] + F[3 * i + 1] * v1[1] + F[3 * i + 2] * v1[2];
  }
  const T n0 = std::sqrt(u0[0] * u0[0] + u0[1] * u0[1] + u0[2] * u0[2]);
  if (n0 > T(1e-30)) {
    #pragma GCC unroll 3
    for (T& x : u0) x /= n0;
  } else {  // F annihilates everything: any rotation will do
    u0[0] = v0[0];
    u0[1] = v0[1];
    u0[2] = v0[2];
  }
  const T d01 = u0[0] * u1[0] + u0[1] * u1[1] + u0[2] * u1[2];
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i) u1[i] -= d01 * u0[i];
  const T n1 = std::sqrt(u1[0] * u1[0] + u1[1] * u1[1] + u1[2] * u1[2]);
  if (n1 > T(1e-30)) {
    #pragma GCC unroll 3
    for (T& x : u1) x /= n1;
  } else {  // F has rank one: complete with any unit vector orthogonal to u0
    const int k = std::fabs(u0[0]) < T(0.6) ? 0 : 1;
    T e[3] = {0, 0, 0};
    e[k] = 1;
    const T d = u0[k];
    #pragma GCC unroll 16
    for (int i = 0; i < 3; ++i) u1[i] = e[i] - d * u0[i];
    const T n = std::sqrt(u1[0] * u1[0] + u1[1] * u1[1] + u1[2] * u1[2]);
    #pragma GCC unroll 3
    for (T& x : u1) x /= n;
  }
  T u2[3] = {u0[1] * u1[2] - u0[2] * u1[1], u0[2] * u1[0] - u0[0] * u1[2], u0[0] * u1[1] - u0[1] * u1[0]};
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j) R[3 * i + j] = u0[i] * v0[j] + u1[i] * v1[j] + u2[i] * v2[j];
}

// ---- corotational linear -----------------------------------------------------
// psi = mu |F - R|^2 + lambda/2 tr(R^T F - I)^2, P = 2 mu (F - R) + lambda tr(R^T F - I) R.
template <class T>
TACTILE_INLINE T stress_corotational(const T* F, T lambda, T mu, T* P) {
  T R[9];
  rotation_of(F, R);
  T tr = -T(3);
  T dd = 0;
  #pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) {
    tr += R[k] * F[k];
    const T d = F[k] - R[k];
    dd += d * d;
  }
  #pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) P[k] = T(2) * mu * (F[k] - R[k]) + lambda * tr * R[k];
  return mu * dd + T(0.5) * lambda * tr * tr;
}

// ---- stable Neo-Hookean (Smith, de Goes and Kim 2018, eq. 14) ----------------
// psi = mu'/2 (I_C - 3) + lambda'/2 (J - alpha)^2 - mu'/2 log(I_C + 1) - psi(I),
// with mu' = 4/3 mu and lambda' = lambda + 5/6 mu so that it linearises to
// (lambda, mu), and alpha = 1 + 3 mu' / (4 lambda') so that F = I is stress free.
// The log term keeps the rest state stable; J may go negative (inversion).
template <class T>
TACTILE_INLINE T stress_neohookean(const T* F, T lambda, T mu, T* P) {
  const T mu_s = T(4.0 / 3.0) * mu;
  const T lambda_s = lambda + T(5.0 / 6.0) * mu;
  // The kernels' padding lanes pass lambda = mu = 0: 0/0 there would put a
  // NaN into the block's energy sum and into node 0's force.
  const T alpha = lambda_s != T(0) ? T(1) + T(0.75) * mu_s / lambda_s : T(1);
  T Ic = 0;
  #pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) Ic += F[k] * F[k];
  T C[9];
  cofactor(F, C);
  const T J = F[0] * C[0] + F[1] * C[1] + F[2] * C[2];
  const T a = mu_s * (T(1) - T(1) / (Ic + T(1)));
  const T b = lambda_s * (J - alpha);
  #pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) P[k] = a * F[k] + b * C[k];
  const T psi_rest = T(0.5) * lambda_s * (T(1) - alpha) * (T(1) - alpha) - T(0.5) * mu_s * std::log(T(4));
  return T(0.5) * mu_s * (Ic - T(3)) + T(0.5) * lambda_s * (J - alpha) * (J - alpha) -
         T(0.5) * mu_s * std::log(Ic + T(1)) - psi_rest;
}

template <MaterialModel M, class T>
TACTILE_INLINE T stress(const T* F, T lambda, T mu, T* P) {
  if constexpr (M == MaterialModel::Linear) return stress_linear(F, lambda, mu, P);
  if constexpr (M == MaterialModel::StVK) return stress_stvk(F, lambda, mu, P);
  if constexpr (M == MaterialModel::Corotational) return stress_corotational(F, lambda, mu, P);
  if constexpr (M == MaterialModel::NeoHookean) return stress_neohookean(F, lambda, mu, P);
}

// Run-time dispatch for tests and tools (not for hot loops).
template <class T>
TACTILE_INLINE T stress(MaterialModel m, const T* F, T lambda, T mu, T* P) {
  switch (m) {
    case MaterialModel::Linear: return stress<MaterialModel::Linear>(F, lambda, mu, P);
    case MaterialModel::StVK: return stress<MaterialModel::StVK>(F, lambda, mu, P);
    case MaterialModel::Corotational: return stress<MaterialModel::Corotational>(F, lambda, mu, P);
    case MaterialModel::NeoHookean: return stress<MaterialModel::NeoHookean>(F, lambda, mu, P);
  }
  return T(0);
}

// Bound on the ratio of the current tangent stiffness to the rest one, used
// to refresh the critical step as the body deforms (see core/stepper.cpp).
// StVK stiffens as (3 s^2 - 1)/2 along a stretch s; Neo-Hookean as s^2.
template <class T>
TACTILE_INLINE T stiffening(MaterialModel m, const T* F) {
  if (m == MaterialModel::Linear || m == MaterialModel::Corotational) return T(1);
  T C[9];
  mul_tn(F, F, C);
  // Gershgorin bound on the largest eigenvalue of C = F^T F (exact when C is diagonal).
  T s2 = 0;
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i) {
    const T row = std::fabs(C[3 * i]) + std::fabs(C[3 * i + 1]) + std::fabs(C[3 * i + 2]);
    s2 = row > s2 ? row : s2;
  }
  const T k = m == MaterialModel::StVK ? (T(3) * s2 - T(1)) / T(2) : s2;
  return k > T(1) ? k : T(1);
}

}  // namespace material
}  // namespace tactile
