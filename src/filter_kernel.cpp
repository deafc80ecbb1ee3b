// Compiled kernel of the joint filter's per-step linear algebra (tensegrity_stiffness/
// estimation/joint_filter.py): the body-form equations of motion and their Jacobians
// (body_dynamics), one Rosenbrock step of the state with its covariance propagation
// (JointFilter._substep) and the stacked whitened EKF update (kalman_update's solve with every
// reading kept). Everything the filter decides (outliers, NIS tests, restarts) stays in
// Python; the numpy lines in joint_filter.py stay the reference and the fallback
// (test/kernel/test_filter_kernel.py and test/estimation/test_joint_filter.py hold this kernel
// to them). The C ABI is declared in include/tensegrity_stiffness/kernel.h.

#include "tensegrity_stiffness/kernel.h"

#include "dense_solve.hpp"

#include <cmath>
#include <cstdint>
#include <vector>

namespace {

using tensegrity_stiffness::detail::solve_in_place;

constexpr int64_t kMaxStrings = int64_t{1} << 20;
constexpr int64_t kMaxRows = int64_t{1} << 12;
// [f; m] <-> [m; f]
constexpr int kSwap[6] = {3, 4, 5, 0, 1, 2};

// C(p) = [[hat(p_m), hat(p_f)], [hat(p_f), 0]] (6 x 6, row-major) of a wrench p = [m; f].
void hat_pair(const double* p, double* out) {
  const double a = p[0], b = p[1], c = p[2], d = p[3], e = p[4], f = p[5];
  const double v[36] = {0.0, -c, b, 0.0, -f, e,   c, 0.0, -a, f, 0.0, -d,
                        -b, a, 0.0, -e, d, 0.0,   0.0, -f, e, 0.0, 0.0, 0.0,
                        f, 0.0, -d, 0.0, 0.0, 0.0, -e, d, 0.0, 0.0, 0.0, 0.0};
  for (int i = 0; i < 36; ++i) {
    out[i] = v[i];
  }
}

// C = A B for row-major A (m x k), B (k x r).
// (C must not overlap A or B.) Row-update form: the sums of a row are independent. With
// kSkipZeros (matmul_sparse) the zero entries of A are skipped (adding 0 b is exact for
// finite B).
template <bool kSkipZeros>
void matmul_rows(const double* __restrict A, const double* __restrict B, double* __restrict C,
                 int64_t m, int64_t k, int64_t r) {
  for (int64_t i = 0; i < m; ++i) {
    double* __restrict c = C + i * r;
    for (int64_t j = 0; j < r; ++j) {
      c[j] = 0.0;
    }
    for (int64_t l = 0; l < k; ++l) {
      const double a = A[i * k + l];
      if constexpr (kSkipZeros) {
        if (a == 0.0) {
          continue;
        }
      }
      const double* __restrict b = B + l * r;
      for (int64_t j = 0; j < r; ++j) {
        c[j] += a * b[j];
      }
    }
  }
}

void matmul(const double* __restrict A, const double* __restrict B, double* __restrict C,
            int64_t m, int64_t k, int64_t r) {
  matmul_rows<false>(A, B, C, m, k, r);
}

// matmul for a sparse A (the update's H: a string's row has 6 nonzero columns of 18; the
// step's Phi).
void matmul_sparse(const double* __restrict A, const double* __restrict B, double* __restrict C,
                   int64_t m, int64_t k, int64_t r) {
  matmul_rows<true>(A, B, C, m, k, r);
}

// Inverse of a 3 x 3 matrix by its adjugate; false when the determinant is zero.
bool inverse3(const double* M, double* out) {
  const double c00 = M[4] * M[8] - M[5] * M[7];
  const double c01 = M[5] * M[6] - M[3] * M[8];
  const double c02 = M[3] * M[7] - M[4] * M[6];
  const double det = M[0] * c00 + M[1] * c01 + M[2] * c02;
  if (det == 0.0 || !std::isfinite(det)) {
    return false;
  }
  const double s = 1.0 / det;
  out[0] = c00 * s;
  out[1] = (M[2] * M[7] - M[1] * M[8]) * s;
  out[2] = (M[1] * M[5] - M[2] * M[4]) * s;
  out[3] = c01 * s;
  out[4] = (M[0] * M[8] - M[2] * M[6]) * s;
  out[5] = (M[2] * M[3] - M[0] * M[5]) * s;
  out[6] = c02 * s;
  out[7] = (M[1] * M[6] - M[0] * M[7]) * s;
  out[8] = (M[0] * M[4] - M[1] * M[3]) * s;
  return true;
}

}  // namespace

