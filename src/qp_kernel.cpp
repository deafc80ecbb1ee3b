// Compiled kernel of the stiffness controller's warm start (tensegrity_stiffness/control/
// controller.py, solve_box_qp, step 1): the tension QP min 1/2 t'Pt - c't s.t. A t = b,
// lo <= t <= hi on the face of the last tick's working set. The free tensions and the equality
// multipliers solve the face's KKT system
//   [[P_FF, A_F'], [A_F, 0]] [t_F; nu] = [c_F - P_FX t_X; b - A_X t_X]
// (Gaussian elimination with partial pivoting), and the face is accepted when the solution is
// inside the box (to a slack), satisfies A t = b and every bound of the working set has a
// nonnegative multiplier. The numpy implementation in control/controller.py (warm_face_numpy)
// stays the reference and the fallback (a singular or inaccurate KKT system goes to its least squares);
// test/control/test_control.py holds this kernel to it. The C ABI is declared in
// include/tensegrity_stiffness/kernel.h.

#include "tensegrity_stiffness/kernel.h"

#include "dense_solve.hpp"

#include <cmath>
#include <cstdint>
#include <vector>

namespace {

using tensegrity_stiffness::detail::solve_in_place;

constexpr int64_t kMaxQpCount = int64_t{1} << 20;

}  // namespace

