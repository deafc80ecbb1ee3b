// The C++ view of the kernel (include/tensegrity_stiffness/joint_kernel.hpp): its defaults are
// kernel_defaults.h's, its outputs the packed buffer's, copies and moves keep their own arrays,
// and refused arguments throw. Run by ctest and by test/kernel/test_kernel_gtest.py.

#include <gtest/gtest.h>

#include <limits>
#include <stdexcept>
#include <utility>
#include <vector>

#include "tensegrity_stiffness/joint_kernel.hpp"

namespace {

using tensegrity_stiffness::ForceLaw;
using tensegrity_stiffness::JointKernel;
using tensegrity_stiffness::KernelError;
using tensegrity_stiffness::Screw;
namespace defaults = tensegrity_stiffness::defaults;

const double kInf = std::numeric_limits<double>::infinity();

// One string from a = (0.1, 0, 0.1) in {1} to b = (0.1, 0, 0) in {2}, k = 100 N/m: at xi = 0 it
// is 0.1 m long, with l0 = 0.05 m its tension is 5 N along +z, the wrench [0, 0, 5, 0, -0.5, 0].
JointKernel one_string(ForceLaw law = ForceLaw::kHooke) {
  return JointKernel({{0.1, 0.0, 0.1}}, {{0.1, 0.0, 0.0}}, {100.0}, {kInf}, law);
}

const Screw kZero{};
const std::vector<double> kRest{0.05};

TEST(JointKernelHpp, CarriesTheDefaultsOfThePythonPackage) {
  JointKernel joint = one_string();
  const tsk_joint_model& m = joint.model();
  EXPECT_EQ(m.n_strings, 1);
  EXPECT_EQ(m.law, TSK_LAW_HOOKE);
  ASSERT_EQ(m.series_terms, defaults::kSeriesTerms);
  for (std::size_t i = 0; i < defaults::kSeries.size(); ++i) {
    EXPECT_EQ(m.series[i], defaults::kSeries[i]) << "entry " << i;
  }
  EXPECT_EQ(m.series_threshold, TSK_DEFAULT_SERIES_THRESHOLD);
  EXPECT_EQ(m.min_string_length, TSK_DEFAULT_MIN_STRING_LENGTH);
}

TEST(JointKernelHpp, OneTautStringByHand) {
  JointKernel joint = one_string();
  const tensegrity_stiffness::JointState state = joint.evaluate(kZero, kRest);
  EXPECT_DOUBLE_EQ(state.lengths.at(0), 0.1);
  EXPECT_DOUBLE_EQ(state.tensions.at(0), 5.0);
  EXPECT_FALSE(state.slack.at(0));
  EXPECT_FALSE(state.saturated.at(0));
  EXPECT_DOUBLE_EQ(state.strings.at(0)[2], 0.1);
  const double want[6] = {0.0, 0.0, 5.0, 0.0, -0.5, 0.0};
  for (int i = 0; i < 6; ++i) {
    EXPECT_NEAR(state.wrench[i], want[i], 1e-15) << "F " << i;
  }
  for (int i = 0; i < 16; ++i) {
    EXPECT_EQ(state.T[i], i % 5 == 0 ? 1.0 : 0.0) << "T " << i;
  }
  // A = df/ds = diag(50, 50, 100); K_c = [H_D, -H_G] has A in its top-left block.
  EXPECT_NEAR(state.K_c[0], 50.0, 1e-12);
  EXPECT_NEAR(state.K_c[7], 50.0, 1e-12);
  EXPECT_NEAR(state.K_c[14], 100.0, 1e-12);
}

TEST(JointKernelHpp, ShortCallsEqualTheFullEvaluation) {
  JointKernel joint = one_string(ForceLaw::kPaper);
  const Screw xi{0.2, -0.1, 0.3, 0.01, 0.0, -0.02};
  const tensegrity_stiffness::JointState state = joint.evaluate(xi, kRest);
  EXPECT_EQ(joint.wrench(xi, kRest), state.wrench);
  EXPECT_EQ(joint.stiffness(xi, kRest), state.K);
  EXPECT_EQ(joint.cartesian_stiffness(xi, kRest), state.K_c);
}

TEST(JointKernelHpp, CopiesAndMovesOwnTheirArrays) {
  const Screw xi{0.1, 0.0, 0.0, 0.0, 0.02, 0.0};
  JointKernel original = one_string();
  const tensegrity_stiffness::Matrix6 want = original.cartesian_stiffness(xi, kRest);
  JointKernel copy(original);
  JointKernel assigned = one_string(ForceLaw::kPaper);
  assigned = original;
  JointKernel moved(std::move(original));
  EXPECT_EQ(copy.cartesian_stiffness(xi, kRest), want);
  EXPECT_EQ(assigned.cartesian_stiffness(xi, kRest), want);
  EXPECT_EQ(moved.cartesian_stiffness(xi, kRest), want);
  EXPECT_NE(copy.model().p1, moved.model().p1);
  EXPECT_NE(copy.model().series, assigned.model().series);
}

TEST(JointKernelHpp, RefusedArgumentsThrow) {
  EXPECT_THROW(JointKernel({{0.0, 0.0, 0.0}}, {}, {1.0}, {kInf}), std::invalid_argument);
  EXPECT_THROW(JointKernel({}, {}, {}, {}), std::invalid_argument);
  EXPECT_THROW(JointKernel({{0.0, 0.0, 0.0}}, {{0.0, 0.0, 1.0}}, {1.0}, {kInf}, ForceLaw::kHooke,
                           1e-12, {1.0, 2.0}),
               std::invalid_argument);
  JointKernel joint = one_string();
  EXPECT_THROW(joint.wrench(kZero, {0.05, 0.05}), std::invalid_argument);
  JointKernel zero({{0.1, 0.0, 0.0}}, {{0.1, 0.0, 0.0}}, {1.0}, {kInf});
  try {
    zero.wrench(kZero, kRest);
    FAIL() << "a zero-length string was evaluated";
  } catch (const KernelError& error) {
    EXPECT_EQ(error.status(), TSK_ERROR_ZERO_LENGTH);
    EXPECT_NE(std::string(error.what()).find("TSK_ERROR_ZERO_LENGTH"), std::string::npos);
  }
}

}  // namespace
