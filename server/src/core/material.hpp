// Hyperelastic materials on the deformation gradient F of a linear tet.
//
// Each model gives an energy density psi(F) [J/m^3] and the first
// Piola-Kirchhoff stress P = d psi / dF [Pa]. The functions are scalar,
// branch-light and inline so that the element kernels (core/kernels/) can run
// them across SIMD lanes; the tests call the very same functions.
//
// Matrices are row-major 3x3 arrays: F[3*i + j] = F_ij.
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string_view>
#include <type_traits>

// Force-inlined: the kernels are compiled once per ISA, and an out-of-line
// copy would be shared between them by the linker.
#define TACTILE_INLINE inline __attribute__((always_inline))

namespace tactile {

enum class MaterialModel : uint8_t {
  Linear,          // small strain, eqs. (2)-(3): the paper's baseline; distorts under rotation
  StVK,            // St. Venant-Kirchhoff on Green strain, eqs. (5)-(6): the paper's model
  Corotational,    // linear stress in the rotated frame of the polar decomposition
  NeoHookean,      // stable Neo-Hookean, Smith, de Goes and Kim 2018
  InvertibleStVK,  // StVK with its singular values held at a floor (Irving, Teran and Fedkiw 2004)
};
inline constexpr int kMaterialModelCount = 5;

// "linear", "stvk", "corotational", "neohookean", "invertible_stvk".
std::string_view to_string(MaterialModel m);
// Parses the names of to_string; false if unknown.
bool parse_material_model(std::string_view s, MaterialModel* out);
// The model a scene's {"model": m, "invertible": true} asks for: StVK's
// invertible variant; the other models already take inversion.
constexpr MaterialModel make_invertible(MaterialModel m) {
  return m == MaterialModel::StVK ? MaterialModel::InvertibleStVK : m;
}

// Whether an element of this model may pass through an inverted state
// (det F <= 0) and recover. Plain StVK cannot: past ~42 % compression its
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
// Written on the six entries of the symmetric C = F^T F, with the halves
// folded into the constants: fewer multiplies for the element pass (the
// double kernel alone, alternated in one process, see kernels_impl.hpp: 2-4 %
// faster; float unchanged).
// StVK from C's six entries, c_ij = (F^T F)_ij.
template <class T>
TACTILE_INLINE T stress_stvk_of_c(const T* F, T c00, T c11, T c22, T c01, T c02, T c12, T lambda, T mu, T* P) {
  const T d0 = c00 - T(1), d1 = c11 - T(1), d2 = c22 - T(1);  // 2 E_ii; c01, c02, c12 are 2 E_ij
  const T tr = T(0.5) * (d0 + d1 + d2);                        // tr E
  const T lt = lambda * tr;
  // S = 2 mu E + lambda tr(E) I
  const T S[9] = {mu * d0 + lt, mu * c01, mu * c02, mu * c01, mu * d1 + lt, mu * c12, mu * c02, mu * c12, mu * d2 + lt};
  mul_nn(F, S, P);
  // E : E = (sum (2 E_ii)^2 + 2 sum (2 E_ij)^2) / 4
  const T ee4 = d0 * d0 + d1 * d1 + d2 * d2 + T(2) * (c01 * c01 + c02 * c02 + c12 * c12);
  return T(0.25) * mu * ee4 + T(0.5) * lambda * tr * tr;
}
template <class T>
TACTILE_INLINE T stress_stvk(const T* F, T lambda, T mu, T* P) {
  auto c = [F](int i, int j) { return F[i] * F[j] + F[3 + i] * F[3 + j] + F[6 + i] * F[6 + j]; };
  return stress_stvk_of_c(F, c(0, 0), c(1, 1), c(2, 2), c(0, 1), c(0, 2), c(1, 2), lambda, mu, P);
}

// ---- rotation of the polar decomposition, inversion-aware --------------------
// R = U V^T from the SVD F = U Sigma V^T, with the sign of the smallest
// singular value flipped when det F < 0 (Irving, Teran and Fedkiw 2004), so R
// is always a proper rotation and an inverted element is pushed back.
//
// Method: McAdams, Selle, Tamstorf, Teran and Sifakis 2011, "Computing the
// SVD of 3x3 matrices with minimal branching and elementary floating point
// operations": Jacobi sweeps on F^T F with approximate Givens angles, sorting
// of the singular vectors by conditional swaps, and a Givens QR of F V. Every
// step is a fixed sequence of arithmetic and value selects, with compile-time
// indices, so the kernels' lane loop vectorises through it (the former
// exact-Jacobi version picked the smallest eigenvalue by index and branched
// on norms, and ran scalar). It was chosen over a polar Newton iteration
// because that needs F^-1 (singular for a flat element) and finds only the
// det F < 0 polar factor, not which axis to flip; here the QR puts the sign
// of det F on the last, smallest, singular value by construction, and every
// rotation it applies is guarded so that R stays a rotation for any F.

// Below this a squared length counts as zero: far enough above the smallest
// normal number that its square root and reciprocal keep full precision.
template <class T>
inline constexpr T kRotationTiny = std::numeric_limits<T>::min() / std::numeric_limits<T>::epsilon();
// Off-diagonal entries of F^T F below this times the diagonal pair are taken
// as zero: far below what changes R, and it stops the cubic convergence from
// driving them into the subnormal range, where each operation costs a
// microcode assist (it made the kernel several times slower).
template <class T>
inline constexpr T kJacobiFloor = std::numeric_limits<T>::epsilon() * std::numeric_limits<T>::epsilon();

// Jacobi sweeps: the approximate angles converge slowly while F^T F is far
// from diagonal and cubically once near; over random F the worst off-diagonal
// left is ~1e-6 after 5 sweeps and ~1e-15 after 6 (relative to |F|^2), and
// ~1e-31 after 7.
template <class T>
inline constexpr int kJacobiSweeps = sizeof(T) == 4 ? 6 : 7;

// One Jacobi rotation of the symmetric S in the (p, q) plane, (p, q, k) cyclic:
// S <- J^T S J, V <- V J, with J's angle theta approximating the one that
// zeroes S_pq (tan 2 theta = 2 S_pq / (S_pp - S_qq)). The half-angle pair
// (ch, sh) = (2 (S_pp - S_qq), S_pq) is exact to first order; where it would
// exceed pi/8 (that is, S_pq is large against the gap, gamma sh^2 >= ch^2
// with gamma = (1 + sqrt 2)^2) the rotation is pi/4 instead (McAdams et al.
// 2011, sec. 2.2). cos and sin of theta follow from the half angle with one
// division and no square root.
template <int p, int q, int k, class T>
TACTILE_INLINE void apply_jacobi_rotation(T (&S)[3][3], T (&V)[3][3]) {
  constexpr T kGamma = T(5.828427124746190097603377448419396157);
  constexpr T kSqrtHalf = T(0.7071067811865475244008443621048490393);
  const T spp = S[p][p], sqq = S[q][q], skk = S[k][k];
  const T spq = std::fabs(S[p][q]) > kJacobiFloor<T> * (spp + sqq) ? S[p][q] : T(0);
  const T spk = std::fabs(S[p][k]) > kJacobiFloor<T> * (spp + skk) ? S[p][k] : T(0);
  const T sqk = std::fabs(S[q][k]) > kJacobiFloor<T> * (sqq + skk) ? S[q][k] : T(0);
  const T ch = T(2) * (spp - sqq);
  const T sh = spq;
  const T ch2 = ch * ch, sh2 = sh * sh;
  const bool approximate = kGamma * sh2 < ch2 && ch2 > kRotationTiny<T>;
  const T inv = T(1) / (approximate ? ch2 + sh2 : T(1));
  const T c = approximate ? (ch2 - sh2) * inv : kSqrtHalf;
  const T s = approximate ? T(2) * ch * sh * inv : kSqrtHalf;
  const T cc = c * c, ss = s * s, cs = c * s;
  S[p][p] = cc * spp + T(2) * cs * spq + ss * sqq;
  S[q][q] = ss * spp - T(2) * cs * spq + cc * sqq;
  S[p][q] = S[q][p] = (cc - ss) * spq + cs * (sqq - spp);
  S[p][k] = S[k][p] = c * spk + s * sqk;
  S[q][k] = S[k][q] = c * sqk - s * spk;
  #pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) {
    const T vp = V[i][p], vq = V[i][q];
    V[i][p] = c * vp + s * vq;
    V[i][q] = c * vq - s * vp;
  }
}