extern "C" {

int64_t tsk_filter_body_dynamics(int64_t n_strings, int64_t damped, const double* T,
                                 const double* J, const double* length_jacobian,
                                 const double* wrench, const double* stiffness,
                                 const double* twist, const double* load, const double* inertia,
                                 const double* inertia_inverse, const double* damping,
                                 double* out, int64_t out_len) {
  try {
    if (n_strings < 1 || n_strings > kMaxStrings) {
      return TSK_ERROR_COUNT;
    }
    if (T == nullptr || J == nullptr || wrench == nullptr || stiffness == nullptr ||
        twist == nullptr || load == nullptr || inertia == nullptr ||
        inertia_inverse == nullptr || out == nullptr ||
        (damped != 0 && (length_jacobian == nullptr || damping == nullptr))) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (out_len < TSK_FILTER_BODY_SIZE) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    if (damped != 0 && damped != 1) {
      return TSK_ERROR_ARGUMENT;
    }
    const int64_t n = n_strings;
    // Ad_T for twists [w; v]
    double Ad[36];
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        const double r = T[i * 4 + j];
        Ad[i * 6 + j] = r;
        Ad[i * 6 + 3 + j] = 0.0;
        Ad[(3 + i) * 6 + 3 + j] = r;
      }
    }
    const double px = T[3], py = T[7], pz = T[11];
    const double hp[9] = {0.0, -pz, py, pz, 0.0, -px, -py, px, 0.0};
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        double acc = 0.0;
        for (int l = 0; l < 3; ++l) {
          acc += hp[i * 3 + l] * T[l * 4 + j];
        }
        Ad[(3 + i) * 6 + j] = acc;
      }
    }
    // J_l = [[G, 0], [Q, G]]; J_l^-1 = [[G^-1, 0], [-G^-1 Q G^-1, G^-1]]; J_b^-1 = J_l^-1 Ad_T
    double G3[9], Q3[9], Gi[9], tmp[9], low[9];
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        G3[i * 3 + j] = J[i * 6 + j];
        Q3[i * 3 + j] = J[(3 + i) * 6 + j];
      }
    }
    if (!inverse3(G3, Gi)) {
      return TSK_ERROR_SINGULAR_SYSTEM;
    }
    matmul(Gi, Q3, tmp, 3, 3, 3);
    matmul(tmp, Gi, low, 3, 3, 3);
    double Jl_inv[36];
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        Jl_inv[i * 6 + j] = Gi[i * 3 + j];
        Jl_inv[i * 6 + 3 + j] = 0.0;
        Jl_inv[(3 + i) * 6 + 3 + j] = Gi[i * 3 + j];
        Jl_inv[(3 + i) * 6 + j] = -low[i * 3 + j];
      }
    }
    double* screw_rate = out;
    double* twist_rate = out + 6;
    double* Jb_inv = out + 12;
    double* d_screw = out + 48;
    double* d_twist = out + 84;
    double* d_load = out + 120;
    matmul(Jl_inv, Ad, Jb_inv, 6, 6, 6);
    double spatial[6], AdT[36], GV[6], adT[36], coriolis[36], total[6], dtw[36];
    for (int i = 0; i < 6; ++i) {
      spatial[i] = wrench[kSwap[i]] + load[kSwap[i]];
      for (int j = 0; j < 6; ++j) {
        AdT[i * 6 + j] = Ad[j * 6 + i];
      }
    }
    matmul(inertia, twist, GV, 6, 6, 1);
    // ad_V^T = [[-hat(w), -hat(v)], [0, -hat(w)]]
    hat_pair(twist, adT);
    for (int i = 0; i < 36; ++i) {
      adT[i] = -adT[i];
    }
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        adT[(3 + i) * 6 + j] = 0.0;
        adT[(3 + i) * 6 + 3 + j] = adT[i * 6 + j];
      }
    }
    hat_pair(GV, coriolis);  // ad_V^T G V = C(G V) V
    double cv[6], as[6];
    matmul(coriolis, twist, cv, 6, 6, 1);
    matmul(AdT, spatial, as, 6, 6, 1);
    for (int i = 0; i < 6; ++i) {
      total[i] = cv[i] + as[i];
    }
    matmul(adT, inertia, dtw, 6, 6, 6);
    for (int i = 0; i < 36; ++i) {
      dtw[i] += coriolis[i];
    }
    if (damped) {
      std::vector<double> A(static_cast<size_t>(6 * n));
      matmul(length_jacobian, Jb_inv, A.data(), n, 6, 6);  // dl/dV
      double D[36] = {0.0};
      for (int64_t s = 0; s < n; ++s) {
        const double c = damping[s];
        const double* a = A.data() + 6 * s;
        for (int i = 0; i < 6; ++i) {
          const double ac = a[i] * c;
          for (int j = 0; j < 6; ++j) {
            D[i * 6 + j] += ac * a[j];
          }
        }
      }
      double dv[6];
      matmul(D, twist, dv, 6, 6, 1);
      for (int i = 0; i < 6; ++i) {
        total[i] -= dv[i];
      }
      for (int i = 0; i < 36; ++i) {
        dtw[i] -= D[i];
      }
    }
    // one product with G^-1 for the rate and its Jacobians: [total, AdT (K_swap + C(s) J_l),
    // d_twist, AdT[:, swap]]
    double Cs[36], CJ[36], Ks[36], dsc[36];
    hat_pair(spatial, Cs);
    matmul(Cs, J, CJ, 6, 6, 6);
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) {
        Ks[i * 6 + j] = stiffness[kSwap[i] * 6 + j] + CJ[i * 6 + j];
      }
    }
    matmul(AdT, Ks, dsc, 6, 6, 6);
    double stacked[6 * 19], solved[6 * 19];
    for (int i = 0; i < 6; ++i) {
      stacked[i * 19] = total[i];
      for (int j = 0; j < 6; ++j) {
        stacked[i * 19 + 1 + j] = dsc[i * 6 + j];
        stacked[i * 19 + 7 + j] = dtw[i * 6 + j];
        stacked[i * 19 + 13 + j] = AdT[i * 6 + kSwap[j]];
      }
    }
    matmul(inertia_inverse, stacked, solved, 6, 6, 19);
    matmul(Jb_inv, twist, screw_rate, 6, 6, 1);
    for (int i = 0; i < 6; ++i) {
      twist_rate[i] = solved[i * 19];
      for (int j = 0; j < 6; ++j) {
        d_screw[i * 6 + j] = solved[i * 19 + 1 + j];
        d_twist[i * 6 + j] = solved[i * 19 + 7 + j];
        d_load[i * 6 + j] = solved[i * 19 + 13 + j];
      }
    }
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

