// Compiled kernel of the structures (tensegrity_stiffness/structures/structure.py): for rigid
// bodies at poses P_i = (R_i, t_i) joined by strings, the string vectors s_j = x_B - x_A, lengths,
// tensions (the joint's force law, eq. 8 with docs/errata.md), the strings' wrench on every body
// [f; m] in the world about its origin and the stiffness K = -dW/d(delta) (6N x 6N, delta the
// stacked spatial twists [dv; dw] of the bodies in the world). Per string, with
// A = gamma s s^T + beta I (beta = phi / l, gamma = (phi' - beta) / l^2), Z(x) = [I; hat(x)] and
// E(f, x) = [[0, 0], [hat(f), -hat(f) hat(x)]]:
//   K_aa += Z_A A Z_A^T + E(f, x_A),   K_ab -= Z_A A Z_B^T,
//   K_bb += Z_B A Z_B^T + E(-f, x_B),  K_ba -= Z_B A Z_A^T.
// Its numpy twin Structure.evaluate_numpy is the reference; test/structures/
// test_structure_kernel.py holds the two together (1e-12). The C ABI is declared in
// include/tensegrity_stiffness/structure_kernel.h; status codes, modes and force laws are those of
// kernel.h (the joint's library).

#include <cmath>
#include <cstdint>
#include <cstring>

#include "tensegrity_stiffness/structure_kernel.h"

#include "string_law.hpp"

namespace {

constexpr int64_t kMaxCount = int64_t(1) << 20;
// At most this many bodies: the stiffness alone is 36 N^2 doubles (300 MB at 1024).
constexpr int64_t kMaxBodies = 1024;

// out (6x3) = M (6x3) hat(x).
void times_hat(const double M[6][3], const double* x, double out[6][3]) {
  for (int i = 0; i < 6; ++i) {
    out[i][0] = M[i][1] * x[2] - M[i][2] * x[1];
    out[i][1] = M[i][2] * x[0] - M[i][0] * x[2];
    out[i][2] = M[i][0] * x[1] - M[i][1] * x[0];
  }
}

// ZA = [A; hat(x) A] (6x3).
void z_times(const double A[3][3], const double* x, double ZA[6][3]) {
  for (int c = 0; c < 3; ++c) {
    ZA[0][c] = A[0][c];
    ZA[1][c] = A[1][c];
    ZA[2][c] = A[2][c];
    ZA[3][c] = x[1] * A[2][c] - x[2] * A[1][c];
    ZA[4][c] = x[2] * A[0][c] - x[0] * A[2][c];
    ZA[5][c] = x[0] * A[1][c] - x[1] * A[0][c];
  }
}

// K[row block bi, column block bj] += sign * [ZA, -ZA hat(x)].
void add_block(double* K, int64_t stride, int64_t bi, int64_t bj, double sign,
               const double ZA[6][3], const double* x) {
  double ZAh[6][3];
  times_hat(ZA, x, ZAh);
  for (int r = 0; r < 6; ++r) {
    double* row = K + (6 * bi + r) * stride + 6 * bj;
    for (int c = 0; c < 3; ++c) {
      row[c] += sign * ZA[r][c];
      row[3 + c] -= sign * ZAh[r][c];
    }
  }
}

// K[block bi, bi] += E(f, x) = [[0, 0], [hat(f), -hat(f) hat(x)]], -hat(f) hat(x) = (f.x) I - x f^T.
void add_geometric(double* K, int64_t stride, int64_t bi, const double* f, const double* x) {
  const double fx = f[0] * x[0] + f[1] * x[1] + f[2] * x[2];
  const double hf[3][3] = {{0.0, -f[2], f[1]}, {f[2], 0.0, -f[0]}, {-f[1], f[0], 0.0}};
  for (int r = 0; r < 3; ++r) {
    double* row = K + (6 * bi + 3 + r) * stride + 6 * bi;
    for (int c = 0; c < 3; ++c) {
      row[c] += hf[r][c];
      row[3 + c] += (r == c ? fx : 0.0) - x[r] * f[c];
    }
  }
}

// The world point of `p` on body `body` (-1: the world itself).
void world_point(const double* transforms, int64_t body, const double* p, double* x) {
  if (body < 0) {
    x[0] = p[0];
    x[1] = p[1];
    x[2] = p[2];
    return;
  }
  const double* T = transforms + 16 * body;
  for (int i = 0; i < 3; ++i) {
    x[i] = T[4 * i] * p[0] + T[4 * i + 1] * p[1] + T[4 * i + 2] * p[2] + T[4 * i + 3];
  }
}

void add_wrench(double* W, int64_t body, double sign, const double* f, const double* x) {
  if (body < 0) {
    return;
  }
  double* w = W + 6 * body;
  w[0] += sign * f[0];
  w[1] += sign * f[1];
  w[2] += sign * f[2];
  w[3] += sign * (x[1] * f[2] - x[2] * f[1]);
  w[4] += sign * (x[2] * f[0] - x[0] * f[2]);
  w[5] += sign * (x[0] * f[1] - x[1] * f[0]);
}

}  // namespace

