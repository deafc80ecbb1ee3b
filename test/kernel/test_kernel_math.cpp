// The kernel's math against closed forms worked out by hand (gtest through ament_cmake_gtest):
// one string's wrench and stiffness in each region and force law, the rotation at 0, pi / 2, pi
// and across the series threshold, the chain's frames and tip stiffness, the linear model of
// link 2 and the controller's pose terms of one string, the warm QP face of a tiny QP, and the
// ABI's checks of counts, buffer sizes, modes and pointers. Run by ctest and by test/kernel/test_kernel_gtest.py.

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <iterator>
#include <limits>
#include <vector>

#include "tensegrity_stiffness/kernel.h"
#include "tensegrity_stiffness/kernel_defaults.h"

namespace {

// The model constants from their one home (kernel_defaults.h, generated from the Python
// package); SeriesDefaultsAreTheTaylorCoefficients checks them against the formula.
constexpr int kTerms = TSK_DEFAULT_SERIES_TERMS;
constexpr double kThreshold = TSK_DEFAULT_SERIES_THRESHOLD;
constexpr double kDefaultSeries[] = TSK_DEFAULT_SERIES;
const double kInf = std::numeric_limits<double>::infinity();

std::vector<double> series_table() {
  return std::vector<double>(std::begin(kDefaultSeries), std::end(kDefaultSeries));
}

// Taylor coefficients in theta^2 (highest power first) of a = sum (-1)^j t^2j / (2j + 1)!,
// b (2j + 2)!, c (2j + 3)! and of b1 = b' / t, c1 = c' / t (as screw.py's _series).
std::vector<double> taylor_table() {
  std::vector<double> table(TSK_SERIES_ROWS * kTerms);
  auto coefficient = [](int j, int offset) {
    double f = 1.0;
    for (int i = 2; i <= 2 * j + offset; ++i) {
      f *= i;
    }
    return (j % 2 ? -1.0 : 1.0) / f;
  };
  const int offsets[TSK_SERIES_ROWS] = {1, 2, 3, 2, 3};
  for (int row = 0; row < TSK_SERIES_ROWS; ++row) {
    for (int j = 0; j < kTerms; ++j) {
      // Power j of t^2 sits at index kTerms - 1 - j.
      const bool derivative = row >= 3;
      const double value = derivative ? 2.0 * (j + 1) * coefficient(j + 1, offsets[row])
                                      : coefficient(j, offsets[row]);
      table[row * kTerms + kTerms - 1 - j] = value;
    }
  }
  return table;
}

// One joint model over caller-owned arrays.
struct Joint {
  std::vector<double> p1, p2, k, max_stretch, series = series_table();
  tsk_joint_model model{};

