// Compiled kernel of the six-DOF tensegrity joint (Monke & Vikas, eqs. 6-11 with the corrections
// of docs/errata.md): for each screw xi = [omega; v], T = exp(hat(xi)) and the SE(3) left Jacobian J
// (eqs. 3, 4, 14-18), the string vectors s_j = p1_j - T p2_j (eq. 7), lengths, tensions (eq. 8),
// the wrench F = sum [f_j; p1_j x f_j] (eq. 9), K = dF/dxi (eq. 10) and K_c = -dF/d[dv; dw].
//
// The formulas are those of tensegrity_stiffness/screw.py (_kinematics_entries) and
// tensegrity_stiffness/joint.py (module docstring), written out per string:
//   A_j = df/ds = gamma s s^T + beta I,  beta = phi / l,  gamma = (phi' - beta) / l^2,
//   H_D = sum [A; P A],  H_G = sum [A hat(q); P A hat(q)]  (P = hat(p1_j), q_j = T p2_j),
//   K = [H_G G - H_D Q, -H_D G],  K_c = [H_D, -H_G].
// The numpy implementation in joint.py stays the reference and the fallback; the tests hold this
// kernel to it (test/test_joint_kernel.py); test/test_kernel_math.cpp to closed forms. The C ABI
// is declared in include/tensegrity_stiffness/kernel.h (loaded with ctypes: no Python headers).

#include "tensegrity_stiffness/kernel.h"

#include <cmath>
#include <cstddef>
#include <cstdint>

namespace {

struct Coefficients {
  double a, b, c, b1, c1;
};

// a = sin t / t, b = (1 - cos t) / t^2, c = (t - sin t) / t^3, b1 = b' / t, c1 = c' / t; below
// the model's series_threshold from its Taylor tables (Horner in t^2, as screw.py).
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
    const double lmax = r0 + model.max_stretch[j];
    const bool is_slack = l <= r0;
    const bool is_saturated = l >= lmax;
    slack[j] = is_slack;
    saturated[j] = is_saturated;
    const bool taut = !(is_slack || is_saturated);
    const double clipped = std::fmin(std::fmax(l, r0), lmax);
    const double kj = model.k[j];
    double tension, dtension;
    if (model.law == TSK_LAW_HOOKE) {
      tension = kj * (clipped - r0);
      dtension = taut ? kj : 0.0;
    } else {
      tension = kj * (clipped - r0) / clipped;
      dtension = taut ? kj * r0 / (clipped * clipped) : 0.0;
    }
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

}  // extern "C"
