// The largest eigenvalue of a small symmetric matrix, for the critical step
// of one element (core/model.cpp for the linear tet, core/quadratic.cpp for
// the quadratic one): cyclic Jacobi, exact to rounding, at build time only.
#pragma once

#include <algorithm>
#include <cmath>

namespace tactile {

// A: n x n, row-major, symmetric; overwritten (rotated towards diagonal).
inline double compute_max_eigenvalue_symmetric(double* A, int n) {
  for (int sweep = 0; sweep < 30; ++sweep) {
    double off = 0, diag = 0;
    for (int p = 0; p < n; ++p) {
      diag += A[p * n + p] * A[p * n + p];
      for (int q = p + 1; q < n; ++q) off += A[p * n + q] * A[p * n + q];
    }
    if (off <= 1e-30 * diag) break;
    for (int p = 0; p < n; ++p) {
      for (int q = p + 1; q < n; ++q) {
        const double apq = A[p * n + q];
        if (std::fabs(apq) < 1e-300) continue;
        const double theta = (A[q * n + q] - A[p * n + p]) / (2.0 * apq);
        const double t = std::copysign(1.0, theta) / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
        for (int k = 0; k < n; ++k) {
          const double akp = A[k * n + p], akq = A[k * n + q];
          A[k * n + p] = c * akp - s * akq;
          A[k * n + q] = s * akp + c * akq;
        }
        for (int k = 0; k < n; ++k) {
          const double apk = A[p * n + k], aqk = A[q * n + k];
          A[p * n + k] = c * apk - s * aqk;
          A[q * n + k] = s * apk + c * aqk;
        }
      }
    }
  }
  double best = A[0];
  for (int p = 1; p < n; ++p) best = std::max(best, A[p * n + p]);
  return best;
}

}  // namespace tactile