  Joint(std::vector<double> a, std::vector<double> b, std::vector<double> stiffness,
        std::vector<double> stretch, int64_t law)
      : p1(a), p2(b), k(stiffness), max_stretch(stretch) {
    model.n_strings = static_cast<int64_t>(k.size());
    model.p1 = p1.data();
    model.p2 = p2.data();
    model.k = k.data();
    model.max_stretch = max_stretch.data();
    model.law = law;
    model.series_terms = kTerms;
    model.series = series.data();
    model.series_threshold = kThreshold;
    model.min_string_length = TSK_DEFAULT_MIN_STRING_LENGTH;
  }
};

// The packed buffer's blocks for n strings (kernel.h).
struct Packed {
  int64_t n;
  std::vector<double> buf;
  explicit Packed(int64_t strings) : n(strings), buf(tsk_joint_packed_size(strings), 0.0) {}
  double* xi() { return buf.data(); }
  double* rest() { return buf.data() + 6; }
  const double* T() const { return buf.data() + 6 + n; }
  const double* s() const { return T() + 16; }
  const double* lengths() const { return s() + 3 * n; }
  const double* tensions() const { return lengths() + n; }
  const double* wrench() const { return tensions() + n; }
  const double* K() const { return wrench() + 6; }
  const double* Kc() const { return K() + 36; }
  const uint8_t* slack() const { return reinterpret_cast<const uint8_t*>(Kc() + 36); }
  const uint8_t* saturated() const { return slack() + n; }
};

int64_t evaluate(const Joint& joint, Packed& out, const std::vector<double>& xi,
                 const std::vector<double>& rest, int64_t mode = TSK_MODE_FULL) {
  for (int i = 0; i < 6; ++i) {
    out.xi()[i] = xi[i];
  }
  for (size_t j = 0; j < rest.size() && j < static_cast<size_t>(out.n); ++j) {
    out.rest()[j] = rest[j];
  }
  return tsk_joint_evaluate_packed(&joint.model, mode, out.buf.data(),
                                   static_cast<int64_t>(out.buf.size()));
}

void expect_near(const double* got, const std::vector<double>& want, double tol,
                 const char* what) {
  for (size_t i = 0; i < want.size(); ++i) {
    EXPECT_NEAR(got[i], want[i], tol) << what << " entry " << i;
  }
}

// K at xi = 0 of one string from a (link 1) to b (link 2): G = I and Q = 0, so
// K = [H_G, -H_D] with H_D = [A; hat(a) A], H_G = H_D hat(b), and K_c = [H_D, -H_G].
void closed_form_K(const double a[3], const double b[3], const double A[3][3],
                   std::vector<double>& K, std::vector<double>& Kc) {
  double H_D[6][3], H_G[6][3];
  for (int c = 0; c < 3; ++c) {
    for (int i = 0; i < 3; ++i) {
      H_D[i][c] = A[i][c];
    }
    H_D[3][c] = a[1] * A[2][c] - a[2] * A[1][c];
    H_D[4][c] = a[2] * A[0][c] - a[0] * A[2][c];
    H_D[5][c] = a[0] * A[1][c] - a[1] * A[0][c];
  }
  for (int i = 0; i < 6; ++i) {  // row x of X hat(b) is (x cross b)^T
    H_G[i][0] = H_D[i][1] * b[2] - H_D[i][2] * b[1];
    H_G[i][1] = H_D[i][2] * b[0] - H_D[i][0] * b[2];
    H_G[i][2] = H_D[i][0] * b[1] - H_D[i][1] * b[0];
  }
  K.assign(36, 0.0);
  Kc.assign(36, 0.0);
  for (int i = 0; i < 6; ++i) {
    for (int c = 0; c < 3; ++c) {
      K[6 * i + c] = H_G[i][c];
      K[6 * i + 3 + c] = -H_D[i][c];
      Kc[6 * i + c] = H_D[i][c];
      Kc[6 * i + 3 + c] = -H_G[i][c];
    }
  }
}

TEST(KernelAbi, VersionAndModelLayout) {
  EXPECT_EQ(tsk_abi_version(), TSK_ABI_VERSION);
  int64_t layout[1 + TSK_MODEL_FIELDS];
  ASSERT_EQ(tsk_joint_model_layout(layout, 1 + TSK_MODEL_FIELDS), 1 + TSK_MODEL_FIELDS);
  EXPECT_EQ(layout[0], static_cast<int64_t>(sizeof(tsk_joint_model)));
  EXPECT_EQ(layout[2], static_cast<int64_t>(offsetof(tsk_joint_model, p1)));
  EXPECT_EQ(layout[10], static_cast<int64_t>(offsetof(tsk_joint_model, min_string_length)));
  EXPECT_EQ(tsk_joint_model_layout(layout, TSK_MODEL_FIELDS), TSK_ERROR_BUFFER_SIZE);
  EXPECT_EQ(tsk_joint_packed_size(12), 6 + 12 + 16 + 60 + 6 + 36 + 36 + 3);
  EXPECT_EQ(tsk_joint_batch_size(12, 2), 2 * (16 + 60 + 6 + 36 + 36) + 6);
  EXPECT_EQ(tsk_joint_packed_size(0), TSK_ERROR_COUNT);
  EXPECT_EQ(tsk_joint_batch_size(12, 0), TSK_ERROR_COUNT);
}

TEST(KernelAbi, SeriesDefaultsAreTheTaylorCoefficients) {
  ASSERT_EQ(std::size(kDefaultSeries), static_cast<size_t>(TSK_SERIES_ROWS * kTerms));
  const std::vector<double> taylor = taylor_table();
  for (size_t i = 0; i < taylor.size(); ++i) {
    EXPECT_NEAR(kDefaultSeries[i], taylor[i], 4e-16 * std::abs(taylor[i])) << "entry " << i;
  }
  EXPECT_EQ(kThreshold, 0.5);
  EXPECT_EQ(TSK_DEFAULT_MIN_STRING_LENGTH, 1e-12);
}

// Hooke, taut, at xi = 0: s = a - b = (0, 0, 0.1), l = 0.1, l0 = 0.05, k = 100: tension 5 N,
// f = (0, 0, 5), A = k (1 - l0 / l) I + k l0 / l^3 s s^T = diag(50, 50, 100).
TEST(JointKernel, OneTautHookeStringByHand) {
  const double a[3] = {0.1, 0.0, 0.1}, b[3] = {0.1, 0.0, 0.0};
  Joint joint({a[0], a[1], a[2]}, {b[0], b[1], b[2]}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  Packed out(1);
  ASSERT_EQ(evaluate(joint, out, {0, 0, 0, 0, 0, 0}, {0.05}), TSK_OK);
  expect_near(out.T(), {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}, 0.0, "T");
  expect_near(out.s(), {0.0, 0.0, 0.1}, 1e-17, "s");
  EXPECT_NEAR(out.lengths()[0], 0.1, 1e-17);
  EXPECT_NEAR(out.tensions()[0], 5.0, 1e-14);
  // F = [f; a x f] = [0, 0, 5; 0 * 5 - 0.1 * 0, 0.1 * 0 - 0.1 * 5, 0].
  expect_near(out.wrench(), {0, 0, 5, 0, -0.5, 0}, 1e-14, "wrench");
  const double A[3][3] = {{50, 0, 0}, {0, 50, 0}, {0, 0, 100}};
  std::vector<double> K, Kc;
  closed_form_K(a, b, A, K, Kc);
  expect_near(out.K(), K, 1e-12, "K");
  expect_near(out.Kc(), Kc, 1e-12, "K_c");
  EXPECT_EQ(out.slack()[0], 0);
  EXPECT_EQ(out.saturated()[0], 0);
}

// The paper's law: tension k (l - l0) / l = 100 * 0.05 / 0.1 = 50 N, phi' = k l0 / l^2 = 500,
// A = (phi' - phi / l) u u^T + (phi / l) I = diag(500, 500, 500).
TEST(JointKernel, OneTautPaperStringByHand) {
  const double a[3] = {0.0, 0.0, 0.1}, b[3] = {0.0, 0.0, 0.0};
  Joint joint({a[0], a[1], a[2]}, {b[0], b[1], b[2]}, {100.0}, {kInf}, TSK_LAW_PAPER);
  Packed out(1);
  ASSERT_EQ(evaluate(joint, out, {0, 0, 0, 0, 0, 0}, {0.05}), TSK_OK);
  EXPECT_NEAR(out.tensions()[0], 50.0, 1e-13);
  expect_near(out.wrench(), {0, 0, 50, 0, 0, 0}, 1e-13, "wrench");
  const double A[3][3] = {{500, 0, 0}, {0, 500, 0}, {0, 0, 500}};
  std::vector<double> K, Kc;
  closed_form_K(a, b, A, K, Kc);
  expect_near(out.K(), K, 1e-11, "K");
}

// Slack (l <= l0): no force, no stiffness. Saturated (l >= lmax): the constant tension
// k (lmax - l0) = 100 * 0.02 = 2 N with A = (phi / l) (I - u u^T) = diag(20, 20, 0).
TEST(JointKernel, SlackAndSaturatedStringsByHand) {
  const double a[3] = {0.0, 0.0, 0.1}, b[3] = {0.0, 0.0, 0.0};
  Joint slack({a[0], a[1], a[2]}, {b[0], b[1], b[2]}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  Packed out(1);
  ASSERT_EQ(evaluate(slack, out, {0, 0, 0, 0, 0, 0}, {0.1}), TSK_OK);  // l == l0: slack
  EXPECT_EQ(out.slack()[0], 1);
  EXPECT_EQ(out.tensions()[0], 0.0);
  expect_near(out.wrench(), std::vector<double>(6, 0.0), 0.0, "wrench");
  expect_near(out.K(), std::vector<double>(36, 0.0), 0.0, "K");

  Joint saturated({a[0], a[1], a[2]}, {b[0], b[1], b[2]}, {100.0}, {0.02}, TSK_LAW_HOOKE);
  ASSERT_EQ(evaluate(saturated, out, {0, 0, 0, 0, 0, 0}, {0.05}), TSK_OK);
  EXPECT_EQ(out.saturated()[0], 1);
  EXPECT_EQ(out.slack()[0], 0);
  EXPECT_NEAR(out.tensions()[0], 2.0, 1e-15);
  const double A[3][3] = {{20, 0, 0}, {0, 20, 0}, {0, 0, 0}};
  std::vector<double> K, Kc;
  closed_form_K(a, b, A, K, Kc);
  expect_near(out.K(), K, 1e-13, "K");
}

// Rodrigues' formula at angle t about the unit axis e, and the kernel's T there.
void expect_rotation(const Joint& joint, const double e[3], double t, double tol) {
  Packed out(1);
  ASSERT_EQ(evaluate(joint, out, {t * e[0], t * e[1], t * e[2], 0, 0, 0}, {0.01}), TSK_OK);
  const double s = std::sin(t), c = std::cos(t);
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      const double K = (i == j ? 0.0 : (i + 1) % 3 == j ? -e[3 - i - j] : e[3 - i - j]);
      // hat(e)[i][j] with the sign of the permutation; R = I + s hat(e) + (1 - c) hat(e)^2.
      double K2 = e[i] * e[j] - (i == j ? 1.0 : 0.0);
      const double want = (i == j ? 1.0 : 0.0) + s * K + (1.0 - c) * K2;
      EXPECT_NEAR(out.T()[4 * i + j], want, tol) << "t " << t << " entry " << i << j;
    }
    EXPECT_EQ(out.T()[4 * i + 3], 0.0);
  }
}

TEST(JointKernel, RotationAtZeroHalfPiPiAndAcrossTheSeriesThreshold) {
  Joint joint({0.0, 0.0, 0.1}, {0.0, 0.0, 0.0}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  const double z[3] = {0.0, 0.0, 1.0};
  const double n = 1.0 / std::sqrt(3.0);
  const double d[3] = {n, -n, n};
  for (const double* e : {z, d}) {
    expect_rotation(joint, e, 0.0, 0.0);
    expect_rotation(joint, e, 1e-9, 1e-16);
    expect_rotation(joint, e, 0.3, 1e-15);
    expect_rotation(joint, e, kThreshold - 1e-12, 1e-15);  // series
    expect_rotation(joint, e, kThreshold, 1e-15);          // closed form
    expect_rotation(joint, e, M_PI / 2, 1e-15);
    expect_rotation(joint, e, M_PI, 1e-15);
    expect_rotation(joint, e, 2 * M_PI - 1e-3, 1e-14);
  }
  // At pi about z: R = diag(-1, -1, 1) exactly up to rounding.
  Packed out(1);
  ASSERT_EQ(evaluate(joint, out, {0, 0, M_PI, 0, 0, 0}, {0.01}), TSK_OK);
  expect_near(out.T(), {-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}, 1e-15, "T at pi");
}

// K is continuous across the series threshold (the series and the closed forms of a, b, c, b1,
// c1 agree there to rounding): a general screw at 0.5 -+ 1e-12 rad.
TEST(JointKernel, StiffnessIsContinuousAcrossTheSeriesEdge) {
  Joint joint({0.05, 0.0, 0.1, -0.03, 0.04, 0.1}, {0.04, 0.01, 0.0, -0.02, 0.05, -0.01},
              {100.0, 80.0}, {kInf, kInf}, TSK_LAW_HOOKE);
  const double n = 1.0 / std::sqrt(14.0);
  const double e[3] = {1 * n, -2 * n, 3 * n};
  Packed below(2), above(2);
  for (Packed* p : {&below, &above}) {
    const double t = p == &below ? kThreshold - 1e-12 : kThreshold + 1e-12;
    ASSERT_EQ(evaluate(joint, *p, {t * e[0], t * e[1], t * e[2], 0.01, -0.02, 0.03},
                       {0.05, 0.05}), TSK_OK);
  }
  double scale = 0.0;
  for (int i = 0; i < 36; ++i) {
    scale = std::fmax(scale, std::fabs(above.K()[i]));
  }
  ASSERT_GT(scale, 1.0);
  for (int i = 0; i < 36; ++i) {
    EXPECT_NEAR(below.K()[i], above.K()[i], 1e-10 * scale) << "K entry " << i;
  }
  // And at 0: K moves by O(theta) from K(0) (the series keep b1, c1 and c accurate where their
  // closed forms cancel catastrophically).
  Packed zero(2), tiny(2);
  const double t = 1e-6;
  ASSERT_EQ(evaluate(joint, zero, {0, 0, 0, 0.01, -0.02, 0.03}, {0.05, 0.05}), TSK_OK);
  ASSERT_EQ(evaluate(joint, tiny, {t * e[0], t * e[1], t * e[2], 0.01, -0.02, 0.03},
                     {0.05, 0.05}), TSK_OK);
  for (int i = 0; i < 36; ++i) {
    EXPECT_NEAR(tiny.K()[i], zero.K()[i], 1e-4 * scale) << "K entry " << i;
  }
}

// A batch of two screws with per-screw rest lengths equals two single evaluations.
TEST(JointKernel, BatchEqualsSingleCalls) {
  Joint joint({0.05, 0.0, 0.1, -0.03, 0.04, 0.1}, {0.04, 0.01, 0.0, -0.02, 0.05, -0.01},
              {100.0, 80.0}, {0.1, kInf}, TSK_LAW_PAPER);
  const std::vector<double> xi = {0.1, 0.2, -0.1, 0.01, 0.0, 0.02, 0.7, -0.1, 0.3, 0.0, 0.01, 0.0};
  const std::vector<double> rest = {0.05, 0.06, 0.04, 0.07};
  std::vector<double> out(tsk_joint_batch_size(2, 2));
  ASSERT_EQ(tsk_joint_evaluate(&joint.model, 2, xi.data(), rest.data(), 4, TSK_MODE_FULL,
                               out.data(), static_cast<int64_t>(out.size())), TSK_OK);
  for (int m = 0; m < 2; ++m) {
    Packed one(2);
    ASSERT_EQ(evaluate(joint, one, {xi.begin() + 6 * m, xi.begin() + 6 * m + 6},
                       {rest[2 * m], rest[2 * m + 1]}), TSK_OK);
    const double* wrench = out.data() + 2 * (16 + 6 + 2 + 2) + 6 * m;
    const double* K = out.data() + 2 * (16 + 6 + 2 + 2 + 6) + 36 * m;
    for (int i = 0; i < 6; ++i) {
      EXPECT_EQ(wrench[i], one.wrench()[i]);
    }
    for (int i = 0; i < 36; ++i) {
      EXPECT_EQ(K[i], one.K()[i]);
    }
  }
}

// tsk_joint_measure_packed: the same evaluation as tsk_joint_evaluate_packed, dl/dxi equal to
// central differences of the kernel's own lengths, dphi/dxi = dphi/dl dl/dxi, J = [[G, 0],
// [Q, G]] with G = I at xi = 0.
TEST(JointKernel, MeasurementJacobiansAreDerivativesOfTheKernelsLengths) {
  Joint joint({0.05, 0.0, 0.1, -0.03, 0.04, 0.1}, {0.04, 0.01, 0.0, -0.02, 0.05, -0.01},
              {100.0, 80.0}, {0.1, kInf}, TSK_LAW_PAPER);
  const std::vector<double> xi = {0.3, -0.2, 0.1, 0.01, 0.0, 0.02};
  const std::vector<double> rest = {0.05, 0.06};
  Packed plain(2), measured(2);
  ASSERT_EQ(evaluate(joint, plain, xi, rest), TSK_OK);
  for (int i = 0; i < 6; ++i) {
    measured.xi()[i] = xi[i];
  }
  measured.rest()[0] = rest[0];
  measured.rest()[1] = rest[1];
  std::vector<double> meas(tsk_joint_measure_size(2), 0.0);
  ASSERT_EQ(meas.size(), 36u + 36u + 13u * 2u);
  ASSERT_EQ(tsk_joint_measure_packed(&joint.model, TSK_MODE_FULL, measured.buf.data(),
                                     static_cast<int64_t>(measured.buf.size()), meas.data(),
                                     static_cast<int64_t>(meas.size())), TSK_OK);
  for (size_t i = 0; i < plain.buf.size(); ++i) {
    EXPECT_EQ(measured.buf[i], plain.buf[i]) << "packed entry " << i;
  }
  const double* dl = meas.data() + 72;
  const double* dphi = dl + 12;
  const double* slope = dphi + 12;
  const double h = 1e-6;
  for (int c = 0; c < 6; ++c) {
    std::vector<double> up = xi, down = xi;
    up[c] += h;
    down[c] -= h;
    Packed a(2), b(2);
    ASSERT_EQ(evaluate(joint, a, up, rest), TSK_OK);
    ASSERT_EQ(evaluate(joint, b, down, rest), TSK_OK);
    for (int j = 0; j < 2; ++j) {
      EXPECT_NEAR(dl[6 * j + c], (a.lengths()[j] - b.lengths()[j]) / (2.0 * h), 1e-8)
          << "dl/dxi string " << j << " column " << c;
      EXPECT_EQ(dphi[6 * j + c], slope[j] * dl[6 * j + c]);
    }
  }
  // paper law, taut: dphi/dl = k l0 / l^2
  for (int j = 0; j < 2; ++j) {
    const double l = plain.lengths()[j];
    EXPECT_NEAR(slope[j], joint.k[j] * rest[j] / (l * l), 1e-12 * joint.k[j]);
  }
  Packed zero(2);
  zero.rest()[0] = rest[0];
  zero.rest()[1] = rest[1];
  ASSERT_EQ(tsk_joint_measure_packed(&joint.model, TSK_MODE_FULL, zero.buf.data(),
                                     static_cast<int64_t>(zero.buf.size()), meas.data(),
                                     static_cast<int64_t>(meas.size())), TSK_OK);
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) {
      EXPECT_EQ(meas[6 * r + c], r == c ? 1.0 : 0.0)
          << "J at xi = 0, entry " << r << ", " << c;
    }
  }
  EXPECT_EQ(tsk_joint_measure_packed(&joint.model, TSK_MODE_FULL, zero.buf.data(),
                                     static_cast<int64_t>(zero.buf.size()), meas.data(), 10),
            TSK_ERROR_BUFFER_SIZE);
  EXPECT_EQ(tsk_joint_measure_size(0), TSK_ERROR_COUNT);
}