// Swaps columns i and j of B and V when |b_i|^2 = rho_i < rho_j, negating the
// new column j so that det V stays +1.
template <int i, int j, class T>
TACTILE_INLINE void sort_singular_pair(T (&B)[3][3], T (&V)[3][3], T (&rho)[3]) {
  const bool swap = rho[i] < rho[j];
  const T ri = rho[i], rj = rho[j];
  rho[i] = swap ? rj : ri;
  rho[j] = swap ? ri : rj;
  #pragma GCC unroll 3
  for (int r = 0; r < 3; ++r) {
    const T bi = B[r][i], bj = B[r][j], vi = V[r][i], vj = V[r][j];
    B[r][i] = swap ? bj : bi;
    B[r][j] = swap ? -bi : bj;
    V[r][i] = swap ? vj : vi;
    V[r][j] = swap ? -vi : vj;
  }
}

// Givens rotation G of rows i and j of B that zeroes B_j,col and leaves
// B_i,col = |(B_i,col, B_j,col)| >= 0; U <- U G^T keeps B_before = U B.
// Where both entries vanish G is the identity.
template <int i, int j, int col, class T>
TACTILE_INLINE void apply_givens_qr(T (&B)[3][3], T (&U)[3][3]) {
  const T a1 = B[i][col], a2 = B[j][col];
  const T rho2 = a1 * a1 + a2 * a2;
  const bool nonzero = rho2 > kRotationTiny<T>;
  const T r = T(1) / std::sqrt(nonzero ? rho2 : T(1));
  const T c = nonzero ? a1 * r : T(1);
  const T s = nonzero ? a2 * r : T(0);
  #pragma GCC unroll 3
  for (int m = 0; m < 3; ++m) {
    const T bi = B[i][m], bj = B[j][m];
    B[i][m] = c * bi + s * bj;
    B[j][m] = c * bj - s * bi;
    const T ui = U[m][i], uj = U[m][j];
    U[m][i] = c * ui + s * uj;
    U[m][j] = c * uj - s * ui;
  }
}

