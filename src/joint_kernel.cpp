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
// kernel to it (test/test_joint_kernel.py). C ABI only (loaded with ctypes): no Python headers.

#include <cmath>
#include <cstdint>

namespace {

constexpr int kSeriesTerms = 12;
constexpr double kSeriesThreshold = 0.5;      // screw.SERIES_THRESHOLD
constexpr double kMinStringLength = 1e-12;     // joint.MIN_STRING_LENGTH

// Taylor coefficients (in theta^2, highest power first) of a, b, c, b1, c1: set once from
// screw.py's tables by tsk_set_series, so that both implementations use the same numbers.
double g_series[5][kSeriesTerms];
bool g_series_set = false;

struct Coefficients {
  double a, b, c, b1, c1;
};

Coefficients rotation_coefficients(double theta) {
  Coefficients k;
  if (theta < kSeriesThreshold) {
    const double t2 = theta * theta;
    double out[5];
    for (int i = 0; i < 5; ++i) {
      double acc = 0.0;
      for (int j = 0; j < kSeriesTerms; ++j) {
        acc = acc * t2 + g_series[i][j];
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
void kinematics(const double* xi, double* T, double G[3][3], double Q[3][3]) {
  const double wx = xi[0], wy = xi[1], wz = xi[2], vx = xi[3], vy = xi[4], vz = xi[5];
  const double theta = std::sqrt(wx * wx + wy * wy + wz * wz);
  const Coefficients k = rotation_coefficients(theta);
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

struct Model {
  int64_t n;                 // strings
  const double* p1;          // n x 3, link-1 end of each string in {1}
  const double* p2;          // n x 3, link-2 end of each string in {2}
  const double* k;           // n, N/m
  const double* max_stretch; // n, lmax - l0 (inf for no limit)
  int64_t law;               // 0 Hooke, 1 the paper's k (l - l0) / l
};

// One screw: returns false when a string is shorter than kMinStringLength.
bool evaluate_one(const Model& model, const double* x, const double* r, int64_t mode, double* T,
                  double* s, double* lengths, double* phi, uint8_t* slack, uint8_t* saturated,
                  double* wrench, double* K, double* Kc) {
  const int64_t n = model.n;
  double G[3][3], Q[3][3];
  kinematics(x, T, G, Q);
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
    if (l < kMinStringLength) {
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
    if (model.law == 0) {
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
    if (mode == 2) {
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
  if (mode == 2) {
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
  if (mode == 0) {
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

}  // namespace

extern "C" {

// Version of the ABI below; the Python loader refuses a library with another one.
int64_t tsk_abi_version() { return 1; }

// The Taylor tables of screw.py: 5 rows (a, b, c, b1, c1) of 12 coefficients, highest power
// first. Must be called once before the evaluations.
void tsk_set_series(const double* series) {
  for (int i = 0; i < 5; ++i) {
    for (int j = 0; j < kSeriesTerms; ++j) {
      g_series[i][j] = series[i * kSeriesTerms + j];
    }
  }
  g_series_set = true;
}

// Modes: 0 everything; 1 K without K_c; 2 the wrench without K and K_c.
// Return values: -1 success, -2 the series tables are not set, m >= 0 the first screw with a
// string shorter than 1e-12 m (outputs from it on are undefined; the caller reports it).

// A batch of n_screws screws xi (n_screws x 6); rest: n values for all screws (rest_stride 0) or
// one row of n per screw (rest_stride n). Outputs row-major per screw: T 16, s 3n, lengths n,
// phi n, slack n and saturated n (bytes 0 / 1), wrench 6, K 36 (unused in mode 2), Kc 36 (mode 0).
int64_t tsk_joint_evaluate(const Model* model, int64_t n_screws, const double* xi,
                           const double* rest, int64_t rest_stride, int64_t mode, double* T,
                           double* s, double* lengths, double* phi, uint8_t* slack,
                           uint8_t* saturated, double* wrench, double* K, double* Kc) {
  if (!g_series_set) {
    return -2;
  }
  const int64_t n = model->n;
  for (int64_t m = 0; m < n_screws; ++m) {
    if (!evaluate_one(*model, xi + 6 * m, rest + rest_stride * m, mode, T + 16 * m,
                      s + 3 * n * m, lengths + n * m, phi + n * m, slack + n * m,
                      saturated + n * m, wrench + 6 * m, mode == 2 ? nullptr : K + 36 * m,
                      mode == 0 ? Kc + 36 * m : nullptr)) {
      return m;
    }
  }
  return -1;
}

// One screw with all inputs and outputs in one buffer of doubles (the per-call path: one
// address for Python to look up): xi 6 at buf[0], then T 16, s 3n, lengths n, phi n, wrench 6,
// K 36, Kc 36, then slack n and saturated n as bytes. rest points to n rest lengths.
int64_t tsk_joint_evaluate_packed(const Model* model, const double* rest, int64_t mode,
                                  double* buf) {
  if (!g_series_set) {
    return -2;
  }
  const int64_t n = model->n;
  double* T = buf + 6;
  double* s = T + 16;
  double* lengths = s + 3 * n;
  double* phi = lengths + n;
  double* wrench = phi + n;
  double* K = wrench + 6;
  double* Kc = K + 36;
  uint8_t* slack = reinterpret_cast<uint8_t*>(Kc + 36);
  uint8_t* saturated = slack + n;
  return evaluate_one(*model, buf, rest, mode, T, s, lengths, phi, slack, saturated, wrench, K,
                      Kc) ? -1 : 0;
}

}  // extern "C"