TEST(JointKernel, RefusesBadCountsBuffersModesAndPointers) {
  Joint joint({0.0, 0.0, 0.1}, {0.0, 0.0, 0.0}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  Packed out(1);
  const std::vector<double> rest = {0.05};
  std::vector<double> short_buf(out.buf.size() - 1, 7.0);
  EXPECT_EQ(tsk_joint_evaluate_packed(&joint.model, TSK_MODE_FULL, short_buf.data(),
                                      static_cast<int64_t>(short_buf.size())),
            TSK_ERROR_BUFFER_SIZE);
  for (double v : short_buf) {
    EXPECT_EQ(v, 7.0);  // nothing written
  }
  EXPECT_EQ(evaluate(joint, out, {0, 0, 0, 0, 0, 0}, rest, 3), TSK_ERROR_ARGUMENT);
  EXPECT_EQ(tsk_joint_evaluate_packed(nullptr, TSK_MODE_FULL, out.buf.data(),
                                      static_cast<int64_t>(out.buf.size())),
            TSK_ERROR_NULL_POINTER);
  EXPECT_EQ(tsk_joint_evaluate_packed(&joint.model, TSK_MODE_FULL, nullptr, 100),
            TSK_ERROR_NULL_POINTER);
  Joint bad_law({0.0, 0.0, 0.1}, {0.0, 0.0, 0.0}, {100.0}, {kInf}, 7);
  EXPECT_EQ(evaluate(bad_law, out, {0, 0, 0, 0, 0, 0}, rest), TSK_ERROR_ARGUMENT);
  Joint empty({0.0, 0.0, 0.1}, {0.0, 0.0, 0.0}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  empty.model.n_strings = 0;
  EXPECT_EQ(evaluate(empty, out, {0, 0, 0, 0, 0, 0}, rest), TSK_ERROR_COUNT);
  Joint no_series({0.0, 0.0, 0.1}, {0.0, 0.0, 0.0}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  no_series.model.series_terms = 0;
  EXPECT_EQ(evaluate(no_series, out, {0, 0, 0, 0, 0, 0}, rest), TSK_ERROR_COUNT);
  // Batch: no screws, a short output, rest lengths neither n nor n x N.
  const std::vector<double> xi(12, 0.0);
  std::vector<double> batch(tsk_joint_batch_size(1, 2));
  const int64_t len = static_cast<int64_t>(batch.size());
  EXPECT_EQ(tsk_joint_evaluate(&joint.model, 0, xi.data(), rest.data(), 1, TSK_MODE_FULL,
                               batch.data(), len), TSK_ERROR_COUNT);
  EXPECT_EQ(tsk_joint_evaluate(&joint.model, 2, xi.data(), rest.data(), 1, TSK_MODE_FULL,
                               batch.data(), len - 1), TSK_ERROR_BUFFER_SIZE);
  const std::vector<double> three = {0.05, 0.05, 0.05};
  EXPECT_EQ(tsk_joint_evaluate(&joint.model, 2, xi.data(), three.data(), 3, TSK_MODE_FULL,
                               batch.data(), len), TSK_ERROR_BUFFER_SIZE);
  // A zero-length string (a == b at xi = 0).
  Joint zero({0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  EXPECT_EQ(evaluate(zero, out, {0, 0, 0, 0, 0, 0}, rest), TSK_ERROR_ZERO_LENGTH);
}

const std::vector<double> kIdentity = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

std::vector<double> translation(double x, double y, double z) {
  return {1, 0, 0, x, 0, 1, 0, y, 0, 0, 1, z, 0, 0, 0, 1};
}

// Two joints, all frames pure translations: P_2 = T_1 O_1, L_2 = P_2 T_2, tip = L_2 O_tool.
TEST(ChainKernel, FramesOfTranslationsAddUp) {
  std::vector<double> T = translation(0.0, 0.0, 0.1);
  const std::vector<double> T2 = translation(0.01, 0.0, 0.1);
  T.insert(T.end(), T2.begin(), T2.end());
  const std::vector<double> offsets = translation(0.0, 0.0, 0.02);
  const std::vector<double> tool = translation(0.0, 0.03, 0.0);
  std::vector<double> out(32 * 2 + 16);
  ASSERT_EQ(tsk_chain_frames(2, T.data(), offsets.data(), tool.data(), out.data(),
                             static_cast<int64_t>(out.size())), TSK_OK);
  expect_near(out.data(), kIdentity, 0.0, "P_1");
  expect_near(out.data() + 16, translation(0.0, 0.0, 0.12), 1e-16, "P_2");
  expect_near(out.data() + 32, translation(0.0, 0.0, 0.1), 0.0, "L_1");
  expect_near(out.data() + 48, translation(0.01, 0.0, 0.22), 1e-16, "L_2");
  expect_near(out.data() + 64, translation(0.01, 0.03, 0.22), 1e-16, "tip");
  EXPECT_EQ(tsk_chain_frames(0, T.data(), offsets.data(), tool.data(), out.data(),
                             static_cast<int64_t>(out.size())), TSK_ERROR_COUNT);
  EXPECT_EQ(tsk_chain_frames(2, T.data(), offsets.data(), tool.data(), out.data(),
                             static_cast<int64_t>(out.size()) - 1), TSK_ERROR_BUFFER_SIZE);
}

// One unloaded joint at the base (P = I, no weights, F = 0): C = K_c^-1, so K_tip = K_c in the
// base frame; in the tool frame Ad^T K_c Ad with Ad the tool's adjoint; the implied wrench 0.
TEST(ChainKernel, OneJointTipStiffnessIsItsCartesianStiffness) {
  std::vector<double> Kc(36, 0.0);
  for (int i = 0; i < 6; ++i) {
    Kc[7 * i] = 10.0 * (i + 1);
  }
  Kc[1] = Kc[6] = 3.0;  // symmetric coupling
  const std::vector<double> F(6, 0.0);
  const std::vector<double> tip = kIdentity;
  std::vector<double> out(78, -1.0);
  ASSERT_EQ(tsk_chain_tip(1, kIdentity.data(), kIdentity.data(), tip.data(), F.data(), Kc.data(),
                          nullptr, nullptr, nullptr, TSK_TIP_BASE | TSK_TIP_TOOL, out.data(),
                          78), TSK_OK);
  expect_near(out.data(), std::vector<double>(6, 0.0), 0.0, "implied wrench");
  expect_near(out.data() + 6, Kc, 1e-12, "K_tip base");
  expect_near(out.data() + 42, Kc, 1e-12, "K_tip tool");
  // A singular joint (K_c = 0) and a bad request.
  const std::vector<double> zero(36, 0.0);
  EXPECT_EQ(tsk_chain_tip(1, kIdentity.data(), kIdentity.data(), tip.data(), F.data(),
                          zero.data(), nullptr, nullptr, nullptr, TSK_TIP_BASE, out.data(), 78),
            TSK_ERROR_SINGULAR_SYSTEM);
  EXPECT_EQ(tsk_chain_tip(1, kIdentity.data(), kIdentity.data(), tip.data(), F.data(),
                          Kc.data(), nullptr, nullptr, nullptr, 4, out.data(), 78),
            TSK_ERROR_ARGUMENT);
  EXPECT_EQ(tsk_chain_tip(1, kIdentity.data(), kIdentity.data(), tip.data(), F.data(),
                          Kc.data(), nullptr, nullptr, nullptr, TSK_TIP_BASE, out.data(), 77),
            TSK_ERROR_BUFFER_SIZE);
  EXPECT_EQ(tsk_chain_tip(0, kIdentity.data(), kIdentity.data(), tip.data(), F.data(),
                          Kc.data(), nullptr, nullptr, nullptr, TSK_TIP_BASE, out.data(), 78),
            TSK_ERROR_COUNT);
}

}  // namespace

// The linear model of link 2 at xi = 0 (J_l = J_b = I) with one taut Hooke string a -> b held by
// the load W = -F: M is the inertia, R = [Pi K | -c w w^T | -k w | Pi] with the unit wrench
// w = [a x u; u] of the string (u = (0, 0, 1)), and M^-1 R = R / 2 for the inertia 2 I.
TEST(JointKernel, LinearModelOfOneStringAtRestByHand) {
  const double a[3] = {0.1, 0.0, 0.1}, b[3] = {0.1, 0.0, 0.0};
  Joint joint({a[0], a[1], a[2]}, {b[0], b[1], b[2]}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  Packed out(1);
  ASSERT_EQ(evaluate(joint, out, {0, 0, 0, 0, 0, 0}, {0.05}), TSK_OK);
  std::vector<double> K(out.K(), out.K() + 36);
  std::vector<double> lin(tsk_joint_linear_size(1), 0.0);
  for (int i = 0; i < 6; ++i) {
    lin[i] = -out.wrench()[i];
  }
  std::vector<double> inertia(36, 0.0);
  for (int i = 0; i < 6; ++i) {
    inertia[7 * i] = 2.0;
  }
  const double damping = 0.3;
  ASSERT_EQ(tsk_joint_linear_model(&joint.model, inertia.data(), &damping, 1e-9, out.buf.data(),
                                   static_cast<int64_t>(out.buf.size()), lin.data(),
                                   static_cast<int64_t>(lin.size())),
            TSK_OK);
  const int width = 18 + 1;
  const double* net = lin.data() + 6;
  const double* J = net + 6;
  const double* M = J + 36;
  const double* R = M + 36;
  const double* S = R + 6 * width;
  EXPECT_EQ(S[6 * width], 1.0);  // an equilibrium
  const double w[6] = {0.0, -0.1, 0.0, 0.0, 0.0, 1.0};
  for (int i = 0; i < 6; ++i) {
    EXPECT_NEAR(net[i], 0.0, 1e-15);
    for (int c = 0; c < 6; ++c) {
      EXPECT_EQ(J[6 * i + c], i == c ? 1.0 : 0.0);
      EXPECT_EQ(M[6 * i + c], i == c ? 2.0 : 0.0);
      const int swapped = i < 3 ? i + 3 : i - 3;
      const double want[4] = {K[6 * swapped + c], -damping * w[i] * w[c], 0.0,
                              swapped == c ? 1.0 : 0.0};
      EXPECT_NEAR(R[width * i + c], want[0], 1e-12) << i << c;
      EXPECT_NEAR(R[width * i + 6 + c], want[1], 1e-15) << i << c;
      EXPECT_EQ(R[width * i + 13 + c], want[3]) << i << c;
      for (int block = 0; block < 3; ++block) {
        const int col = block == 0 ? c : (block == 1 ? 6 + c : 13 + c);
        EXPECT_NEAR(S[width * i + col], 0.5 * R[width * i + col], 1e-12) << i << col;
      }
    }
    EXPECT_NEAR(R[width * i + 12], -100.0 * w[i], 1e-12) << i;
    EXPECT_NEAR(S[width * i + 12], -50.0 * w[i], 1e-12) << i;
  }
  // Without the load the state is no equilibrium (the flag), the blocks the same.
  for (int i = 0; i < 6; ++i) {
    lin[i] = 0.0;
  }
  ASSERT_EQ(tsk_joint_linear_model(&joint.model, inertia.data(), nullptr, 1e-9, out.buf.data(),
                                   static_cast<int64_t>(out.buf.size()), lin.data(),
                                   static_cast<int64_t>(lin.size())),
            TSK_OK);
  EXPECT_EQ(lin[84 + 12 * width], 0.0);
  EXPECT_EQ(lin[84 + width + 7], 0.0);  // no damping: its block is 0 (-0.3 * 0.01 above)
}

// The pose terms at T = I of one Hooke string a -> b: l = 0.1, B = X = [u; a x u],
// K0 = k X X^T and M = -X X^T / l + ZE / l with ZE = [[I, -hat(b)], [hat(a), -hat(a) hat(b)]].
TEST(JointKernel, PoseTermsOfOneStringByHand) {
  const double a[3] = {0.1, 0.0, 0.1}, b[3] = {0.1, 0.0, 0.0};
  Joint joint({a[0], a[1], a[2]}, {b[0], b[1], b[2]}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  std::vector<double> buf(tsk_joint_pose_terms_size(1), 0.0);
  for (int i = 0; i < 4; ++i) {
    buf[5 * i] = 1.0;
  }
  ASSERT_EQ(tsk_joint_pose_terms(&joint.model, buf.data(), static_cast<int64_t>(buf.size())),
            TSK_OK);
  const double l = 0.1;
  EXPECT_NEAR(buf[16], l, 1e-17);
  const double X[6] = {0.0, 0.0, 1.0, 0.0, -0.1, 0.0};
  // -hat(a) hat(b) = -(b a^T - (a . b) I), a . b = 0.01.
  const double ab[3][3] = {{-(0.01 - 0.01), 0.0, -(0.01)}, {0.0, 0.01, 0.0}, {0.0, 0.0, 0.01}};
  const double ZE[6][6] = {{1, 0, 0, 0, b[2], -b[1]},
                           {0, 1, 0, -b[2], 0, b[0]},
                           {0, 0, 1, b[1], -b[0], 0},
                           {0, -a[2], a[1], ab[0][0], ab[0][1], ab[0][2]},
                           {a[2], 0, -a[0], ab[1][0], ab[1][1], ab[1][2]},
                           {-a[1], a[0], 0, ab[2][0], ab[2][1], ab[2][2]}};
  for (int r = 0; r < 6; ++r) {
    EXPECT_NEAR(buf[17 + r], X[r], 1e-16);
    for (int c = 0; c < 6; ++c) {
      EXPECT_NEAR(buf[23 + 6 * r + c], 100.0 * X[r] * X[c], 1e-13) << r << c;
      EXPECT_NEAR(buf[59 + 6 * r + c], -X[r] * X[c] / l + ZE[r][c] / l, 1e-13) << r << c;
    }
  }
}

// min 1/2 |t|^2 - t'1 s.t. t_0 + t_1 + t_2 = 3 on a box: t = 1 (nu = 0) when the box holds it;
// a box [0, 0.5]^3 rejects that face; P = 0 makes the face's KKT system singular.
TEST(QpKernel, WarmFaceOptimalRejectedAndSingular) {
  const int64_t n = 3, m = 1;
  auto run = [&](double p, double high, double* t_out) {
    std::vector<double> buf(tsk_qp_face_size(n, m), 0.0);
    for (int i = 0; i < 3; ++i) {
      buf[4 * i] = p;                 // P
      buf[9 + i] = 1.0;               // c
      buf[12 + i] = 1.0;              // A
      buf[16 + i] = 0.0;              // lo
      buf[19 + i] = high;             // hi
      buf[22 + i] = 0.5 * high;       // t0
    }
    buf[15] = 3.0;                    // b
    EXPECT_EQ(tsk_qp_warm_face(n, m, 1e-9, 1e-12, 1e-10, 1e-12, buf.data(),
                               static_cast<int64_t>(buf.size())),
              TSK_OK);
    for (int i = 0; i < 3; ++i) {
      t_out[i] = buf[31 + i];
    }
    return buf.back();
  };
  double t[3];
  EXPECT_EQ(run(1.0, 2.0, t), TSK_FACE_OPTIMAL);
  for (double v : t) {
    EXPECT_NEAR(v, 1.0, 1e-15);
  }
  EXPECT_EQ(run(1.0, 0.5, t), TSK_FACE_REJECTED);
  EXPECT_EQ(run(0.0, 2.0, t), TSK_FACE_SINGULAR);
  std::vector<double> small(tsk_qp_face_size(n, m) - 1, 7.0);
  EXPECT_EQ(tsk_qp_warm_face(n, m, 1e-9, 1e-12, 1e-10, 1e-12, small.data(),
                             static_cast<int64_t>(small.size())),
            TSK_ERROR_BUFFER_SIZE);
  EXPECT_EQ(tsk_qp_face_size(0, 1), TSK_ERROR_COUNT);
}

// exp of a pure translation is [I, v]; of a rotation by pi / 2 about z, that rotation.
TEST(JointKernel, TransformOfATranslationAndAQuarterTurn) {
  Joint joint({0.1, 0.0, 0.1}, {0.1, 0.0, 0.0}, {100.0}, {kInf}, TSK_LAW_HOOKE);
  std::vector<double> buf = {0.0, 0.0, 0.0, 0.01, -0.02, 0.03};
  buf.resize(22, 7.0);
  ASSERT_EQ(tsk_joint_transform(&joint.model, buf.data(), 22), TSK_OK);
  expect_near(buf.data() + 6, {1, 0, 0, 0.01, 0, 1, 0, -0.02, 0, 0, 1, 0.03, 0, 0, 0, 1}, 0.0,
              "T");
  buf = {0.0, 0.0, M_PI / 2, 0.0, 0.0, 0.0};
  buf.resize(22, 7.0);
  ASSERT_EQ(tsk_joint_transform(&joint.model, buf.data(), 22), TSK_OK);
  expect_near(buf.data() + 6, {0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}, 1e-15, "T");
  EXPECT_EQ(tsk_joint_transform(&joint.model, buf.data(), 21), TSK_ERROR_BUFFER_SIZE);
}