extern "C" {

int64_t tsk_qp_face_size(int64_t n, int64_t m) {
  if (n < 1 || m < 0 || n > kMaxQpCount || m > kMaxQpCount) {
    return TSK_ERROR_COUNT;
  }
  return n * n + m * n + 7 * n + 2 * m + 1;
}

int64_t tsk_qp_warm_face(int64_t n, int64_t m, double feasibility_tolerance,
                         double multiplier_tolerance, double residual_tolerance,
                         double bound_slack, double* buf, int64_t buf_len) {
  try {
    if (buf == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    const int64_t size = tsk_qp_face_size(n, m);
    if (size < 0) {
      return size;
    }
    if (buf_len < size) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    if (!(feasibility_tolerance >= 0.0) || !(multiplier_tolerance >= 0.0) ||
        !(residual_tolerance >= 0.0) || !(bound_slack >= 0.0)) {
      return TSK_ERROR_ARGUMENT;
    }
    const double* P = buf;
    const double* c = P + n * n;
    const double* A = c + n;
    const double* b = A + m * n;
    const double* lo = b + m;
    const double* hi = lo + n;
    const double* start = hi + n;
    const double* at_lo = start + n;
    const double* at_hi = at_lo + n;
    double* t = buf + (n * n + m * n + 6 * n + m);
    double* nu = t + n;
    double* outcome = nu + m;
    // The start on the face: the working set's bounds, the rest at the start.
    std::vector<int64_t> free_index;
    free_index.reserve(static_cast<size_t>(n));
    for (int64_t i = 0; i < n; ++i) {
      const bool low = at_lo[i] != 0.0, high = at_hi[i] != 0.0;
      t[i] = low ? lo[i] : (high ? hi[i] : start[i]);
      if (!low && !high) {
        free_index.push_back(i);
      }
    }
    for (int64_t k = 0; k < m; ++k) {
      nu[k] = 0.0;
    }
    const int64_t nf = static_cast<int64_t>(free_index.size());
    if (nf == 0) {
      *outcome = TSK_FACE_REJECTED;
      return TSK_OK;
    }
    // The KKT system of the face.
    const int64_t k_size = nf + m;
    std::vector<double> K(static_cast<size_t>(k_size * k_size), 0.0), rhs(k_size);
    std::vector<bool> is_free(static_cast<size_t>(n), false);
    for (int64_t f : free_index) {
      is_free[f] = true;
    }
    for (int64_t r = 0; r < nf; ++r) {
      const int64_t i = free_index[r];
      double acc = c[i];
      for (int64_t j = 0; j < n; ++j) {
        if (!is_free[j]) {
          acc -= P[n * i + j] * t[j];
        }
      }
      rhs[r] = acc;
      for (int64_t s = 0; s < nf; ++s) {
        K[k_size * r + s] = P[n * i + free_index[s]];
      }
      for (int64_t k = 0; k < m; ++k) {
        K[k_size * r + nf + k] = A[n * k + i];
        K[k_size * (nf + k) + r] = A[n * k + i];
      }
    }
    for (int64_t k = 0; k < m; ++k) {
      double acc = b[k];
      for (int64_t j = 0; j < n; ++j) {
        if (!is_free[j]) {
          acc -= A[n * k + j] * t[j];
        }
      }
      rhs[nf + k] = acc;
    }
    std::vector<double> LU(K), sol(rhs);
    if (!solve_in_place(LU.data(), sol.data(), k_size, 1)) {
      *outcome = TSK_FACE_SINGULAR;
      return TSK_OK;
    }
    // A near-singular face leaves a large residual (NaN fails the test too).
    double residual = 0.0, largest = 0.0;
    for (int64_t r = 0; r < k_size; ++r) {
      double acc = 0.0;
      for (int64_t s = 0; s < k_size; ++s) {
        acc += K[k_size * r + s] * sol[s];
      }
      residual = std::fmax(residual, std::fabs(acc - rhs[r]));
      largest = std::fmax(largest, std::fabs(rhs[r]));
      if (std::isnan(acc)) {
        residual = NAN;
        break;
      }
    }
    if (!(residual <= residual_tolerance * (1.0 + largest))) {
      *outcome = TSK_FACE_SINGULAR;
      return TSK_OK;
    }
    for (int64_t r = 0; r < nf; ++r) {
      t[free_index[r]] = sol[r];
    }
    for (int64_t k = 0; k < m; ++k) {
      nu[k] = sol[nf + k];
    }
    // Inside the box (to the slack) and on A t = b.
    bool inside = true;
    for (int64_t i = 0; i < n; ++i) {
      const double slack = bound_slack * std::fmax(1.0, std::fabs(hi[i] - lo[i]));
      if (!(t[i] >= lo[i] - slack && t[i] <= hi[i] + slack)) {
        inside = false;
      }
    }
    double gap = 0.0;
    for (int64_t k = 0; k < m; ++k) {
      double acc = 0.0;
      for (int64_t j = 0; j < n; ++j) {
        acc += A[n * k + j] * t[j];
      }
      gap += (acc - b[k]) * (acc - b[k]);
    }
    if (!inside || !(std::sqrt(gap) <= feasibility_tolerance)) {
      *outcome = TSK_FACE_REJECTED;
      return TSK_OK;
    }
    // The multipliers of the working set's bounds: grad = P t - c + A' nu, >= 0 at lo, <= 0 at
    // hi, down to -tolerance max(1, |P|, |c|).
    double scale = 1.0;
    for (int64_t i = 0; i < n * n; ++i) {
      scale = std::fmax(scale, std::fabs(P[i]));
    }
    for (int64_t i = 0; i < n; ++i) {
      scale = std::fmax(scale, std::fabs(c[i]));
    }
    bool optimal = true;
    for (int64_t i = 0; i < n; ++i) {
      if (is_free[i]) {
        continue;
      }
      double grad = -c[i];
      for (int64_t j = 0; j < n; ++j) {
        grad += P[n * i + j] * t[j];
      }
      for (int64_t k = 0; k < m; ++k) {
        grad += A[n * k + i] * nu[k];
      }
      const double mu = at_lo[i] != 0.0 ? grad : -grad;
      if (!(mu >= -multiplier_tolerance * scale)) {
        optimal = false;
      }
    }
    if (!optimal) {
      *outcome = TSK_FACE_REJECTED;
      return TSK_OK;
    }
    for (int64_t i = 0; i < n; ++i) {
      t[i] = std::fmin(std::fmax(t[i], lo[i]), hi[i]);
    }
    *outcome = TSK_FACE_OPTIMAL;
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

}  // extern "C"