int64_t tsk_structure_size(int64_t n_bodies, int64_t n_strings) {
  if (n_bodies < 1 || n_strings < 1 || n_bodies > kMaxBodies || n_strings > kMaxCount) {
    return TSK_ERROR_COUNT;
  }
  return 5 * n_strings + 6 * n_bodies + 36 * n_bodies * n_bodies + (2 * n_strings + 7) / 8;
}

int64_t tsk_structure_evaluate(int64_t n_bodies, int64_t n_strings, const int64_t* ends,
                               const double* points, const double* k, const double* rest,
                               const double* max_stretch, int64_t law,
                               double min_string_length, const double* transforms, int64_t mode,
                               double* out, int64_t out_size) {
  try {
    const int64_t size = tsk_structure_size(n_bodies, n_strings);
    if (size < 0) {
      return size;
    }
    if (ends == nullptr || points == nullptr || k == nullptr || rest == nullptr ||
        max_stretch == nullptr || transforms == nullptr || out == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    if ((mode != TSK_MODE_FULL && mode != TSK_MODE_WRENCH) ||
        (law != TSK_LAW_HOOKE && law != TSK_LAW_PAPER)) {
      return TSK_ERROR_ARGUMENT;
    }
    if (out_size < size) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    for (int64_t j = 0; j < 2 * n_strings; ++j) {
      if (ends[j] < -1 || ends[j] >= n_bodies) {
        return TSK_ERROR_ARGUMENT;
      }
    }
    const int64_t n = n_strings;
    double* s = out;
    double* lengths = s + 3 * n;
    double* phi = lengths + n;
    double* W = phi + n;
    double* K = W + 6 * n_bodies;
    const int64_t stride = 6 * n_bodies;
    uint8_t* slack = reinterpret_cast<uint8_t*>(K + stride * stride);
    uint8_t* saturated = slack + n;
    std::memset(W, 0, sizeof(double) * 6 * n_bodies);
    const bool full = mode == TSK_MODE_FULL;
    if (full) {
      std::memset(K, 0, sizeof(double) * stride * stride);
    }
    for (int64_t j = 0; j < n; ++j) {
      const int64_t ia = ends[2 * j], ib = ends[2 * j + 1];
      double xa[3], xb[3], sv[3];
      world_point(transforms, ia, points + 6 * j, xa);
      world_point(transforms, ib, points + 6 * j + 3, xb);
      for (int i = 0; i < 3; ++i) {
        sv[i] = xb[i] - xa[i];
        s[3 * j + i] = sv[i];
      }
      const double l2 = sv[0] * sv[0] + sv[1] * sv[1] + sv[2] * sv[2];
      const double l = std::sqrt(l2);
      if (l < min_string_length) {
        return TSK_ERROR_ZERO_LENGTH;
      }
      lengths[j] = l;
      const double r0 = rest[j];
      const tensegrity_stiffness::detail::StringForce force =
          tensegrity_stiffness::detail::string_force(l, r0, max_stretch[j], k[j], law);
      slack[j] = force.slack;
      saturated[j] = force.saturated;
      const double tension = force.tension;
      const double dtension = force.dtension;
      phi[j] = tension;
      const double beta = tension / l;
      const double f[3] = {beta * sv[0], beta * sv[1], beta * sv[2]};
      add_wrench(W, ia, 1.0, f, xa);
      add_wrench(W, ib, -1.0, f, xb);
      if (!full || (tension == 0.0 && dtension == 0.0)) {
        continue;
      }
      const double gamma = (dtension - beta) / l2;
      double A[3][3];
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
          A[r][c] = gamma * sv[r] * sv[c] + (r == c ? beta : 0.0);
        }
      }
      const double minus_f[3] = {-f[0], -f[1], -f[2]};
      if (ia >= 0) {
        double ZA[6][3];
        z_times(A, xa, ZA);
        add_block(K, stride, ia, ia, 1.0, ZA, xa);
        add_geometric(K, stride, ia, f, xa);
        if (ib >= 0) {
          add_block(K, stride, ia, ib, -1.0, ZA, xb);
        }
      }
      if (ib >= 0) {
        double ZB[6][3];
        z_times(A, xb, ZB);
        add_block(K, stride, ib, ib, 1.0, ZB, xb);
        add_geometric(K, stride, ib, minus_f, xb);
        if (ia >= 0) {
          add_block(K, stride, ib, ia, -1.0, ZB, xa);
        }
      }
    }
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}