// The signed SVD F = U diag(sigma) V^T: U and V proper rotations, sigma_0 >=
// sigma_1 >= |sigma_2|, and sigma_2 with the sign of det F (Irving et al.'s
// flip). U[i][j], V[i][j] are row i, column j.
template <class T>
TACTILE_INLINE void svd_of(const T* F, T (&U)[3][3], T* sigma, T (&V)[3][3]) {
  // A = F / |F|: U and V do not change, and every threshold below is relative.
  T f2 = 0;
  #pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) f2 += F[k] * F[k];
  const T norm2 = f2 > kRotationTiny<T> ? f2 : kRotationTiny<T>;
  const T scale = T(1) / std::sqrt(norm2);
  T A[3][3];
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j) A[i][j] = scale * F[3 * i + j];
  // V: eigenvectors of S = A^T A, a proper rotation from the start.
  T S[3][3];
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j) S[i][j] = A[0][i] * A[0][j] + A[1][i] * A[1][j] + A[2][i] * A[2][j];
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j) V[i][j] = i == j ? T(1) : T(0);
  #pragma GCC unroll 16
  for (int sweep = 0; sweep < kJacobiSweeps<T>; ++sweep) {
    apply_jacobi_rotation<0, 1, 2>(S, V);
    apply_jacobi_rotation<1, 2, 0>(S, V);
    apply_jacobi_rotation<2, 0, 1>(S, V);
  }
  // B = A V = U Sigma: columns in decreasing length, so the last is the smallest.
  T B[3][3];
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j) B[i][j] = A[i][0] * V[0][j] + A[i][1] * V[1][j] + A[i][2] * V[2][j];
  T rho[3];
  #pragma GCC unroll 16
  for (int j = 0; j < 3; ++j) rho[j] = B[0][j] * B[0][j] + B[1][j] * B[1][j] + B[2][j] * B[2][j];
  sort_singular_pair<0, 1>(B, V, rho);
  sort_singular_pair<0, 2>(B, V, rho);
  sort_singular_pair<1, 2>(B, V, rho);
  // B = U Sigma' by Givens QR: Sigma'_00, Sigma'_11 >= 0 and Sigma'_22 has the
  // sign of det F, which is the Irving et al. flip.
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j) U[i][j] = i == j ? T(1) : T(0);
  apply_givens_qr<0, 1, 0>(B, U);
  apply_givens_qr<0, 2, 0>(B, U);
  apply_givens_qr<1, 2, 1>(B, U);
  const T norm = norm2 * scale;  // |F|
  #pragma GCC unroll 3
  for (int j = 0; j < 3; ++j) sigma[j] = B[j][j] * norm;
}

template <class T>
TACTILE_INLINE void rotation_of(const T* F, T* R) {
  T U[3][3], V[3][3], sigma[3];
  svd_of(F, U, sigma, V);
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j) R[3 * i + j] = U[i][0] * V[j][0] + U[i][1] * V[j][1] + U[i][2] * V[j][2];
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

