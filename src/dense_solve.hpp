// Internal to the compiled kernel (not installed, not part of the ABI): the dense linear solve
// shared by src/chain_kernel.cpp (the spine's 6N x 6N system, the tip compliance) and
// src/joint_kernel.cpp (the joint's linear model, M^-1 of its blocks).

#ifndef TENSEGRITY_STIFFNESS__SRC__DENSE_SOLVE_HPP_
#define TENSEGRITY_STIFFNESS__SRC__DENSE_SOLVE_HPP_

#include <cmath>
#include <cstdint>
#include <utility>

namespace tensegrity_stiffness {
namespace detail {

// Solves A X = B in place (A: m x m row-major, B: m x r row-major) by Gaussian elimination with
// partial pivoting (as LAPACK's dgesv); false when a pivot is exactly zero (singular).
inline bool solve_in_place(double* A, double* B, int64_t m, int64_t r) {
  for (int64_t c = 0; c < m; ++c) {
    int64_t pivot = c;
    double best = std::fabs(A[c * m + c]);
    for (int64_t i = c + 1; i < m; ++i) {
      const double v = std::fabs(A[i * m + c]);
      if (v > best) {
        best = v;
        pivot = i;
      }
    }
    if (best == 0.0) {
      return false;
    }
    if (pivot != c) {
      for (int64_t j = 0; j < m; ++j) {
        std::swap(A[c * m + j], A[pivot * m + j]);
      }
      for (int64_t j = 0; j < r; ++j) {
        std::swap(B[c * r + j], B[pivot * r + j]);
      }
    }
    const double d = A[c * m + c];
    for (int64_t i = c + 1; i < m; ++i) {
      const double f = A[i * m + c] / d;
      if (f == 0.0) {
        continue;
      }
      A[i * m + c] = 0.0;
      for (int64_t j = c + 1; j < m; ++j) {
        A[i * m + j] -= f * A[c * m + j];
      }
      for (int64_t j = 0; j < r; ++j) {
        B[i * r + j] -= f * B[c * r + j];
      }
    }
  }
  for (int64_t c = m - 1; c >= 0; --c) {
    const double d = A[c * m + c];
    for (int64_t j = 0; j < r; ++j) {
      double acc = B[c * r + j];
      for (int64_t k = c + 1; k < m; ++k) {
        acc -= A[c * m + k] * B[k * r + j];
      }
      B[c * r + j] = acc / d;
    }
  }
  return true;
}

}  // namespace detail
}  // namespace tensegrity_stiffness

#endif  // TENSEGRITY_STIFFNESS__SRC__DENSE_SOLVE_HPP_
