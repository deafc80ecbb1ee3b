// Compiled kernel of tensegrity_stiffness.mechanics.chain: the frames of a spine, the implied tip
// wrench and the exact tip stiffness (the conventions and the derivation are in
// mechanics/chain.py's docstring):
//   P_1 = I, L_i = P_i T_i, P_{i+1} = L_i O_i, T_tip = L_N O_tool;
//   residuals r_i = F_i + Ad_{P_i}^T B_i, B_i = W + sum_{k >= i} w_k (w_k the link weights);
//   D_ij = -[i = j] K_c,i + Ad_{P_i}^T E_ij Ad_{P_j},
//   E_ij = [j < i] M(B_i) + sum_{k >= max(i, j)} N_k,
//   C = -[Ad_{P_1} ... Ad_{P_N}] D^-1 [Ad_{P_1}^T; ...; Ad_{P_N}^T],  K_tip = C^-1 (base frame)
//   (without weights D is block lower triangular: block forward substitution, O(N); with them
//   an LU of D with partial pivoting),
//   K_tool = Ad_{T_tip}^T K_tip Ad_{T_tip}.
// Twists [dv; dw], wrenches [f; m]; Ad_P = [[R, hat(p) R], [0, R]]. The numpy implementation in
// mechanics/chain.py stays the reference and the fallback (test/kernel/test_chain_kernel.py). The
// C ABI is declared in include/tensegrity_stiffness/kernel.h.

#include "tensegrity_stiffness/kernel.h"

#include "dense_solve.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

namespace {

using tensegrity_stiffness::detail::solve_in_place;
using Mat6 = double[6][6];

// out = a b for 4x4 row-major rigid transforms.
void compose(const double* a, const double* b, double* out) {
  double r[16];
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      r[4 * i + j] = a[4 * i] * b[j] + a[4 * i + 1] * b[4 + j] + a[4 * i + 2] * b[8 + j] +
                     a[4 * i + 3] * b[12 + j];
    }
  }
  std::memcpy(out, r, sizeof(r));
}

// Ad_P (6x6) of a 4x4 pose.
void adjoint(const double* P, Mat6 Ad) {
  const double R[3][3] = {{P[0], P[1], P[2]}, {P[4], P[5], P[6]}, {P[8], P[9], P[10]}};
  const double p[3] = {P[3], P[7], P[11]};
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 6; ++j) {
      Ad[i][j] = 0.0;
    }
  }
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Ad[i][j] = R[i][j];
      Ad[i + 3][j + 3] = R[i][j];
    }
  }
  // hat(p) R.
  for (int j = 0; j < 3; ++j) {
    Ad[0][j + 3] = p[1] * R[2][j] - p[2] * R[1][j];
    Ad[1][j + 3] = p[2] * R[0][j] - p[0] * R[2][j];
    Ad[2][j + 3] = p[0] * R[1][j] - p[1] * R[0][j];
  }
}

void hat3(const double* w, double H[3][3]) {
  H[0][0] = 0.0;
  H[0][1] = -w[2];
  H[0][2] = w[1];
  H[1][0] = w[2];
  H[1][1] = 0.0;
  H[1][2] = -w[0];
  H[2][0] = -w[1];
  H[2][1] = w[0];
  H[2][2] = 0.0;
}

// M([f; m]) = [[0, hat(f)], [hat(f), hat(m)]].
void load_transport(const double* B, Mat6 M) {
  double hf[3][3], hm[3][3];
  hat3(B, hf);
  hat3(B + 3, hm);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      M[i][j] = 0.0;
      M[i][j + 3] = hf[i][j];
      M[i + 3][j] = hf[i][j];
      M[i + 3][j + 3] = hm[i][j];
    }
  }
}

// out = A^T B C (6x6).
void at_b_c(const Mat6 A, const Mat6 B, const Mat6 C, Mat6 out) {
  double BC[6][6];
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 6; ++j) {
      double acc = 0.0;
      for (int k = 0; k < 6; ++k) {
        acc += B[i][k] * C[k][j];
      }
      BC[i][j] = acc;
    }
  }
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 6; ++j) {
      double acc = 0.0;
      for (int k = 0; k < 6; ++k) {
        acc += A[k][i] * BC[k][j];
      }
      out[i][j] = acc;
    }
  }
}