// ---- invertible St. Venant-Kirchhoff ------------------------------------------
// StVK on the signed singular values sigma of F (Irving, Teran and Fedkiw
// 2004), each held at a floor c, with the energy extended past it so that the
// stress stays the energy's derivative (as Stomakhin et al. 2012 ask) and
// restores an element through inversion:
//   psi~(sigma) = psi(sigma^) + sum_i [g_i(sigma^) d_i + k/2 d_i^2],
// sigma^ = max(sigma, c), d = sigma - sigma^ (<= 0), g_i = d psi / d sigma_i,
// k = lambda + 2 mu (StVK's stiffness at rest along one axis). Where no
// sigma_i is under c this is StVK itself. Past the floor the resistance to
// compression grows at the rest stiffness instead of falling to zero, and an
// inverted element (sigma_2 < 0) is pushed back. c = 1/sqrt(3): where StVK's
// resistance to uniaxial compression peaks, so the extension never weakens.
// With E_i = (sigma^_i^2 - 1)/2, psi(sigma^) = mu sum E_i^2 + lambda/2 (sum E_i)^2
// and g_i = sigma^_i (2 mu E_i + lambda sum E_j). The principal stress is
// d psi~ / d sigma_i: g_i + k d_i for a held sigma_i (sigma^_i stands at c);
// for a free one, g_i plus what the held ones' g_j d_j give it through
// d g_j / d sigma_i = lambda sigma^_j sigma_i. P = U diag(those) V^T.
inline constexpr double kInversionFloor = 0.5773502691896257645091487805019574557;

// Whether F has a singular value under the floor, or is inverted: the
// kernels take the SVD only where this says true. Exact, without the SVD,
// from the invariants of C = F^T F (I1 = tr C, I2 = its principal 2 x 2
// minors, I3 = det C = J^2): its eigenvalues lambda_1 >= lambda_2 >= lambda_3
// are the roots of p(x) = x^3 - I1 x^2 + I2 x - I3, p < 0 below lambda_3,
// and lambda_3 lies below the smaller root of p'. So lambda_3 > c^2 exactly
// when p(c^2) < 0 and c^2 is below that root of p', which needs no square
// root: 3 c^2 < I1 and I1^2 - 3 I2 < (I1 - 3 c^2)^2. C's entries are those
// StVK's stress computes.
template <class T>
TACTILE_INLINE bool reaches_floor(T c00, T c11, T c22, T c01, T c02, T c12, T J) {
  const T i1 = c00 + c11 + c22;
  const T i2 = c00 * c11 + c00 * c22 + c11 * c22 - c01 * c01 - c02 * c02 - c12 * c12;
  const T c2 = T(kInversionFloor * kInversionFloor);
  const T p = ((c2 - i1) * c2 + i2) * c2 - J * J;
  const T gap = i1 - T(3) * c2;
  return !(J > T(0) && p < T(0) && gap > T(0) && i1 * i1 - T(3) * i2 < gap * gap);
}
template <class T>
TACTILE_INLINE bool reaches_floor(const T* F) {
  auto c = [F](int i, int j) { return F[i] * F[j] + F[3 + i] * F[3 + j] + F[6 + i] * F[6 + j]; };
  return reaches_floor(c(0, 0), c(1, 1), c(2, 2), c(0, 1), c(0, 2), c(1, 2), det(F));
}

// StVK's stress and energy (as stress_stvk), and from the same entries of C
// whether F may reach invertible StVK's floor: near = 1 unless J > 0 and,
// by Gershgorin (every eigenvalue of C lies within a row's off-diagonal sum
// of its diagonal entry), each c_ii - sum |c_ij| is above c^2, so that no
// singular value is under the floor. A dozen operations more than StVK's;
// reaches_floor(F), exact, settles the lanes this leaves in doubt.
template <class T>
TACTILE_INLINE T stress_stvk_near(const T* F, T lambda, T mu, T* P, T& near) {
  auto c = [F](int i, int j) { return F[i] * F[j] + F[3 + i] * F[3 + j] + F[6 + i] * F[6 + j]; };
  const T c00 = c(0, 0), c11 = c(1, 1), c22 = c(2, 2), c01 = c(0, 1), c02 = c(0, 2), c12 = c(1, 2);
  const T a01 = std::fabs(c01), a02 = std::fabs(c02), a12 = std::fabs(c12);
  const T g0 = c00 - a01 - a02, g1 = c11 - a01 - a12, g2 = c22 - a02 - a12;
  const T lo = g0 < g1 ? (g0 < g2 ? g0 : g2) : (g1 < g2 ? g1 : g2);
  near = (lo > T(kInversionFloor * kInversionFloor)) & (det(F) > T(0)) ? T(0) : T(1);
  return stress_stvk_of_c(F, c00, c11, c22, c01, c02, c12, lambda, mu, P);
}

