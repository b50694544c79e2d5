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
  return A[0] * (A[4] * A[8] - A[5] * A[7]) - A[1] * (A[3] * A[8] - A[5] * A[6]) + A[2] * (A[3] * A[7] - A[4] * A[6]);
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
    for (int j = 0; j < 3; ++j) C[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
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
// folded into the constants: fewer multiplies for the element pass
// (fem_bench --only=passes; docs/perf.md, The element pass).
// StVK from C's six entries, c_ij = (F^T F)_ij.
template <class T>
TACTILE_INLINE T stress_stvk_of_c(const T* F, T c00, T c11, T c22, T c01, T c02, T c12, T lambda, T mu, T* P) {
  const T d0 = c00 - T(1), d1 = c11 - T(1), d2 = c22 - T(1);  // 2 E_ii; c01, c02, c12 are 2 E_ij
  const T tr = T(0.5) * (d0 + d1 + d2);                       // tr E
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

// ---- two lanes at once -------------------------------------------------------
// Pair<T> carries two independent values through the same scalar code, so
// that the SVD below can run two elements (two kernel blocks' lanes) in one
// pass over its instructions: the Jacobi sweeps are a chain of dependent
// operations, and with one element per vector lane the core waits on that
// chain; two chains in one instruction stream keep its units busy
// (fem_bench --only=invertible; docs/perf.md). pick(), abs_of() and sqrt_of()
// are the select, |x| and sqrt that take either a T or a Pair<T>.
template <class T>
struct Pair {
  T a, b;
  Pair() = default;
  constexpr Pair(T x) : a(x), b(x) {}  // NOLINT(google-explicit-constructor): constants broadcast
  constexpr Pair(T x, T y) : a(x), b(y) {}
};
struct PairMask {
  bool a, b;
};
template <class T>
struct ScalarOf {
  using type = T;
};
template <class T>
struct ScalarOf<Pair<T>> {
  using type = T;
};
template <class T>
using Scalar = typename ScalarOf<T>::type;

#define TACTILE_PAIR_ARITHMETIC(op)                               \
  template <class T>                                              \
  TACTILE_INLINE Pair<T> operator op(Pair<T> x, Pair<T> y) {      \
    return {x.a op y.a, x.b op y.b};                              \
  }                                                               \
  template <class T>                                              \
  TACTILE_INLINE Pair<T>& operator op##=(Pair<T>& x, Pair<T> y) { \
    x.a op## = y.a;                                               \
    x.b op## = y.b;                                               \
    return x;                                                     \
  }
TACTILE_PAIR_ARITHMETIC(+)
TACTILE_PAIR_ARITHMETIC(-)
TACTILE_PAIR_ARITHMETIC(*)
TACTILE_PAIR_ARITHMETIC(/)
#undef TACTILE_PAIR_ARITHMETIC
#define TACTILE_PAIR_COMPARISON(op)                           \
  template <class T>                                          \
  TACTILE_INLINE PairMask operator op(Pair<T> x, Pair<T> y) { \
    return {x.a op y.a, x.b op y.b};                          \
  }
TACTILE_PAIR_COMPARISON(<)
TACTILE_PAIR_COMPARISON(>)
#undef TACTILE_PAIR_COMPARISON
template <class T>
TACTILE_INLINE Pair<T> operator-(Pair<T> x) {
  return {-x.a, -x.b};
}
template <class T>
TACTILE_INLINE T pick(bool c, T x, T y) {
  return c ? x : y;
}
template <class T>
TACTILE_INLINE Pair<T> pick(PairMask c, Pair<T> x, Pair<T> y) {
  return {c.a ? x.a : y.a, c.b ? x.b : y.b};
}
template <class T>
TACTILE_INLINE T abs_of(T x) {
  return std::fabs(x);
}
template <class T>
TACTILE_INLINE Pair<T> abs_of(Pair<T> x) {
  return {std::fabs(x.a), std::fabs(x.b)};
}
template <class T>
TACTILE_INLINE T sqrt_of(T x) {
  return std::sqrt(x);
}
template <class T>
TACTILE_INLINE Pair<T> sqrt_of(Pair<T> x) {
  return {std::sqrt(x.a), std::sqrt(x.b)};
}

// ---- rotation of the polar decomposition, inversion-aware --------------------
// R = U V^T from the SVD F = U Sigma V^T, with the sign of the smallest
// singular value flipped when det F < 0 (Irving, Teran and Fedkiw 2004), so R
// is always a proper rotation and an inverted element is pushed back.
//
// Method: after McAdams, Selle, Tamstorf, Teran and Sifakis 2011, "Computing
// the SVD of 3x3 matrices with minimal branching and elementary floating
// point operations": Jacobi sweeps on F^T F with Givens angles from a
// rational formula (no square root), sorting of the singular vectors by
// conditional swaps, and U from F V by Gram-Schmidt. Every step is a fixed
// sequence of arithmetic and value selects, with compile-time indices, so
// the kernels' lane loop vectorises through it. The SVD serves where F may
// be near singular or inverted: Newton's polar iteration (polar_newton_step)
// needs F^-1 and finds only the det F < 0 polar factor, not which axis to
// flip; here U's last column puts the sign of det F on the last, smallest,
// singular value by construction, and R stays a rotation for any F.
//
// Speed: the sweeps drive off-diagonal entries towards zero, into the
// subnormal range, where every operation on them costs a microcode assist
// (fem_bench --only=invertible; docs/perf.md). The kernels run these
// functions with subnormals flushed to zero (kernels_impl.hpp,
// FlushSubnormals); elsewhere they are as accurate, only slower.

// Below this a squared length counts as zero: far enough above the smallest
// normal number that its square root and reciprocal keep full precision.
template <class T>
inline constexpr Scalar<T> kRotationTiny =
    std::numeric_limits<Scalar<T>>::min() / std::numeric_limits<Scalar<T>>::epsilon();
// Added to the angle's denominator ch (below), which is of degree two in the
// entries of S (trace 1): a pair already diagonal with equal entries turns by
// nothing rather than by 0/0, and ch^2 stays far enough above the smallest
// normal number that cos^2 + sin^2 = 1 holds with subnormals flushed (where
// sh^2 would vanish and ch sh would not). It slows the last rotations only
// for entries under ~3e-8 in float, below what changes its result.
template <class T>
inline constexpr Scalar<T> kAngleTiny = sizeof(Scalar<T>) == 4 ? Scalar<T>(0x1p-50) : Scalar<T>(0x1p-480);

// Jacobi sweeps. Over random F (also nearly flat and nearly rank-2 ones) the
// worst off-diagonal entry of F^T F left, relative to |F|^2, is ~2e-4 after
// 3 sweeps, ~2e-8 after 4 and ~1e-22 after 5: 4 for float, 5 for double.
// (McAdams et al.'s first-order angle needs 6 and 7 for the same.)
template <class T>
inline constexpr int kJacobiSweeps = sizeof(Scalar<T>) == 4 ? 4 : 5;

// One Jacobi rotation of the symmetric S in the (p, q) plane, (p, q, k) cyclic:
// S <- J^T S J, V <- V J. The angle theta that zeroes S_pq has tan 2 theta
// = z = e / d, with d = S_pp - S_qq and e = 2 S_pq. J is built from
// u = tan(theta / 2) by the half-angle formulas cos theta = (1 - u^2) / (1 +
// u^2), sin theta = 2u / (1 + u^2): exactly orthogonal for any u, with one
// division. u = tan(atan(z) / 4) is approximated by the rational function
//   u ~ z (a + b|z|) / (1 + c|z| + d' z^2),  a = 1/4, d' = 5/16, b = a c,
// c = 4 d' tan(pi/8): exact to third order in z, so that sweeps converge
// fast once S is nearly diagonal, and exact at |z| -> infinity (a rotation
// of pi/4), so that the first sweeps, far from diagonal, make progress (its
// angle is within 0.065 rad of the exact one over all z). Written in d and e
// so that there is no division: u = sh / ch.
template <int p, int q, int k, class T>
TACTILE_INLINE void apply_jacobi_rotation(T (&S)[3][3], T (&V)[3][3]) {
  using R = Scalar<T>;
  const T kA = R(0.25), kD = R(0.3125);
  const T kC = R(0.5177669529663688110021109052621225982);  // 4 d' tan(pi/8)
  const T kB = R(0.1294417382415922027505277263155306496);  // a c
  const T spp = S[p][p], sqq = S[q][q], spq = S[p][q], spk = S[p][k], sqk = S[q][k];
  const T d = spp - sqq, e = T(R(2)) * spq;
  const T ad = abs_of(d), ae = abs_of(e);
  const T sh = e * (kA * d + kB * pick(d < T(R(0)), -ae, ae));
  const T ch = d * d + kC * ad * ae + kD * e * e + T(kAngleTiny<T>);
  const T ch2 = ch * ch, sh2 = sh * sh;
  const T inv = T(R(1)) / (ch2 + sh2);
  const T c = (ch2 - sh2) * inv;
  const T s = T(R(2)) * ch * sh * inv;
  const T cc = c * c, ss = s * s, cs = c * s;
  S[p][p] = cc * spp + T(R(2)) * cs * spq + ss * sqq;
  S[q][q] = ss * spp - T(R(2)) * cs * spq + cc * sqq;
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
  const auto swap = rho[i] < rho[j];
  const T ri = rho[i], rj = rho[j];
  rho[i] = pick(swap, rj, ri);
  rho[j] = pick(swap, ri, rj);
#pragma GCC unroll 3
  for (int r = 0; r < 3; ++r) {
    const T bi = B[r][i], bj = B[r][j], vi = V[r][i], vj = V[r][j];
    B[r][i] = pick(swap, bj, bi);
    B[r][j] = pick(swap, -bi, bj);
    V[r][i] = pick(swap, vj, vi);
    V[r][j] = pick(swap, -vi, vj);
  }
}

// The signed SVD F = U diag(sigma) V^T: U and V proper rotations, sigma_0 >=
// sigma_1 >= |sigma_2|, and sigma_2 with the sign of det F (Irving et al.'s
// flip). U[i][j], V[i][j] are row i, column j. T is float, double or a Pair.
template <class T>
TACTILE_INLINE void svd_of(const T* F, T (&U)[3][3], T* sigma, T (&V)[3][3]) {
  using R = Scalar<T>;
  // A = F / |F|: U and V do not change, and every threshold below is relative.
  T f2 = R(0);
#pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) f2 += F[k] * F[k];
  const T norm2 = pick(f2 > T(kRotationTiny<T>), f2, T(kRotationTiny<T>));
  const T scale = T(R(1)) / sqrt_of(norm2);
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
    for (int j = 0; j < 3; ++j) V[i][j] = T(i == j ? R(1) : R(0));
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
  T rho[3] = {S[0][0], S[1][1], S[2][2]};  // |b_j|^2, as S is now V^T A^T A V
  sort_singular_pair<0, 1>(B, V, rho);
  sort_singular_pair<0, 2>(B, V, rho);
  sort_singular_pair<1, 2>(B, V, rho);
  // U from B's columns by Gram-Schmidt (they are orthogonal but for the
  // Jacobi sweeps' residue): u0 = b0 / |b0|, u1 = the part of b1 normal to
  // u0, normalised, and u2 = u0 x u1, so that U is a proper rotation and
  // sigma_2 = u2 . b2 takes the sign of det F, which is the Irving et al.
  // flip. |b0| >= 1/sqrt(3) as |A| = 1, unless F = 0; where b1's part is
  // nil (F of rank one), u1 is any unit vector normal to u0. (Cheaper than the Givens QR
  // of McAdams et al.: fem_bench --only=invertible; docs/perf.md.)
  // (F = 0, the one case with b0 nil, takes b0 = e_x.)
  const auto zero = rho[0] < T(kRotationTiny<T>);
  const T b0[3] = {pick(zero, T(R(1)), B[0][0]), B[1][0], B[2][0]};
  const T b2[3] = {B[0][2], B[1][2], B[2][2]};
  const T r0 = sqrt_of(pick(zero, T(R(1)), rho[0]));
  const T i0 = T(R(1)) / r0;
  const T u0[3] = {b0[0] * i0, b0[1] * i0, b0[2] * i0};
  const T p = u0[0] * B[0][1] + u0[1] * B[1][1] + u0[2] * B[2][1];
  const T b1[3] = {B[0][1] - p * u0[0], B[1][1] - p * u0[1], B[2][1] - p * u0[2]};
  const auto rank_one = b1[0] * b1[0] + b1[1] * b1[1] + b1[2] * b1[2] < T(kRotationTiny<T>);
  // u0 x e_x, or u0 x e_y where u0 lies near x: never nil.
  const auto near_x = abs_of(u0[0]) > T(R(0.5));
  const T normal[3] = {pick(near_x, -u0[2], T(R(0))), pick(near_x, T(R(0)), u0[2]), pick(near_x, u0[0], -u0[1])};
  T v[3];
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) v[i] = pick(rank_one, normal[i], b1[i]);
  // Projected once more: where b1 is nearly parallel to b0, what is left of
  // it after one projection is rounding, no longer normal to u0 to rounding
  // of its own size (Kahan's "twice is enough").
  const T q = u0[0] * v[0] + u0[1] * v[1] + u0[2] * v[2];
  const T w[3] = {v[0] - q * u0[0], v[1] - q * u0[1], v[2] - q * u0[2]};
  const T r1 = sqrt_of(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
  const T i1 = T(R(1)) / r1;
  const T u1[3] = {w[0] * i1, w[1] * i1, w[2] * i1};
  const T u2[3] = {u0[1] * u1[2] - u0[2] * u1[1], u0[2] * u1[0] - u0[0] * u1[2], u0[0] * u1[1] - u0[1] * u1[0]};
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) {
    U[i][0] = u0[i];
    U[i][1] = u1[i];
    U[i][2] = u2[i];
  }
  const T norm = norm2 * scale;  // |F|
  sigma[0] = pick(zero, T(R(0)), r0) * norm;
  sigma[1] = pick(rank_one, T(R(0)), r1) * norm;
  sigma[2] = (u2[0] * b2[0] + u2[1] * b2[1] + u2[2] * b2[2]) * norm;
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
// psi = mu |F - R|^2 + lambda/2 tr(R^T F - I)^2, P = 2 mu (F - R) + lambda tr(R^T F - I) R,
// with R the polar rotation of F.
template <class T>
TACTILE_INLINE T stress_corotational_of(const T* F, const T* R, T lambda, T mu, T* P) {
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
template <class T>
TACTILE_INLINE T stress_corotational(const T* F, T lambda, T mu, T* P) {
  T R[9];
  rotation_of(F, R);
  return stress_corotational_of(F, R, lambda, mu, P);
}

// One step of Newton's iteration for the polar rotation, X <- (X + X^-T) / 2
// (Higham 1986), with X^-T = cof(X) / det X: from X = F it converges to R
// for any F with det F > 0, quadratically once near (each step squares the
// distance of every singular value from 1, halved), with one division a step
// and no SVD. Returns |X_new - X|^2: once that is under the precision's
// epsilon the new X is R to rounding. The kernels take it where F is well
// away from singular (may_reach_floor says no), where it needs 3 to 5 steps.
template <class T>
TACTILE_INLINE T polar_newton_step(T* X) {
  T C[9];
  cofactor(X, C);
  const T h = T(0.5) / (X[0] * C[0] + X[1] * C[1] + X[2] * C[2]);
  T change = 0;
#pragma GCC unroll 16
  for (int k = 0; k < 9; ++k) {
    const T next = T(0.5) * X[k] + h * C[k];
    const T d = next - X[k];
    change += d * d;
    X[k] = next;
  }
  return change;
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

// 1 unless J > 0 and, by Gershgorin (every eigenvalue of C = F^T F lies
// within a row's off-diagonal sum of its diagonal entry), each c_ii - sum
// |c_ij| is above c^2, so that no singular value of F is under the floor c:
// a dozen operations on C's entries. reaches_floor, exact, settles the lanes
// this leaves in doubt.
template <class T>
TACTILE_INLINE T may_reach_floor(T c00, T c11, T c22, T c01, T c02, T c12, T J) {
  const T a01 = std::fabs(c01), a02 = std::fabs(c02), a12 = std::fabs(c12);
  const T g0 = c00 - a01 - a02, g1 = c11 - a01 - a12, g2 = c22 - a02 - a12;
  const T lo = g0 < g1 ? (g0 < g2 ? g0 : g2) : (g1 < g2 ? g1 : g2);
  return (lo > T(kInversionFloor * kInversionFloor)) & (J > T(0)) ? T(0) : T(1);
}
template <class T>
TACTILE_INLINE T may_reach_floor(const T* F) {
  auto c = [F](int i, int j) { return F[i] * F[j] + F[3 + i] * F[3 + j] + F[6 + i] * F[6 + j]; };
  return may_reach_floor(c(0, 0), c(1, 1), c(2, 2), c(0, 1), c(0, 2), c(1, 2), det(F));
}

// StVK's stress and energy (as stress_stvk), and from the same entries of C
// whether F may reach invertible StVK's floor (near = may_reach_floor).
template <class T>
TACTILE_INLINE T stress_stvk_near(const T* F, T lambda, T mu, T* P, T& near) {
  auto c = [F](int i, int j) { return F[i] * F[j] + F[3 + i] * F[3 + j] + F[6 + i] * F[6 + j]; };
  const T c00 = c(0, 0), c11 = c(1, 1), c22 = c(2, 2), c01 = c(0, 1), c02 = c(0, 2), c12 = c(1, 2);
  near = may_reach_floor(c00, c11, c22, c01, c02, c12, det(F));
  return stress_stvk_of_c(F, c00, c11, c22, c01, c02, c12, lambda, mu, P);
}

template <class T>
TACTILE_INLINE T stress_invertible_stvk(const T* F, T lambda, T mu, T* P) {
  using R = Scalar<T>;
  T U[3][3], V[3][3], s[3];
  svd_of(F, U, s, V);
  const T c = T(R(kInversionFloor)), k = lambda + T(R(2)) * mu;
  T sh[3], d[3], E[3];
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) {
    sh[i] = pick(s[i] > c, s[i], c);
    d[i] = s[i] - sh[i];
    E[i] = T(R(0.5)) * (sh[i] * sh[i] - T(R(1)));
  }
  const T tr = E[0] + E[1] + E[2];
  const T q = sh[0] * d[0] + sh[1] * d[1] + sh[2] * d[2];  // sum_j sigma^_j d_j, over the held ones
  T Ph[3], psi = mu * (E[0] * E[0] + E[1] * E[1] + E[2] * E[2]) + T(R(0.5)) * lambda * tr * tr;
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i) {
    const T g = sh[i] * (T(R(2)) * mu * E[i] + lambda * tr);
    const auto held = d[i] < T(R(0));
    Ph[i] = pick(held, g + k * d[i], g + lambda * sh[i] * q);
    psi += g * d[i] + T(R(0.5)) * k * d[i] * d[i];
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
