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
void matmul(const double* A, const double* B, double* C, int64_t m, int64_t k, int64_t r) {
  for (int64_t i = 0; i < m; ++i) {
    for (int64_t j = 0; j < r; ++j) {
      C[i * r + j] = 0.0;
    }
    for (int64_t l = 0; l < k; ++l) {
      const double a = A[i * k + l];
      for (int64_t j = 0; j < r; ++j) {
        C[i * r + j] += a * B[l * r + j];
      }
    }
  }
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
    std::vector<double> PhiP(static_cast<size_t>(s * s));
    matmul(Phi.data(), P, PhiP.data(), s, s, s);
    std::vector<double> Pn(static_cast<size_t>(s * s));
    for (int64_t i = 0; i < s; ++i) {
      for (int64_t j = 0; j < s; ++j) {
        double acc = 0.0;
        for (int64_t l = 0; l < s; ++l) {
          acc += PhiP[i * s + l] * Phi[j * s + l];
        }
        Pn[i * s + j] = acc + Q[i * s + j];
      }
    }
    for (int64_t i = 0; i < s; ++i) {
      x[i] += step[i];
      for (int64_t j = 0; j < s; ++j) {
        P[i * s + j] = 0.5 * (Pn[i * s + j] + Pn[j * s + i]);
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
    matmul(H, P, HP.data(), m, s, s);
    // S = H P H^T + I; solve S [nu, HP]
    std::vector<double> S(static_cast<size_t>(m * m));
    for (int64_t i = 0; i < m; ++i) {
      for (int64_t j = 0; j < m; ++j) {
        double acc = 0.0;
        for (int64_t l = 0; l < s; ++l) {
          acc += HP[i * s + l] * H[j * s + l];
        }
        S[i * m + j] = acc + (i == j ? 1.0 : 0.0);
      }
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
    std::vector<double> full(static_cast<size_t>(s * s));
    for (int64_t i = 0; i < s; ++i) {
      for (int64_t j = 0; j < s; ++j) {
        double d = 0.0;
        for (int64_t l = 0; l < m; ++l) {
          d += HP[l * s + i] * sol[l * width + 1 + j];
        }
        full[i * s + j] = P[i * s + j] - d;
      }
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

}  // extern "C"