template <class T>
TACTILE_INLINE T stress_invertible_stvk(const T* F, T lambda, T mu, T* P) {
  T U[3][3], V[3][3], s[3];
  svd_of(F, U, s, V);
  const T c = T(kInversionFloor), k = lambda + T(2) * mu;
  T sh[3], d[3], E[3];
  #pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) {
    sh[i] = s[i] > c ? s[i] : c;
    d[i] = s[i] - sh[i];
    E[i] = T(0.5) * (sh[i] * sh[i] - T(1));
  }
  const T tr = E[0] + E[1] + E[2];
  const T q = sh[0] * d[0] + sh[1] * d[1] + sh[2] * d[2];  // sum_j sigma^_j d_j, over the held ones
  T Ph[3], psi = mu * (E[0] * E[0] + E[1] * E[1] + E[2] * E[2]) + T(0.5) * lambda * tr * tr;
  #pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) {
    const T g = sh[i] * (T(2) * mu * E[i] + lambda * tr);
    const bool held = d[i] < T(0);
    Ph[i] = held ? g + k * d[i] : g + lambda * sh[i] * q;
    psi += g * d[i] + T(0.5) * k * d[i] * d[i];
  }
  #pragma GCC unroll 16
  for (int i = 0; i < 3; ++i)
    #pragma GCC unroll 16
    for (int j = 0; j < 3; ++j)
      P[3 * i + j] = U[i][0] * Ph[0] * V[j][0] + U[i][1] * Ph[1] * V[j][1] + U[i][2] * Ph[2] * V[j][2];
  return psi;
}

