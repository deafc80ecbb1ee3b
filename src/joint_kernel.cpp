// Compiled kernel of the six-DOF tensegrity joint (Monke & Vikas, eqs. 6-11 with the corrections
// of docs/errata.md): for each screw xi = [omega; v], T = exp(hat(xi)) and the SE(3) left Jacobian J
// (eqs. 3, 4, 14-18), the string vectors s_j = p1_j - T p2_j (eq. 7), lengths, tensions (eq. 8),
// the wrench F = sum [f_j; p1_j x f_j] (eq. 9), K = dF/dxi (eq. 10) and K_c = -dF/d[dv; dw].
//
// The formulas are those of tensegrity_stiffness/geometry/screw.py (its kinematics entries) and
// tensegrity_stiffness/mechanics/joint.py (module docstring), written out per string:
//   A_j = df/ds = gamma s s^T + beta I,  beta = phi / l,  gamma = (phi' - beta) / l^2,
//   H_D = sum [A; P A],  H_G = sum [A hat(q); P A hat(q)]  (P = hat(p1_j), q_j = T p2_j),
//   K = [H_G G - H_D Q, -H_D G],  K_c = [H_D, -H_G].
// Built on the same evaluation: the linear model of link 2's dynamics at an equilibrium
// (mechanics/joint_dynamics.py, JointDynamics: M = J_b^T G J_b, the blocks J_l^T Pi K,
// -L^T C L, J_l^T Pi dF/dl0, J_l^T Pi and M^-1 of them), the stiffness controller's pose terms
// (control/controller.py, pose_terms_numpy) and exp(hat(xi)) alone.
// The numpy implementation in mechanics/joint.py stays the reference and the fallback; the tests
// hold this kernel to it (test/kernel/test_joint_kernel.py); test/kernel/test_kernel_math.cpp to
// closed forms. The C ABI is declared in include/tensegrity_stiffness/kernel.h (loaded with
// ctypes: no Python headers).

#include "tensegrity_stiffness/kernel.h"

#include "dense_solve.hpp"
#include "string_law.hpp"

#include <cmath>
#include <cstddef>
#include <cstdint>