int64_t tsk_filter_propagate_size(int64_t size) {
  if (size != 12 && size != 18) {
    return TSK_ERROR_COUNT;
  }
  return size + size * size + size + 12;
}

int64_t tsk_filter_propagate(int64_t size, double h, const double* dynamics, const double* dx,
                             const double* twist_density, const double* load_density,
                             double* buf, int64_t buf_len) {
  try {
    if (size != 12 && size != 18) {
      return TSK_ERROR_COUNT;
    }
    if (dynamics == nullptr || twist_density == nullptr || buf == nullptr ||
        (size == 18 && load_density == nullptr)) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (buf_len < size + size * size + size + 12) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    if (!(h > 0.0) || !std::isfinite(h)) {
      return TSK_ERROR_ARGUMENT;
    }
    const int64_t s = size;
    double* x = buf;
    double* P = buf + s;
    double* step = buf + s + s * s;
    double* f_out = step + s;
    const double* screw_rate = dynamics;
    const double* twist_rate = dynamics + 6;
    const double* Jb_inv = dynamics + 12;
    const double* d_screw = dynamics + 48;
    const double* d_twist = dynamics + 84;
    const double* d_load = dynamics + 120;
    double A[144] = {0.0};
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) {
        A[i * 12 + 6 + j] = Jb_inv[i * 6 + j];
        A[(6 + i) * 12 + j] = d_screw[i * 6 + j];
        A[(6 + i) * 12 + 6 + j] = d_twist[i * 6 + j];
      }
    }
    double f[12];
    for (int i = 0; i < 6; ++i) {
      f[i] = screw_rate[i];
      f[6 + i] = twist_rate[i];
    }
    if (dx != nullptr) {
      // the last update's linearisation carried to its posterior to first order
      double Adx[12];
      matmul(A, dx, Adx, 12, 12, 1);
      for (int i = 0; i < 12; ++i) {
        f[i] += Adx[i];
      }
      if (s == 18) {
        double Ldx[6];
        matmul(d_load, dx + 12, Ldx, 6, 6, 1);
        for (int i = 0; i < 6; ++i) {
          f[6 + i] += Ldx[i];
        }
      }
    }
    const int64_t width = (s == 18) ? 19 : 13;
    const double half = 0.5 * h;
    double E[144], rhs[12 * 19];
    for (int i = 0; i < 12; ++i) {
      rhs[i * width] = f[i] * h;
      for (int j = 0; j < 12; ++j) {
        const double a = half * A[i * 12 + j];
        rhs[i * width + 1 + j] = a + (i == j ? 1.0 : 0.0);
        E[i * 12 + j] = -a + (i == j ? 1.0 : 0.0);
      }
      if (s == 18) {
        for (int j = 0; j < 6; ++j) {
          rhs[i * width + 13 + j] = i < 6 ? 0.0 : h * d_load[(i - 6) * 6 + j];
        }
      }
    }
    if (!solve_in_place(E, rhs, 12, width)) {
      return TSK_ERROR_SINGULAR_SYSTEM;
    }
    // Phi = [[sol[:, 1:13], sol[:, 13:]], [0, I]]
    std::vector<double> Phi(static_cast<size_t>(s * s), 0.0);
    for (int64_t i = 0; i < s; ++i) {
      if (i < 12) {
        for (int64_t j = 0; j < s; ++j) {
          Phi[i * s + j] = rhs[i * width + 1 + j];
        }
      } else {
        Phi[i * s + i] = 1.0;
      }
    }
    for (int i = 0; i < 12; ++i) {
      step[i] = rhs[i * width];
      f_out[i] = f[i];
    }
    for (int64_t i = 12; i < s; ++i) {
      step[i] = 0.0;
    }
    // discretised white noise: the twist's density through J_b^-1 into the screw
    std::vector<double> Q(static_cast<size_t>(s * s), 0.0);
    const double* q = twist_density;
    const double h3 = h * h * h / 3.0, h2 = h * h / 2.0;
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) {
        double acc = 0.0;
        for (int l = 0; l < 6; ++l) {
          acc += Jb_inv[i * 6 + l] * q[l] * Jb_inv[j * 6 + l];
        }
        Q[i * s + j] = acc * h3;
        const double c = Jb_inv[i * 6 + j] * q[j] * h2;
        Q[i * s + 6 + j] = c;
        Q[(6 + j) * s + i] = c;
      }
      Q[(6 + i) * s + 6 + i] = q[i] * h;
      if (s == 18) {
        Q[(12 + i) * s + 12 + i] = load_density[i] * h;
      }
    }
    // Phi P Phi^T + Q, both products in their row-update form (independent sums)
    std::vector<double> PhiP(static_cast<size_t>(s * s)), PhiT(static_cast<size_t>(s * s)),
        Pn(static_cast<size_t>(s * s));
    matmul_sparse(Phi.data(), P, PhiP.data(), s, s, s);
    for (int64_t i = 0; i < s; ++i) {
      for (int64_t j = 0; j < s; ++j) {
        PhiT[j * s + i] = Phi[i * s + j];
      }
    }
    matmul(PhiP.data(), PhiT.data(), Pn.data(), s, s, s);
    for (int64_t i = 0; i < s; ++i) {
      x[i] += step[i];
      for (int64_t j = 0; j < s; ++j) {
        P[i * s + j] = 0.5 * ((Pn[i * s + j] + Q[i * s + j]) + (Pn[j * s + i] + Q[j * s + i]));
      }
    }
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