// K = C^-1 into K_base and Ad_tip^T K Ad_tip into K_tool (either may be null): TSK_OK, or
// TSK_ERROR_SINGULAR_COMPLIANCE when the compliance C (overwritten) is singular.
int64_t invert_and_store(double* C, const double* tip, double* K_base, double* K_tool) {
  double K[36];
  for (int i = 0; i < 36; ++i) {
    K[i] = (i % 7 == 0) ? 1.0 : 0.0;
  }
  if (!solve_in_place(C, K, 6, 6)) {
    return TSK_ERROR_SINGULAR_COMPLIANCE;
  }
  if (K_base) {
    std::memcpy(K_base, K, sizeof(K));
  }
  if (K_tool) {
    Mat6 At, Kt, out;
    adjoint(tip, At);
    std::memcpy(Kt, K, sizeof(K));
    at_b_c(At, Kt, At, out);
    std::memcpy(K_tool, out, sizeof(out));
  }
  return TSK_OK;
}

}  // namespace

extern "C" {

int64_t tsk_chain_frames(int64_t n_joints, const double* T, const double* offsets,
                         const double* tool, double* out, int64_t out_len) {
  try {
    const int64_t n = n_joints;
    if (n < 1 || n > (int64_t{1} << 40)) {
      return TSK_ERROR_COUNT;
    }
    if (T == nullptr || tool == nullptr || out == nullptr || (n > 1 && offsets == nullptr)) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (out_len < 32 * n + 16) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    double* P = out;
    double* L = out + 16 * n;
    double current[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    for (int64_t i = 0; i < n; ++i) {
      std::memcpy(P + 16 * i, current, sizeof(current));
      compose(current, T + 16 * i, L + 16 * i);
      if (i < n - 1) {
        compose(L + 16 * i, offsets + 16 * i, current);
      }
    }
    compose(L + 16 * (n - 1), tool, out + 32 * n);
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

}  // extern "C"

namespace {

// The computation of tsk_chain_tip (its contract is in kernel.h), on checked arguments.
int64_t chain_tip(int64_t n, const double* P, const double* L, const double* tip, const double* F,
                  const double* Kc, const double* weights, const double* coms, const double* W_in,
                  double* W_out, double* K_base, double* K_tool) {
  // Link weights as base wrenches w_k = [G_k; x_k x G_k], x_k = L_k c_k.
  std::vector<double> w(weights ? 6 * n : 0), x(weights ? 3 * n : 0);
  if (weights) {
    for (int64_t k = 0; k < n; ++k) {
      const double* Lk = L + 16 * k;
      const double* c = coms + 3 * k;
      const double* G = weights + 3 * k;
      double* xk = x.data() + 3 * k;
      for (int i = 0; i < 3; ++i) {
        xk[i] = Lk[4 * i] * c[0] + Lk[4 * i + 1] * c[1] + Lk[4 * i + 2] * c[2] + Lk[4 * i + 3];
      }
      double* wk = w.data() + 6 * k;
      wk[0] = G[0];
      wk[1] = G[1];
      wk[2] = G[2];
      wk[3] = xk[1] * G[2] - xk[2] * G[1];
      wk[4] = xk[2] * G[0] - xk[0] * G[2];
      wk[5] = xk[0] * G[1] - xk[1] * G[0];
    }
  }
  double W[6];
  if (W_in) {
    std::memcpy(W, W_in, sizeof(W));
  } else {
    // -Ad_{P_N}^-T F_N: f = R F_f, m = R F_m + p x f; less the weight of link N.
    const double* PN = P + 16 * (n - 1);
    const double* FN = F + 6 * (n - 1);
    double f[3], m[3];
    for (int i = 0; i < 3; ++i) {
      f[i] = PN[4 * i] * FN[0] + PN[4 * i + 1] * FN[1] + PN[4 * i + 2] * FN[2];
      m[i] = PN[4 * i] * FN[3] + PN[4 * i + 1] * FN[4] + PN[4 * i + 2] * FN[5];
    }
    const double p[3] = {PN[3], PN[7], PN[11]};
    m[0] += p[1] * f[2] - p[2] * f[1];
    m[1] += p[2] * f[0] - p[0] * f[2];
    m[2] += p[0] * f[1] - p[1] * f[0];
    for (int i = 0; i < 3; ++i) {
      W[i] = -f[i];
      W[i + 3] = -m[i];
    }
    if (weights) {
      for (int i = 0; i < 6; ++i) {
        W[i] -= w[6 * (n - 1) + i];
      }
    }
  }
  if (W_out) {
    std::memcpy(W_out, W, sizeof(W));
  }
  if (!K_base && !K_tool) {
    return TSK_OK;
  }
  const int64_t m6 = 6 * n;
  std::vector<double> Ad(36 * n);
  for (int64_t i = 0; i < n; ++i) {
    adjoint(P + 16 * i, reinterpret_cast<double(*)[6]>(Ad.data() + 36 * i));
  }
  auto ad = [&Ad](int64_t i) { return reinterpret_cast<const double(*)[6]>(Ad.data() + 36 * i); };
  // E_ij per block: loads B_i (suffix sums of w) and transports Nsum_k = sum_{k' >= k} N_k'.
  std::vector<double> B(6 * n), Nsum(weights ? 36 * n : 0);
  for (int64_t i = n - 1; i >= 0; --i) {
    for (int c = 0; c < 6; ++c) {
      B[6 * i + c] = (i == n - 1 ? W[c] : B[6 * (i + 1) + c]) + (weights ? w[6 * i + c] : 0.0);
    }
  }
  if (weights) {
    for (int64_t k = n - 1; k >= 0; --k) {
      double hG[3][3], hx[3][3];
      hat3(weights + 3 * k, hG);
      hat3(x.data() + 3 * k, hx);
      double* Nk = Nsum.data() + 36 * k;
      for (int i = 0; i < 36; ++i) {
        Nk[i] = k == n - 1 ? 0.0 : Nsum[36 * (k + 1) + i];
      }
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          Nk[6 * (i + 3) + j] -= hG[i][j];
          double acc = 0.0;
          for (int e = 0; e < 3; ++e) {
            acc += hG[i][e] * hx[e][j];
          }
          Nk[6 * (i + 3) + j + 3] += acc;
        }
      }
    }
  }
  bool loaded = false;
  for (int c = 0; c < 6; ++c) {
    loaded = loaded || W[c] != 0.0;
  }
  double C[36] = {0.0};
  if (!weights) {
    // Without weights D is block lower triangular, D_ij = Ad_i^T M(W) Ad_j (j < i) and
    // D_ii = -K_c,i: block forward substitution, X_i = -K_c,i^-1 Ad_i^T (I - M(W) S_i) with
    // S_i = sum_{j < i} Ad_j X_j, and C = -S_N.
    Mat6 Mw, S = {{0.0}};
    load_transport(W, Mw);
    for (int64_t i = 0; i < n; ++i) {
      const auto A = ad(i);
      double IMS[6][6];
      for (int a = 0; a < 6; ++a) {
        for (int b = 0; b < 6; ++b) {
          double acc = a == b ? 1.0 : 0.0;
          if (loaded) {
            for (int e = 0; e < 6; ++e) {
              acc -= Mw[a][e] * S[e][b];
            }
          }
          IMS[a][b] = acc;
        }
      }
      double rhs[36], negKc[36];
      for (int a = 0; a < 6; ++a) {
        for (int b = 0; b < 6; ++b) {
          double acc = 0.0;
          for (int e = 0; e < 6; ++e) {
            acc += A[e][a] * IMS[e][b];
          }
          rhs[6 * a + b] = acc;
          negKc[6 * a + b] = -Kc[36 * i + 6 * a + b];
        }
      }
      if (!solve_in_place(negKc, rhs, 6, 6)) {
        return TSK_ERROR_SINGULAR_SYSTEM;
      }
      for (int a = 0; a < 6; ++a) {
        for (int b = 0; b < 6; ++b) {
          double acc = 0.0;
          for (int e = 0; e < 6; ++e) {
            acc += A[a][e] * rhs[6 * e + b];
          }
          S[a][b] += acc;
        }
      }
    }
    for (int a = 0; a < 6; ++a) {
      for (int b = 0; b < 6; ++b) {
        C[6 * a + b] = -S[a][b];
      }
    }
    return invert_and_store(C, tip, K_base, K_tool);
  }
  std::vector<double> D(m6 * m6, 0.0);
  Mat6 E, block, M;
  for (int64_t i = 0; i < n; ++i) {
    if (weights || loaded) {
      load_transport(B.data() + 6 * i, M);
    }
    for (int64_t j = 0; j < n; ++j) {
      bool any = false;
      for (int a = 0; a < 6; ++a) {
        for (int b = 0; b < 6; ++b) {
          E[a][b] = 0.0;
        }
      }
      if (j < i && (weights || loaded)) {
        std::memcpy(E, M, sizeof(E));
        any = true;
      }
      if (weights) {
        const double* Nk = Nsum.data() + 36 * (i > j ? i : j);
        for (int a = 0; a < 6; ++a) {
          for (int b = 0; b < 6; ++b) {
            E[a][b] += Nk[6 * a + b];
          }
        }
        any = true;
      }
      if (any) {
        at_b_c(ad(i), E, ad(j), block);
      }
      for (int a = 0; a < 6; ++a) {
        for (int b = 0; b < 6; ++b) {
          double v = any ? block[a][b] : 0.0;
          if (i == j) {
            v -= Kc[36 * i + 6 * a + b];
          }
          D[(6 * i + a) * m6 + 6 * j + b] = v;
        }
      }
    }
  }
  // X = D^-1 [Ad_1^T; ...; Ad_N^T] (6N x 6), then C = -sum_j Ad_j X_j.
  std::vector<double> X(m6 * 6);
  for (int64_t i = 0; i < n; ++i) {
    const auto A = ad(i);
    for (int a = 0; a < 6; ++a) {
      for (int b = 0; b < 6; ++b) {
        X[(6 * i + a) * 6 + b] = A[b][a];
      }
    }
  }
  if (!solve_in_place(D.data(), X.data(), m6, 6)) {
    return TSK_ERROR_SINGULAR_SYSTEM;
  }
  for (int64_t j = 0; j < n; ++j) {
    const auto A = ad(j);
    for (int a = 0; a < 6; ++a) {
      for (int b = 0; b < 6; ++b) {
        double acc = 0.0;
        for (int e = 0; e < 6; ++e) {
          acc += A[a][e] * X[(6 * j + e) * 6 + b];
        }
        C[6 * a + b] -= acc;
      }
    }
  }
  return invert_and_store(C, tip, K_base, K_tool);
}

}  // namespace

extern "C" {

int64_t tsk_chain_tip(int64_t n_joints, const double* P, const double* L, const double* tip,
                      const double* F, const double* Kc, const double* weights,
                      const double* coms, const double* W_in, int64_t outputs, double* out,
                      int64_t out_len) {
  // std::vector may throw std::bad_alloc: caught here, never across the C boundary.
  try {
    if (n_joints < 1 || n_joints > (int64_t{1} << 20)) {
      return TSK_ERROR_COUNT;
    }
    if (P == nullptr || L == nullptr || tip == nullptr || F == nullptr || Kc == nullptr ||
        out == nullptr || (weights != nullptr && coms == nullptr)) {
      return TSK_ERROR_NULL_POINTER;
    }
    if ((outputs & ~int64_t{TSK_TIP_BASE | TSK_TIP_TOOL}) != 0) {
      return TSK_ERROR_ARGUMENT;
    }
    if (out_len < 6 + 36 + 36) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    return chain_tip(n_joints, P, L, tip, F, Kc, weights, coms, W_in, out,
                     (outputs & TSK_TIP_BASE) ? out + 6 : nullptr,
                     (outputs & TSK_TIP_TOOL) ? out + 42 : nullptr);
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

}  // extern "C"