namespace {

using tensegrity_stiffness::detail::solve_in_place;
using tensegrity_stiffness::detail::string_force;
using tensegrity_stiffness::detail::StringForce;

struct Coefficients {
  double a, b, c, b1, c1;
};

// a = sin t / t, b = (1 - cos t) / t^2, c = (t - sin t) / t^3, b1 = b' / t, c1 = c' / t; below
// the model's series_threshold from its Taylor tables (Horner in t^2, as geometry/screw.py).
Coefficients rotation_coefficients(const tsk_joint_model& model, double theta) {
  Coefficients k;
  if (theta < model.series_threshold) {
    const double t2 = theta * theta;
    const int64_t terms = model.series_terms;
    double out[TSK_SERIES_ROWS];
    for (int i = 0; i < TSK_SERIES_ROWS; ++i) {
      const double* row = model.series + terms * i;
      double acc = 0.0;
      for (int64_t j = 0; j < terms; ++j) {
        acc = acc * t2 + row[j];
      }
      out[i] = acc;
    }
    k = {out[0], out[1], out[2], out[3], out[4]};
    return k;
  }
  const double s = std::sin(theta), c = std::cos(theta), t2 = theta * theta;
  k.a = s / theta;
  k.b = (1.0 - c) / t2;
  k.c = (theta - s) / (t2 * theta);
  k.b1 = (theta * s + 2.0 * c - 2.0) / (t2 * t2);
  k.c1 = (3.0 * s - theta * c - 2.0 * theta) / (t2 * t2 * theta);
  return k;
}

// T (4x4 row-major) and the blocks G, Q of J = [[G, 0], [Q, G]] (eqs. 3, 4, 15-17).
void kinematics(const tsk_joint_model& model, const double* xi, double* T, double G[3][3],
                double Q[3][3]) {
  const double wx = xi[0], wy = xi[1], wz = xi[2], vx = xi[3], vy = xi[4], vz = xi[5];
  const double theta = std::sqrt(wx * wx + wy * wy + wz * wz);
  const Coefficients k = rotation_coefficients(model, theta);
  const double a = k.a, b = k.b, c = k.c, b1 = k.b1, c1 = k.c1;
  const double xx = wx * wx, yy = wy * wy, zz = wz * wz, xy = wx * wy, xz = wx * wz,
               yz = wy * wz;
  const double t2 = xx + yy + zz;
  G[0][0] = 1.0 + c * (xx - t2);
  G[0][1] = -b * wz + c * xy;
  G[0][2] = b * wy + c * xz;
  G[1][0] = b * wz + c * xy;
  G[1][1] = 1.0 + c * (yy - t2);
  G[1][2] = -b * wx + c * yz;
  G[2][0] = -b * wy + c * xz;
  G[2][1] = b * wx + c * yz;
  G[2][2] = 1.0 + c * (zz - t2);
  const double tx = G[0][0] * vx + G[0][1] * vy + G[0][2] * vz;
  const double ty = G[1][0] * vx + G[1][1] * vy + G[1][2] * vz;
  const double tz = G[2][0] * vx + G[2][1] * vy + G[2][2] * vz;
  T[0] = 1.0 + b * (xx - t2);
  T[1] = -a * wz + b * xy;
  T[2] = a * wy + b * xz;
  T[3] = tx;
  T[4] = a * wz + b * xy;
  T[5] = 1.0 + b * (yy - t2);
  T[6] = -a * wx + b * yz;
  T[7] = ty;
  T[8] = -a * wy + b * xz;
  T[9] = a * wx + b * yz;
  T[10] = 1.0 + b * (zz - t2);
  T[11] = tz;
  T[12] = 0.0;
  T[13] = 0.0;
  T[14] = 0.0;
  T[15] = 1.0;
  const double wv = wx * vx + wy * vy + wz * vz;
  const double ex = b1 * (wy * vz - wz * vy) + c1 * (wx * wv - t2 * vx);
  const double ey = b1 * (wz * vx - wx * vz) + c1 * (wy * wv - t2 * vy);
  const double ez = b1 * (wx * vy - wy * vx) + c1 * (wz * wv - t2 * vz);
  double d[3][3];
  d[0][0] = c * (wv - wx * vx) + ex * wx;
  d[0][1] = b * vz + c * (wx * vy - 2.0 * vx * wy) + ex * wy;
  d[0][2] = -b * vy + c * (wx * vz - 2.0 * vx * wz) + ex * wz;
  d[1][0] = -b * vz + c * (wy * vx - 2.0 * vy * wx) + ey * wx;
  d[1][1] = c * (wv - wy * vy) + ey * wy;
  d[1][2] = b * vx + c * (wy * vz - 2.0 * vy * wz) + ey * wz;
  d[2][0] = b * vy + c * (wz * vx - 2.0 * vz * wx) + ez * wx;
  d[2][1] = -b * vx + c * (wz * vy - 2.0 * vz * wy) + ez * wy;
  d[2][2] = c * (wv - wz * vz) + ez * wz;
  for (int j = 0; j < 3; ++j) {
    Q[0][j] = d[0][j] - tz * G[1][j] + ty * G[2][j];
    Q[1][j] = d[1][j] + tz * G[0][j] - tx * G[2][j];
    Q[2][j] = d[2][j] - ty * G[0][j] + tx * G[1][j];
  }
}

// J = [[G, 0], [Q, G]] (6x6 row-major) of one screw (the SE(3) left Jacobian, eqs. 14-18).
void left_jacobian(const tsk_joint_model& model, const double* xi, double J[6][6]) {
  double T[16], G[3][3], Q[3][3];
  kinematics(model, xi, T, G, Q);
  for (int i = 0; i < 3; ++i) {
    for (int c = 0; c < 3; ++c) {
      J[i][c] = G[i][c];
      J[i][c + 3] = 0.0;
      J[i + 3][c] = Q[i][c];
      J[i + 3][c + 3] = G[i][c];
    }
  }
}

// Index of the swap Pi of the 3-blocks ([f; m] <-> [m; f]).
inline int swap_block(int i) { return i < 3 ? i + 3 : i - 3; }

// One screw: returns false when a string is shorter than min_string_length.
bool evaluate_one(const tsk_joint_model& model, const double* x, const double* r, int64_t mode, double* T,
                  double* s, double* lengths, double* phi, uint8_t* slack, uint8_t* saturated,
                  double* wrench, double* K, double* Kc) {
  const int64_t n = model.n_strings;
  double G[3][3], Q[3][3];
  kinematics(model, x, T, G, Q);
  double F[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
  double HD[6][3] = {{0.0}};
  double HG[6][3] = {{0.0}};
  for (int64_t j = 0; j < n; ++j) {
    const double* a1 = model.p1 + 3 * j;
    const double* b2 = model.p2 + 3 * j;
    double q[3], sv[3];
    for (int i = 0; i < 3; ++i) {
      q[i] = T[4 * i] * b2[0] + T[4 * i + 1] * b2[1] + T[4 * i + 2] * b2[2] + T[4 * i + 3];
      sv[i] = a1[i] - q[i];
      s[3 * j + i] = sv[i];
    }
    const double l2 = sv[0] * sv[0] + sv[1] * sv[1] + sv[2] * sv[2];
    const double l = std::sqrt(l2);
    if (l < model.min_string_length) {
      return false;
    }
    lengths[j] = l;
    const double r0 = r[j];
    const StringForce force = string_force(l, r0, model.max_stretch[j], model.k[j], model.law);
    slack[j] = force.slack;
    saturated[j] = force.saturated;
    const double tension = force.tension;
    const double dtension = force.dtension;
    phi[j] = tension;
    const double beta = tension / l;
    const double f[3] = {beta * sv[0], beta * sv[1], beta * sv[2]};
    F[0] += f[0];
    F[1] += f[1];
    F[2] += f[2];
    F[3] += a1[1] * f[2] - a1[2] * f[1];
    F[4] += a1[2] * f[0] - a1[0] * f[2];
    F[5] += a1[0] * f[1] - a1[1] * f[0];
    if (mode == TSK_MODE_WRENCH) {
      continue;
    }
    // A = gamma s s^T + beta I and P A with P = hat(p1).
    const double gamma = (dtension - beta) / l2;
    double A[3][3];
    for (int i = 0; i < 3; ++i) {
      const double gs = gamma * sv[i];
      for (int c = 0; c < 3; ++c) {
        A[i][c] = gs * sv[c];
      }
      A[i][i] += beta;
    }
    double PA[3][3];
    for (int c = 0; c < 3; ++c) {
      PA[0][c] = a1[1] * A[2][c] - a1[2] * A[1][c];
      PA[1][c] = a1[2] * A[0][c] - a1[0] * A[2][c];
      PA[2][c] = a1[0] * A[1][c] - a1[1] * A[0][c];
    }
    // H_D += [A; P A], H_G += [A; P A] hat(q) (row x of X hat(q) is (x cross q)^T).
    for (int i = 0; i < 3; ++i) {
      for (int c = 0; c < 3; ++c) {
        HD[i][c] += A[i][c];
        HD[i + 3][c] += PA[i][c];
      }
      HG[i][0] += A[i][1] * q[2] - A[i][2] * q[1];
      HG[i][1] += A[i][2] * q[0] - A[i][0] * q[2];
      HG[i][2] += A[i][0] * q[1] - A[i][1] * q[0];
      HG[i + 3][0] += PA[i][1] * q[2] - PA[i][2] * q[1];
      HG[i + 3][1] += PA[i][2] * q[0] - PA[i][0] * q[2];
      HG[i + 3][2] += PA[i][0] * q[1] - PA[i][1] * q[0];
    }
  }
  for (int i = 0; i < 6; ++i) {
    wrench[i] = F[i];
  }
  if (mode == TSK_MODE_WRENCH) {
    return true;
  }
  // K = [H_G G - H_D Q, -H_D G].
  for (int i = 0; i < 6; ++i) {
    for (int c = 0; c < 3; ++c) {
      double hg = 0.0, hq = 0.0, hdg = 0.0;
      for (int e = 0; e < 3; ++e) {
        hg += HG[i][e] * G[e][c];
        hq += HD[i][e] * Q[e][c];
        hdg += HD[i][e] * G[e][c];
      }
      K[6 * i + c] = hg - hq;
      K[6 * i + 3 + c] = -hdg;
    }
  }
  if (mode == TSK_MODE_FULL) {
    // K_c = [H_D, -H_G].
    for (int i = 0; i < 6; ++i) {
      for (int c = 0; c < 3; ++c) {
        Kc[6 * i + c] = HD[i][c];
        Kc[6 * i + 3 + c] = -HG[i][c];
      }
    }
  }
  return true;
}


// The model's own checks (counts, pointers, law, series): TSK_OK or the error.
int64_t check_model(const tsk_joint_model* model) {
  if (model == nullptr) {
    return TSK_ERROR_NULL_POINTER;
  }
  if (model->n_strings < 1 || model->series_terms < 1) {
    return TSK_ERROR_COUNT;
  }
  if (model->p1 == nullptr || model->p2 == nullptr || model->k == nullptr ||
      model->max_stretch == nullptr || model->series == nullptr) {
    return TSK_ERROR_NULL_POINTER;
  }
  if (model->law != TSK_LAW_HOOKE && model->law != TSK_LAW_PAPER) {
    return TSK_ERROR_ARGUMENT;
  }
  return TSK_OK;
}

bool valid_mode(int64_t mode) {
  return mode == TSK_MODE_FULL || mode == TSK_MODE_STIFFNESS || mode == TSK_MODE_WRENCH;
}

// Doubles that hold `bytes` bytes.
int64_t doubles_for_bytes(int64_t bytes) { return (bytes + 7) / 8; }

// Largest count for which the buffer sizes below fit in int64_t with room to spare.
constexpr int64_t kMaxCount = int64_t{1} << 40;

}  // namespace

extern "C" {

int64_t tsk_abi_version(void) { return TSK_ABI_VERSION; }

int64_t tsk_joint_model_layout(int64_t* out, int64_t capacity) {
  if (out == nullptr) {
    return TSK_ERROR_NULL_POINTER;
  }
  const int64_t layout[1 + TSK_MODEL_FIELDS] = {
      sizeof(tsk_joint_model),
      offsetof(tsk_joint_model, n_strings),
      offsetof(tsk_joint_model, p1),
      offsetof(tsk_joint_model, p2),
      offsetof(tsk_joint_model, k),
      offsetof(tsk_joint_model, max_stretch),
      offsetof(tsk_joint_model, law),
      offsetof(tsk_joint_model, series_terms),
      offsetof(tsk_joint_model, series),
      offsetof(tsk_joint_model, series_threshold),
      offsetof(tsk_joint_model, min_string_length),
  };
  if (capacity < 1 + TSK_MODEL_FIELDS) {
    return TSK_ERROR_BUFFER_SIZE;
  }
  for (int i = 0; i < 1 + TSK_MODEL_FIELDS; ++i) {
    out[i] = layout[i];
  }
  return 1 + TSK_MODEL_FIELDS;
}

int64_t tsk_joint_packed_size(int64_t n_strings) {
  if (n_strings < 1 || n_strings > kMaxCount) {
    return TSK_ERROR_COUNT;
  }
  return 6 + n_strings + 16 + 5 * n_strings + 6 + 36 + 36 + doubles_for_bytes(2 * n_strings);
}

int64_t tsk_joint_evaluate_packed(const tsk_joint_model* model, int64_t mode, double* buf,
                                  int64_t buf_len) {
  // No allocation and no throwing call below: nothing can raise (the try is the rule of the
  // boundary, at no cost on the normal path).
  try {
    const int64_t status = check_model(model);
    if (status != TSK_OK) {
      return status;
    }
    if (buf == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (!valid_mode(mode)) {
      return TSK_ERROR_ARGUMENT;
    }
    const int64_t n = model->n_strings;
    if (buf_len < tsk_joint_packed_size(n)) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    const double* rest = buf + 6;
    double* T = buf + 6 + n;
    double* s = T + 16;
    double* lengths = s + 3 * n;
    double* phi = lengths + n;
    double* wrench = phi + n;
    double* K = wrench + 6;
    double* Kc = K + 36;
    uint8_t* slack = reinterpret_cast<uint8_t*>(Kc + 36);
    uint8_t* saturated = slack + n;
    return evaluate_one(*model, buf, rest, mode, T, s, lengths, phi, slack, saturated, wrench, K,
                        Kc) ? TSK_OK : TSK_ERROR_ZERO_LENGTH;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

int64_t tsk_joint_batch_size(int64_t n_strings, int64_t n_screws) {
  if (n_strings < 1 || n_screws < 1 || n_strings > kMaxCount || n_screws > kMaxCount ||
      n_strings > kMaxCount / n_screws) {
    return TSK_ERROR_COUNT;
  }
  const int64_t per_screw = 16 + 5 * n_strings + 6 + 36 + 36;
  return per_screw * n_screws + doubles_for_bytes(2 * n_strings * n_screws);
}

int64_t tsk_joint_evaluate(const tsk_joint_model* model, int64_t n_screws, const double* xi,
                           const double* rest, int64_t rest_len, int64_t mode, double* out,
                           int64_t out_len) {
  try {
    const int64_t status = check_model(model);
    if (status != TSK_OK) {
      return status;
    }
    if (xi == nullptr || rest == nullptr || out == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (!valid_mode(mode)) {
      return TSK_ERROR_ARGUMENT;
    }
    const int64_t n = model->n_strings;
    const int64_t size = tsk_joint_batch_size(n, n_screws);
    if (size < 0) {
      return size;
    }
    if (out_len < size || (rest_len != n && rest_len != n * n_screws)) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    const int64_t rest_stride = rest_len == n && n_screws > 1 ? 0 : n;
    const int64_t N = n_screws;
    double* T = out;
    double* s = T + 16 * N;
    double* lengths = s + 3 * n * N;
    double* phi = lengths + n * N;
    double* wrench = phi + n * N;
    double* K = wrench + 6 * N;
    double* Kc = K + 36 * N;
    uint8_t* slack = reinterpret_cast<uint8_t*>(Kc + 36 * N);
    uint8_t* saturated = slack + n * N;
    for (int64_t m = 0; m < N; ++m) {
      if (!evaluate_one(*model, xi + 6 * m, rest + rest_stride * m, mode, T + 16 * m,
                        s + 3 * n * m, lengths + n * m, phi + n * m, slack + n * m,
                        saturated + n * m, wrench + 6 * m,
                        mode == TSK_MODE_WRENCH ? nullptr : K + 36 * m,
                        mode == TSK_MODE_FULL ? Kc + 36 * m : nullptr)) {
        return TSK_ERROR_ZERO_LENGTH;
      }
    }
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

int64_t tsk_joint_measure_size(int64_t n_strings) {
  if (n_strings < 1 || n_strings > kMaxCount) {
    return TSK_ERROR_COUNT;
  }
  return 36 + 36 + 13 * n_strings;
}

int64_t tsk_joint_measure_packed(const tsk_joint_model* model, int64_t mode, double* buf,
                                 int64_t buf_len, double* meas, int64_t meas_len) {
  try {
    // Every check before anything is written (the evaluation checks the rest).
    const int64_t checked = check_model(model);
    if (checked != TSK_OK) {
      return checked;
    }
    const int64_t n = model->n_strings;
    if (meas == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (meas_len < tsk_joint_measure_size(n)) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    const int64_t status = tsk_joint_evaluate_packed(model, mode, buf, buf_len);
    if (status != TSK_OK) {
      return status;
    }
    // The same kinematics as the evaluation (recomputed: about 100 flops).
    double T[16], G[3][3], Q[3][3];
    kinematics(*model, buf, T, G, Q);
    double* J = meas;
    double* P = J + 36;
    double* dl = P + 36;
    double* dphi = dl + 6 * n;
    double* slope = dphi + 6 * n;
    // J = [[G, 0], [Q, G]]; P = [[D, G], [G, 0]] with D = Q - hat(t) G (sensor_models.
    // pose_jacobian: ScrewKinematics.D written out).
    const double tx = T[3], ty = T[7], tz = T[11];
    for (int i = 0; i < 3; ++i) {
      for (int c = 0; c < 3; ++c) {
        J[6 * i + c] = G[i][c];
        J[6 * i + 3 + c] = 0.0;
        J[6 * (i + 3) + c] = Q[i][c];
        J[6 * (i + 3) + 3 + c] = G[i][c];
        P[6 * i + 3 + c] = G[i][c];
        P[6 * (i + 3) + c] = G[i][c];
        P[6 * (i + 3) + 3 + c] = 0.0;
      }
    }
    for (int c = 0; c < 3; ++c) {
      P[c] = Q[0][c] - (-tz * G[1][c] + ty * G[2][c]);
      P[6 + c] = Q[1][c] - (tz * G[0][c] - tx * G[2][c]);
      P[12 + c] = Q[2][c] - (-ty * G[0][c] + tx * G[1][c]);
    }
    // dl_j/dxi = -[(p1_j x u_j)^T, u_j^T] J (q x u = p1 x u), dphi_j/dxi = phi_j'(l_j) dl_j/dxi.
    const double* rest = buf + 6;
    const double* s = buf + 6 + n + 16;
    const double* lengths = s + 3 * n;
    for (int64_t j = 0; j < n; ++j) {
      const double l = lengths[j];
      const double u[3] = {s[3 * j] / l, s[3 * j + 1] / l, s[3 * j + 2] / l};
      const double* a1 = model->p1 + 3 * j;
      const double w[3] = {a1[1] * u[2] - a1[2] * u[1], a1[2] * u[0] - a1[0] * u[2],
                           a1[0] * u[1] - a1[1] * u[0]};
      const double r0 = rest[j];
      const double lmax = r0 + model->max_stretch[j];
      const bool taut = !(l <= r0 || l >= lmax);
      const double clipped = std::fmin(std::fmax(l, r0), lmax);
      const double kj = model->k[j];
      const double d = !taut ? 0.0 : (model->law == TSK_LAW_HOOKE ? kj
                                                                  : kj * r0 / (clipped * clipped));
      slope[j] = d;
      for (int c = 0; c < 3; ++c) {
        const double rot = -(w[0] * G[0][c] + w[1] * G[1][c] + w[2] * G[2][c] +
                             u[0] * Q[0][c] + u[1] * Q[1][c] + u[2] * Q[2][c]);
        const double trans = -(u[0] * G[0][c] + u[1] * G[1][c] + u[2] * G[2][c]);
        dl[6 * j + c] = rot;
        dl[6 * j + 3 + c] = trans;
        dphi[6 * j + c] = d * rot;
        dphi[6 * j + 3 + c] = d * trans;
      }
    }
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

int64_t tsk_joint_linear_size(int64_t n_strings) {
  if (n_strings < 1 || n_strings > kMaxCount) {
    return TSK_ERROR_COUNT;
  }
  return 6 + 6 + 36 + 36 + 12 * (18 + n_strings) + 1;
}

int64_t tsk_joint_linear_model(const tsk_joint_model* model, const double* inertia,
                               const double* damping, double equilibrium_tolerance, double* buf,
                               int64_t buf_len, double* lin, int64_t lin_len) {
  try {
    // Every check before anything is written (the evaluation checks buf).
    const int64_t checked = check_model(model);
    if (checked != TSK_OK) {
      return checked;
    }
    if (inertia == nullptr || lin == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (!(equilibrium_tolerance >= 0.0)) {
      return TSK_ERROR_ARGUMENT;
    }
    const int64_t n = model->n_strings;
    if (lin_len < tsk_joint_linear_size(n)) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    const int64_t status = tsk_joint_evaluate_packed(model, TSK_MODE_STIFFNESS, buf, buf_len);
    if (status != TSK_OK) {
      return status;
    }
    const double* xi = buf;
    const double* rest = buf + 6;
    const double* s = buf + 6 + n + 16;
    const double* lengths = s + 3 * n;
    const double* phi = lengths + n;
    const double* wrench = phi + n;
    const double* K = wrench + 6;
    const double* W = lin;
    double* net = lin + 6;
    double* Jl_out = net + 6;
    double* M_out = Jl_out + 36;
    const int64_t width = 18 + n;
    double* R = M_out + 36;
    double* S = R + 6 * width;
    double* flag = S + 6 * width;
    // J_l = J(xi), J_b = J(-xi); M = J_b^T G J_b.
    double J[6][6], Jb[6][6];
    left_jacobian(*model, xi, J);
    const double minus[6] = {-xi[0], -xi[1], -xi[2], -xi[3], -xi[4], -xi[5]};
    left_jacobian(*model, minus, Jb);
    double GJ[6][6];
    for (int i = 0; i < 6; ++i) {
      for (int c = 0; c < 6; ++c) {
        double acc = 0.0;
        for (int e = 0; e < 6; ++e) {
          acc += inertia[6 * i + e] * Jb[e][c];
        }
        GJ[i][c] = acc;
      }
    }
    double M[36];
    for (int i = 0; i < 6; ++i) {
      for (int c = 0; c < 6; ++c) {
        double acc = 0.0;
        for (int e = 0; e < 6; ++e) {
          acc += Jb[e][i] * GJ[e][c];
        }
        M[6 * i + c] = acc;
        M_out[6 * i + c] = acc;
        Jl_out[6 * i + c] = J[i][c];
      }
    }
    // F + W and the equilibrium test of mechanics/joint_dynamics.py
    // (|F + W| <= tol max(max tension, 1e-300)).
    double top = 0.0, largest = 0.0;
    for (int64_t j = 0; j < n; ++j) {
      top = std::fmax(top, phi[j]);
    }
    for (int i = 0; i < 6; ++i) {
      net[i] = wrench[i] + W[i];
      largest = std::fmax(largest, std::fabs(net[i]));
    }
    *flag = largest > equilibrium_tolerance * std::fmax(top, 1e-300) ? 0.0 : 1.0;
    // R = [J_l^T Pi K | -L^T C L | J_l^T Pi dF/dl0 | J_l^T Pi], (J_l^T Pi)_ic = J_l[Pi c][i].
    for (int i = 0; i < 6; ++i) {
      double* row = R + width * i;
      for (int c = 0; c < 6; ++c) {
        double acc = 0.0;
        for (int e = 0; e < 6; ++e) {
          acc += J[swap_block(e)][i] * K[6 * e + c];
        }
        row[c] = acc;
        row[6 + c] = 0.0;
        row[12 + n + c] = J[swap_block(c)][i];
      }
    }
    for (int64_t j = 0; j < n; ++j) {
      // The unit wrench w = [p1 x u; u] ([m; f]) and L_j = -w^T J_l.
      const double l = lengths[j];
      const double u[3] = {s[3 * j] / l, s[3 * j + 1] / l, s[3 * j + 2] / l};
      const double* a1 = model->p1 + 3 * j;
      const double w[6] = {a1[1] * u[2] - a1[2] * u[1], a1[2] * u[0] - a1[0] * u[2],
                           a1[0] * u[1] - a1[1] * u[0], u[0], u[1], u[2]};
      // d tension / d l0: Hooke -k (taut); paper -k / l (taut), -k s / lmax^2 (saturated).
      const double r0 = rest[j];
      const double lmax = r0 + model->max_stretch[j];
      const bool slack = l <= r0, saturated = l >= lmax;
      const double kj = model->k[j];
      double dt = 0.0;
      if (!(slack || saturated)) {
        dt = model->law == TSK_LAW_HOOKE ? -kj : -kj / l;
      } else if (saturated && model->law == TSK_LAW_PAPER) {
        dt = -kj * model->max_stretch[j] / (lmax * lmax);
      }
      double L[6];
      for (int c = 0; c < 6; ++c) {
        double acc = 0.0, dl0 = 0.0;
        for (int e = 0; e < 6; ++e) {
          acc += w[e] * J[e][c];
          dl0 += J[e][c] * (w[e] * dt);
        }
        L[c] = -acc;
        R[width * c + 12 + j] = dl0;
      }
      const double cj = damping == nullptr ? 0.0 : damping[j];
      if (cj != 0.0) {
        for (int a = 0; a < 6; ++a) {
          const double ca = L[a] * cj;
          for (int b = 0; b < 6; ++b) {
            R[width * a + 6 + b] -= ca * L[b];
          }
        }
      }
    }
    // S = M^-1 R (one solve for all blocks).
    for (int64_t i = 0; i < 6 * width; ++i) {
      S[i] = R[i];
    }
    if (!solve_in_place(M, S, 6, width)) {
      return TSK_ERROR_SINGULAR_SYSTEM;
    }
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

int64_t tsk_joint_pose_terms_size(int64_t n_strings) {
  if (n_strings < 1 || n_strings > kMaxCount) {
    return TSK_ERROR_COUNT;
  }
  return 16 + 43 * n_strings + 36;
}

int64_t tsk_joint_pose_terms(const tsk_joint_model* model, double* buf, int64_t buf_len) {
  try {
    const int64_t checked = check_model(model);
    if (checked != TSK_OK) {
      return checked;
    }
    if (buf == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    const int64_t n = model->n_strings;
    if (buf_len < tsk_joint_pose_terms_size(n)) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    const double* T = buf;
    double* lengths = buf + 16;
    double* B = lengths + n;
    double* K0 = B + 6 * n;
    double* Mj = K0 + 36;
    double K0_acc[36] = {0.0};
    for (int64_t j = 0; j < n; ++j) {
      const double* p = model->p1 + 3 * j;
      const double* b2 = model->p2 + 3 * j;
      double q[3], sv[3];
      for (int i = 0; i < 3; ++i) {
        q[i] = b2[0] * T[4 * i] + b2[1] * T[4 * i + 1] + b2[2] * T[4 * i + 2] + T[4 * i + 3];
        sv[i] = p[i] - q[i];
      }
      const double l = std::sqrt(sv[0] * sv[0] + sv[1] * sv[1] + sv[2] * sv[2]);
      if (l < model->min_string_length) {
        return TSK_ERROR_ZERO_LENGTH;
      }
      lengths[j] = l;
      const double u[3] = {sv[0] / l, sv[1] / l, sv[2] / l};
      // X = [u; p1 x u] ([f; m]): the wrench per unit tension, column j of B.
      const double X[6] = {u[0], u[1], u[2], p[1] * u[2] - p[2] * u[1],
                           p[2] * u[0] - p[0] * u[2], p[0] * u[1] - p[1] * u[0]};
      const double kj = model->k[j];
      const double a = model->law == TSK_LAW_HOOKE ? kj : kj / l;
      const double bj = model->law == TSK_LAW_HOOKE ? 0.0 : -1.0 / l;
      const double coef = bj - 1.0 / l;
      // ZE = [[I, -hat(q)], [hat(p), -hat(p) hat(q)]] with hat(p) hat(q) = q p^T - (p . q) I:
      // -hat(p) hat(q) has -q_r p_c off the diagonal and p . q - p_r q_r on it.
      double ZE[6][6];
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
          ZE[r][c] = r == c ? 1.0 : 0.0;
          ZE[r + 3][c + 3] = -(q[r] * p[c]);
        }
        const int r1 = (r + 1) % 3, r2 = (r + 2) % 3;
        ZE[r + 3][r + 3] = p[r1] * q[r1] + p[r2] * q[r2];
      }
      ZE[0][3] = 0.0, ZE[0][4] = q[2], ZE[0][5] = -q[1];
      ZE[1][3] = -q[2], ZE[1][4] = 0.0, ZE[1][5] = q[0];
      ZE[2][3] = q[1], ZE[2][4] = -q[0], ZE[2][5] = 0.0;
      ZE[3][0] = 0.0, ZE[3][1] = -p[2], ZE[3][2] = p[1];
      ZE[4][0] = p[2], ZE[4][1] = 0.0, ZE[4][2] = -p[0];
      ZE[5][0] = -p[1], ZE[5][1] = p[0], ZE[5][2] = 0.0;
      double* Mrow = Mj + 36 * j;
      for (int r = 0; r < 6; ++r) {
        B[n * r + j] = X[r];
        for (int c = 0; c < 6; ++c) {
          const double xx = X[r] * X[c];
          K0_acc[6 * r + c] += a * xx;
          Mrow[6 * r + c] = coef * xx + ZE[r][c] / l;
        }
      }
    }
    for (int i = 0; i < 36; ++i) {
      K0[i] = K0_acc[i];
    }
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

int64_t tsk_joint_transform(const tsk_joint_model* model, double* buf, int64_t buf_len) {
  try {
    const int64_t checked = check_model(model);
    if (checked != TSK_OK) {
      return checked;
    }
    if (buf == nullptr) {
      return TSK_ERROR_NULL_POINTER;
    }
    if (buf_len < 22) {
      return TSK_ERROR_BUFFER_SIZE;
    }
    double G[3][3], Q[3][3];
    kinematics(*model, buf, buf + 6, G, Q);
    return TSK_OK;
  } catch (...) {
    return TSK_ERROR_INTERNAL;
  }
}

}  // extern "C"