// ---- natural log, branch-free -------------------------------------------------
// log x for positive normal float or double x, written so that GCC vectorises
// it inline in the kernels' lane loop (the Neo-Hookean energy's log). With
// std::log the loop is scalar, or, where libmvec's vector log is declared (glibc
// declares it only under -ffast-math), it calls out once per vector, which
// spills every live vector register, gives a few ulp that vary with the glibc
// version and the ISA, and differs from what the tests' scalar calls compute.
//
// Method: x = 2^k m with m in [sqrt(1/2), sqrt(2)), found with integer
// operations on the bits of x; then with f = m - 1 and s = f / (2 + f),
//   log m = 2 atanh s = 2s + s R(s^2),   R(z) = z (2/3 + 2/5 z + 2/7 z^2 + ...),
// evaluated as log m = f - f^2/2 + s (f^2/2 + R) (since 2s = f - (1 - s) f^2/2):
// f is exact, f^2/2 is at most 0.21 of f and the rest smaller still, so the
// rounding errors of s, f^2/2 and R barely reach the result. R is a weighted
// minimax polynomial in z = s^2 on [0, (3 - 2 sqrt 2)^2] (Remez exchange,
// computed for this file): its error is below 2^-30 of log m for float (3
// terms) and 2^-59 for double (7 terms). log 2 is split into a part whose
// product with k is exact and a remainder.
//
// Accuracy, measured against a log of higher precision over every normal
// float and over 3 x 10^8 doubles (spread over all normal numbers, [1, 10]
// and [1/2, 2]): at most 0.84 ulp for float and 0.86 ulp for double, relative
// error below 0.69 epsilon; the worst cases lie just below sqrt(2), where
// log m is largest. Where GCC contracts into FMA (the v3 and v4 kernels) the
// worst is 0.76 ulp. Exact 0 at x = 1 (tests/core/fastmath_test.cpp). Zero,
// subnormal, negative, infinite and NaN x give unspecified finite values: the
// Neo-Hookean energy calls it with I_C + 1 >= 1.
template <class T>
TACTILE_INLINE T branchless_log(T x) {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double>);
  using Bits = std::conditional_t<sizeof(T) == 4, uint32_t, uint64_t>;
  constexpr int kFraction = std::numeric_limits<T>::digits - 1;  // stored mantissa bits: 23 or 52
  constexpr Bits kFractionMask = (Bits(1) << kFraction) - 1;
  constexpr Bits kOne = std::bit_cast<Bits>(T(1));
  constexpr Bits kSqrtHalf = std::bit_cast<Bits>(T(0.7071067811865475244008443621048490393));
  // Adding 1 - sqrt(1/2) to the bits carries into the exponent exactly when
  // the mantissa is >= sqrt(2): the exponent field of u is then k + bias.
  const Bits u = std::bit_cast<Bits>(x) + (kOne - kSqrtHalf);
  const T m = std::bit_cast<T>((u & kFractionMask) + kSqrtHalf);  // in [sqrt(1/2), sqrt(2))
  // k as T through the bits of 2^kFraction + (k + bias): there is no vector
  // int64-to-double conversion below AVX-512.
  constexpr Bits kTwoPowFraction = std::bit_cast<Bits>(T(Bits(1) << kFraction));
  constexpr T kBias = T(kOne >> kFraction);
  const T k = std::bit_cast<T>((u >> kFraction) | kTwoPowFraction) - (T(Bits(1) << kFraction) + kBias);
  const T f = m - T(1);  // exact (Sterbenz)
  const T s = f / (T(2) + f);
  const T z = s * s;
  const T hfsq = T(0.5) * f * f;
  T R, ln2_hi, ln2_lo;
  if constexpr (sizeof(T) == 4) {
    R = z * (0.666667759f + z * (0.399775416f + z * 0.298717290f));
    ln2_hi = 0x1.62e4p-1f;  // 16 significant bits: k ln2_hi is exact for |k| <= 2^8
    ln2_lo = 0x1.7f7d1cp-20f;
  } else {
    R = z * (0.6666666666666734 +
             z * (0.39999999999414676 +
                  z * (0.2857142874238762 +
                       z * (0.22222198573184523 +
                            z * (0.18183564326119675 + z * (0.15314050552112712 + z * 0.14795949700582858))))));
    ln2_hi = 0x1.62e42fefa4p-1;  // 40 significant bits: k ln2_hi is exact for |k| <= 2^13
    ln2_lo = -0x1.8432a1b0e2634p-43;
  }
  return k * ln2_hi - ((hfsq - (s * (hfsq + R) + k * ln2_lo)) - f);
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
  // The same log for both terms, so that psi(I) = 0 exactly.
  const T psi_rest = T(0.5) * lambda_s * (T(1) - alpha) * (T(1) - alpha) - T(0.5) * mu_s * branchless_log(T(4));
  return T(0.5) * mu_s * (Ic - T(3)) + T(0.5) * lambda_s * (J - alpha) * (J - alpha) -
         T(0.5) * mu_s * branchless_log(Ic + T(1)) - psi_rest;
}

template <MaterialModel M, class T>
TACTILE_INLINE T stress(const T* F, T lambda, T mu, T* P) {
  if constexpr (M == MaterialModel::Linear) return stress_linear(F, lambda, mu, P);
  if constexpr (M == MaterialModel::StVK) return stress_stvk(F, lambda, mu, P);
  if constexpr (M == MaterialModel::Corotational) return stress_corotational(F, lambda, mu, P);
  if constexpr (M == MaterialModel::NeoHookean) return stress_neohookean(F, lambda, mu, P);
  if constexpr (M == MaterialModel::InvertibleStVK) return stress_invertible_stvk(F, lambda, mu, P);
}

// Run-time dispatch for tests and tools (not for hot loops).
template <class T>
TACTILE_INLINE T stress(MaterialModel m, const T* F, T lambda, T mu, T* P) {
  switch (m) {
    case MaterialModel::Linear: return stress<MaterialModel::Linear>(F, lambda, mu, P);
    case MaterialModel::StVK: return stress<MaterialModel::StVK>(F, lambda, mu, P);
    case MaterialModel::Corotational: return stress<MaterialModel::Corotational>(F, lambda, mu, P);
    case MaterialModel::NeoHookean: return stress<MaterialModel::NeoHookean>(F, lambda, mu, P);
    case MaterialModel::InvertibleStVK: return stress<MaterialModel::InvertibleStVK>(F, lambda, mu, P);
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
  // (Invertible StVK stiffens as StVK along a stretch; past its floor it
  // resists compression at the rest stiffness.)
  const T k = m == MaterialModel::StVK || m == MaterialModel::InvertibleStVK ? (T(3) * s2 - T(1)) / T(2) : s2;
  return k > T(1) ? k : T(1);
}

}  // namespace material
}  // namespace tactile