int64_t tsk_filter_update_size(int64_t size, int64_t rows) {
  if (size < 1 || size > kMaxRows || rows < 1 || rows > kMaxRows) {
    return TSK_ERROR_COUNT;
  }
  return size * size + rows + rows * size + 1 + size + size * size;
}

int64_t tsk_filter_update(int64_t size, int64_t rows, double* buf, int64_t buf_len) {
  try {
    if (size < 1 || size > kMaxRows || rows < 1 || rows > kMaxRows) {
      return TSK_ERROR_COUNT;
    }
    if (buf == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    const int64_t s = size, m = rows;
    if (buf_len < s * s + m + m * s + 1 + s + s * s) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    const double* P = buf;
    const double* r = buf + s * s;
    const double* H = r + m;
    double* nis = buf + s * s + m + m * s;
    double* dx = nis + 1;
    double* Pn = dx + s;
    std::vector<double> HP(static_cast<size_t>(m * s));
    matmul_sparse(H, P, HP.data(), m, s, s);
    // S = H (H P)^T + I (= H P H^T + I, P symmetric); solve S [nu, HP]
    std::vector<double> HPt(static_cast<size_t>(s * m)), S(static_cast<size_t>(m * m));
    for (int64_t l = 0; l < m; ++l) {
      for (int64_t i = 0; i < s; ++i) {
        HPt[i * m + l] = HP[l * s + i];
      }
    }
    matmul_sparse(H, HPt.data(), S.data(), m, s, m);
    for (int64_t i = 0; i < m; ++i) {
      S[i * m + i] += 1.0;
    }
    const int64_t width = s + 1;
    std::vector<double> sol(static_cast<size_t>(m * width));
    for (int64_t i = 0; i < m; ++i) {
      sol[i * width] = -r[i];
      for (int64_t j = 0; j < s; ++j) {
        sol[i * width + 1 + j] = HP[i * s + j];
      }
    }
    if (!solve_in_place(S.data(), sol.data(), m, width)) {
      return TSK_ERROR_SINGULAR_SYSTEM;
    }
    double acc = 0.0;
    for (int64_t i = 0; i < m; ++i) {
      acc += -r[i] * sol[i * width];
    }
    *nis = acc;
    for (int64_t j = 0; j < s; ++j) {
      double d = 0.0;
      for (int64_t i = 0; i < m; ++i) {
        d += HP[i * s + j] * sol[i * width];
      }
      dx[j] = d;
    }
    // (H P)^T S^-1 H P: the transpose of HP times the solved block (row-update form)
    std::vector<double> X(static_cast<size_t>(m * s)), full(static_cast<size_t>(s * s));
    for (int64_t l = 0; l < m; ++l) {
      for (int64_t i = 0; i < s; ++i) {
        X[l * s + i] = sol[l * width + 1 + i];
      }
    }
    matmul(HPt.data(), X.data(), full.data(), s, m, s);
    for (int64_t i = 0; i < s * s; ++i) {
      full[i] = P[i] - full[i];
    }
    for (int64_t i = 0; i < s; ++i) {
      for (int64_t j = 0; j < s; ++j) {
        Pn[i * s + j] = 0.5 * (full[i * s + j] + full[j * s + i]);
      }
    }
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

int64_t tsk_filter_motion_rows(int64_t size, int64_t readings, double min_gravity_norm,
                               const double* in, const double* dynamics, double* r, double* H) {
  try {
    if (size != 12 && size != 18) {
      return TSK_ERROR_COUNT;
    }
    if (in == nullptr || dynamics == nullptr || r == nullptr || H == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (readings < 0 || readings > 7 || !(min_gravity_norm >= 0.0)) {
      return TSK_ERROR_ARGUMENT;
    }
    const int64_t s = size;
    const double* T = in;
    const double* J = in + 16;
    const double* V = in + 52;
    const double* g = in + 58;
    const double* twist_rate = dynamics + 6;
    const double* d_screw = dynamics + 48;
    const double* d_twist = dynamics + 84;
    const double* d_load = dynamics + 120;
    const double wx = V[0], wy = V[1], wz = V[2], vx = V[3], vy = V[4], vz = V[5];
    double value[3] = {0.0, 0.0, 0.0};
    double df[3 * 18] = {0.0};
    if (readings & (TSK_FILTER_SPECIFIC_FORCE | TSK_FILTER_GRAVITY)) {
      // f = dv/dt + w x v - R^T g; df/dxi = -R^T hat(g) G (+ the dynamics' rows of dv/dt)
      const double hg[9] = {0.0, -g[2], g[1], g[2], 0.0, -g[0], -g[1], g[0], 0.0};
      double Rt[9], RtH[9], G3[9], dg[9];
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          Rt[i * 3 + j] = T[j * 4 + i];
          G3[i * 3 + j] = J[i * 6 + j];
        }
      }
      matmul(Rt, hg, RtH, 3, 3, 3);
      matmul(RtH, G3, dg, 3, 3, 3);
      double g2[3];
      matmul(Rt, g, g2, 3, 3, 1);
      const double cross[3] = {wy * vz - wz * vy, wz * vx - wx * vz, wx * vy - wy * vx};
      const double dtw[18] = {0.0, vz, -vy, 0.0, -wz, wy, -vz, 0.0, vx, wz, 0.0, -wx,
                              vy, -vx, 0.0, -wy, wx, 0.0};
      for (int i = 0; i < 3; ++i) {
        value[i] = twist_rate[3 + i] + cross[i] - g2[i];
        for (int j = 0; j < 6; ++j) {
          df[i * s + j] = (j < 3 ? -dg[i * 3 + j] : 0.0) + d_screw[(3 + i) * 6 + j];
          df[i * s + 6 + j] = dtw[i * 6 + j] + d_twist[(3 + i) * 6 + j];
          if (s == 18) {
            df[i * s + 12 + j] = d_load[(3 + i) * 6 + j];
          }
        }
      }
    }
    int64_t row = 0;
    if (readings & TSK_FILTER_SPECIFIC_FORCE) {
      const double* z = in + 61;
      const double* w = in + 64;
      for (int i = 0; i < 3; ++i) {
        r[row + i] = (value[i] - z[i]) * w[i];
        for (int64_t j = 0; j < s; ++j) {
          H[(row + i) * s + j] = df[i * s + j] * w[i];
        }
      }
      row += 3;
    }
    if (readings & TSK_FILTER_GRAVITY) {
      const double* z = in + 67;
      const double* w = in + 70;
      const double norm = std::sqrt(value[0] * value[0] + value[1] * value[1] +
                                    value[2] * value[2]);
      if (!(norm >= min_gravity_norm)) {
        return TSK_ERROR_ARGUMENT;
      }
      const double nv[3] = {value[0] / norm, value[1] / norm, value[2] / norm};
      double du[9];
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          du[i * 3 + j] = -((i == j ? 1.0 : 0.0) - nv[i] * nv[j]) / norm;
        }
      }
      for (int i = 0; i < 3; ++i) {
        r[row + i] = (-nv[i] - z[i]) * w[i];
        for (int64_t j = 0; j < s; ++j) {
          double acc = 0.0;
          for (int l = 0; l < 3; ++l) {
            acc += du[i * 3 + l] * df[l * s + j];
          }
          H[(row + i) * s + j] = acc * w[i];
        }
      }
      row += 3;
    }
    if (readings & TSK_FILTER_GYRO) {
      const double* z = in + 73;
      const double* w = in + 76;
      for (int i = 0; i < 3; ++i) {
        r[row + i] = (V[i] - z[i]) * w[i];
        for (int64_t j = 0; j < s; ++j) {
          H[(row + i) * s + j] = (j == 6 + i) ? w[i] : 0.0;
        }
      }
      row += 3;
    }
    return row;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

int64_t tsk_filter_output(int64_t size, const double* P, const double* x, const double* T,
                          const double* pose_jacobian, double* out, int64_t out_len) {
  try {
    if (size < 12 || size > kMaxRows) {
      return TSK_ERROR_COUNT;
    }
    if (P == nullptr || x == nullptr || T == nullptr || pose_jacobian == nullptr ||
        out == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (out_len < TSK_FILTER_OUTPUT_SIZE) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    const int64_t s = size;
    const double* Pj = pose_jacobian;
    double C[36], PjT[36], PC[36], cov[36];
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) {
        C[i * 6 + j] = P[i * s + j];
        PjT[j * 6 + i] = Pj[i * 6 + j];
      }
    }
    matmul(Pj, C, PC, 6, 6, 6);
    matmul(PC, PjT, cov, 6, 6, 6);
    double* pose_cov = out;
    double* twist = out + 36;
    double* twist_cov = out + 42;
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) {
        pose_cov[i * 6 + j] = 0.5 * (cov[i * 6 + j] + cov[j * 6 + i]);
      }
    }
    // [dp/dt; w_s] = [R v; R w]; first order in the screw through R (dtheta = Pj[3:] dxi)
    double R[9], ws[3], vs[3];
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        R[i * 3 + j] = T[i * 4 + j];
      }
    }
    matmul(R, x + 6, ws, 3, 3, 1);
    matmul(R, x + 9, vs, 3, 3, 1);
    const double hv[9] = {0.0, vs[2], -vs[1], -vs[2], 0.0, vs[0], vs[1], -vs[0], 0.0};
    const double hw[9] = {0.0, ws[2], -ws[1], -ws[2], 0.0, ws[0], ws[1], -ws[0], 0.0};
    double Jt[72] = {0.0};
    double top[18], bottom[18];
    matmul(hv, Pj + 18, top, 3, 3, 6);     // -hat(v_s) Pj[3:]
    matmul(hw, Pj + 18, bottom, 3, 3, 6);  // -hat(w_s) Pj[3:]
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 6; ++j) {
        Jt[i * 12 + j] = top[i * 6 + j];
        Jt[(3 + i) * 12 + j] = bottom[i * 6 + j];
      }
      for (int j = 0; j < 3; ++j) {
        Jt[i * 12 + 9 + j] = R[i * 3 + j];
        Jt[(3 + i) * 12 + 6 + j] = R[i * 3 + j];
      }
    }
    double P12[144], JP[72], JtT[72], tc[36];
    for (int i = 0; i < 12; ++i) {
      for (int j = 0; j < 12; ++j) {
        P12[i * 12 + j] = P[i * s + j];
      }
    }
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 12; ++j) {
        JtT[j * 6 + i] = Jt[i * 12 + j];
      }
    }
    matmul(Jt, P12, JP, 6, 12, 12);
    matmul(JP, JtT, tc, 6, 12, 6);
    for (int i = 0; i < 3; ++i) {
      twist[i] = vs[i];
      twist[3 + i] = ws[i];
    }
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) {
        twist_cov[i * 6 + j] = 0.5 * (tc[i * 6 + j] + tc[j * 6 + i]);
      }
    }
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

}  // extern "C"
