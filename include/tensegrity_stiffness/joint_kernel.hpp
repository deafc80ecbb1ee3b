// C++ view of the compiled kernel's joint evaluation (the C ABI of kernel.h), for controllers:
//
//   #include <tensegrity_stiffness/joint_kernel.hpp>
//   tensegrity_stiffness::JointKernel joint(p1, p2, k, max_stretch);   // per-string arrays
//   std::array<double, 36> Kc = joint.cartesian_stiffness(xi, rest_lengths);
//
// Link with the CMake target tensegrity_stiffness::kernel. The model's series tables, threshold
// and minimum string length default to the values the Python package passes (kernel_defaults.h,
// generated from them at build time), so both languages compute the same numbers. Matrices are
// row-major std::array; failures throw (KernelError for a status of the library,
// std::invalid_argument for arrays of unequal lengths). An object owns its arrays and one
// evaluation buffer: no allocation per call, one object per thread.
#ifndef TENSEGRITY_STIFFNESS__JOINT_KERNEL_HPP_
#define TENSEGRITY_STIFFNESS__JOINT_KERNEL_HPP_

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "tensegrity_stiffness/kernel.h"
#include "tensegrity_stiffness/kernel_defaults.h"

namespace tensegrity_stiffness {

/// The constants the Python package gives every joint model (one home: kernel_defaults.h).
namespace defaults {
inline constexpr int64_t kSeriesTerms = TSK_DEFAULT_SERIES_TERMS;
inline constexpr std::array<double, TSK_SERIES_ROWS * TSK_DEFAULT_SERIES_TERMS> kSeries =
    TSK_DEFAULT_SERIES;
inline constexpr double kSeriesThreshold = TSK_DEFAULT_SERIES_THRESHOLD;
inline constexpr double kMinStringLength = TSK_DEFAULT_MIN_STRING_LENGTH;
}  // namespace defaults

/// Force laws (mechanics/joint.py's FORCE_LAWS): Hooke k (l - l0); the paper's k (l - l0) / l.
enum class ForceLaw : int64_t { kHooke = TSK_LAW_HOOKE, kPaper = TSK_LAW_PAPER };

using Vector3 = std::array<double, 3>;
using Screw = std::array<double, 6>;      // xi = [omega; v] (rad, m)
using Wrench = std::array<double, 6>;     // F = [force; moment] in {1}
using Matrix4 = std::array<double, 16>;   // row-major 4 x 4
using Matrix6 = std::array<double, 36>;   // row-major 6 x 6

/// A negative status of the library (TSK_ERROR_*), e.g. TSK_ERROR_ZERO_LENGTH.
class KernelError : public std::runtime_error {
 public:
  KernelError(int64_t status, const std::string& call)
      : std::runtime_error(call + " returned " + std::to_string(status) + " (" + name(status) +
                           ")"),
        status_(status) {}

  int64_t status() const noexcept { return status_; }

  static const char* name(int64_t status) noexcept {
    switch (status) {
      case TSK_ERROR_NULL_POINTER: return "TSK_ERROR_NULL_POINTER";
      case TSK_ERROR_COUNT: return "TSK_ERROR_COUNT";
      case TSK_ERROR_BUFFER_SIZE: return "TSK_ERROR_BUFFER_SIZE";
      case TSK_ERROR_ARGUMENT: return "TSK_ERROR_ARGUMENT";
      case TSK_ERROR_ZERO_LENGTH: return "TSK_ERROR_ZERO_LENGTH";
      case TSK_ERROR_SINGULAR_SYSTEM: return "TSK_ERROR_SINGULAR_SYSTEM";
      case TSK_ERROR_SINGULAR_COMPLIANCE: return "TSK_ERROR_SINGULAR_COMPLIANCE";
      case TSK_ERROR_INTERNAL: return "TSK_ERROR_INTERNAL";
      default: return "TSK_ERROR_UNKNOWN";
    }
  }

 private:
  int64_t status_;
};

/// Everything one evaluation gives (kernel.h's packed buffer, unpacked).
struct JointState {
  Matrix4 T{};                   // exp(hat(xi)): {2} into {1}
  std::vector<Vector3> strings;  // s_j = p1_j - T p2_j in {1}
  std::vector<double> lengths;   // |s_j|
  std::vector<double> tensions;  // string forces (>= 0)
  Wrench wrench{};               // F
  Matrix6 K{};                   // dF/dxi
  Matrix6 K_c{};                 // Cartesian stiffness
  std::vector<bool> slack;       // l <= l0
  std::vector<bool> saturated;   // l >= l0 + max_stretch
};

/// One joint model bound to the kernel: string j joins p1[j] (in {1}) to p2[j] (in {2}) with
/// stiffness k[j] (N/m), stretch limit max_stretch[j] (m, infinity for none).
class JointKernel {
 public:
  JointKernel(const std::vector<Vector3>& p1, const std::vector<Vector3>& p2,
              std::vector<double> k, std::vector<double> max_stretch,
              ForceLaw law = ForceLaw::kHooke,
              double min_string_length = defaults::kMinStringLength,
              std::vector<double> series = {defaults::kSeries.begin(), defaults::kSeries.end()},
              double series_threshold = defaults::kSeriesThreshold)
      : k_(std::move(k)), max_stretch_(std::move(max_stretch)), series_(std::move(series)) {
    const std::size_t n = p1.size();
    if (n == 0 || p2.size() != n || k_.size() != n || max_stretch_.size() != n) {
      throw std::invalid_argument(
          "JointKernel: p1, p2, k and max_stretch need the same number (>= 1) of strings");
    }
    if (series_.empty() || series_.size() % TSK_SERIES_ROWS != 0) {
      throw std::invalid_argument("JointKernel: series needs TSK_SERIES_ROWS equal rows");
    }
    if (tsk_abi_version() != TSK_ABI_VERSION) {
      throw KernelError(TSK_ERROR_ARGUMENT, "tsk_abi_version (library and header differ)");
    }
    for (std::size_t j = 0; j < n; ++j) {
      p1_.insert(p1_.end(), p1[j].begin(), p1[j].end());
      p2_.insert(p2_.end(), p2[j].begin(), p2[j].end());
    }
    model_.n_strings = static_cast<int64_t>(n);
    model_.law = static_cast<int64_t>(law);
    model_.series_terms = static_cast<int64_t>(series_.size() / TSK_SERIES_ROWS);
    model_.series_threshold = series_threshold;
    model_.min_string_length = min_string_length;
    const int64_t size = tsk_joint_packed_size(model_.n_strings);
    if (size < 0) {
      throw KernelError(size, "tsk_joint_packed_size");
    }
    buffer_.assign(static_cast<std::size_t>(size), 0.0);
    bind();
  }

  JointKernel(const JointKernel& other)
      : p1_(other.p1_), p2_(other.p2_), k_(other.k_), max_stretch_(other.max_stretch_),
        series_(other.series_), buffer_(other.buffer_), model_(other.model_) {
    bind();
  }
  JointKernel(JointKernel&& other) noexcept
      : p1_(std::move(other.p1_)), p2_(std::move(other.p2_)), k_(std::move(other.k_)),
        max_stretch_(std::move(other.max_stretch_)), series_(std::move(other.series_)),
        buffer_(std::move(other.buffer_)), model_(other.model_) {
    bind();
  }
  JointKernel& operator=(JointKernel other) noexcept {
    swap(other);
    return *this;
  }
  ~JointKernel() = default;

  std::size_t n_strings() const noexcept { return k_.size(); }

  /// The model as the C ABI sees it (pointers into this object).
  const tsk_joint_model& model() const noexcept { return model_; }

  /// Everything at screw xi with these rest lengths (n values, m).
  JointState evaluate(const Screw& xi, const std::vector<double>& rest_lengths) {
    run(xi, rest_lengths, TSK_MODE_FULL);
    const std::size_t n = n_strings();
    JointState state;
    const double* b = buffer_.data() + 6 + n;
    copy(b, state.T);
    b += 16;
    state.strings.resize(n);
    for (std::size_t j = 0; j < n; ++j, b += 3) {
      state.strings[j] = {b[0], b[1], b[2]};
    }
    state.lengths.assign(b, b + n);
    state.tensions.assign(b + n, b + 2 * n);
    b += 2 * n;
    copy(b, state.wrench);
    copy(b + 6, state.K);
    copy(b + 42, state.K_c);
    const auto* flags = reinterpret_cast<const unsigned char*>(b + 78);
    state.slack.assign(flags, flags + n);
    state.saturated.assign(flags + n, flags + 2 * n);
    return state;
  }

  /// F at xi.
  Wrench wrench(const Screw& xi, const std::vector<double>& rest_lengths) {
    run(xi, rest_lengths, TSK_MODE_WRENCH);
    Wrench out;
    copy(buffer_.data() + offset_wrench(), out);
    return out;
  }

  /// K = dF/dxi at xi.
  Matrix6 stiffness(const Screw& xi, const std::vector<double>& rest_lengths) {
    run(xi, rest_lengths, TSK_MODE_STIFFNESS);
    Matrix6 out;
    copy(buffer_.data() + offset_wrench() + 6, out);
    return out;
  }

  /// K_c, the Cartesian stiffness, at xi.
  Matrix6 cartesian_stiffness(const Screw& xi, const std::vector<double>& rest_lengths) {
    run(xi, rest_lengths, TSK_MODE_FULL);
    Matrix6 out;
    copy(buffer_.data() + offset_wrench() + 42, out);
    return out;
  }

  void swap(JointKernel& other) noexcept {
    p1_.swap(other.p1_);
    p2_.swap(other.p2_);
    k_.swap(other.k_);
    max_stretch_.swap(other.max_stretch_);
    series_.swap(other.series_);
    buffer_.swap(other.buffer_);
    std::swap(model_, other.model_);
    bind();
    other.bind();
  }

 private:
  // Points the C struct at the arrays this object owns (after construction, copy, move).
  void bind() noexcept {
    model_.p1 = p1_.data();
    model_.p2 = p2_.data();
    model_.k = k_.data();
    model_.max_stretch = max_stretch_.data();
    model_.series = series_.data();
  }

  std::size_t offset_wrench() const noexcept { return 22 + 6 * n_strings(); }

  void run(const Screw& xi, const std::vector<double>& rest_lengths, int64_t mode) {
    const std::size_t n = n_strings();
    if (rest_lengths.size() != n) {
      throw std::invalid_argument("JointKernel: rest_lengths needs one value per string");
    }
    std::copy(xi.begin(), xi.end(), buffer_.begin());
    std::copy(rest_lengths.begin(), rest_lengths.end(), buffer_.begin() + 6);
    const int64_t status = tsk_joint_evaluate_packed(&model_, mode, buffer_.data(),
                                                     static_cast<int64_t>(buffer_.size()));
    if (status != TSK_OK) {
      throw KernelError(status, "tsk_joint_evaluate_packed");
    }
  }

  template <std::size_t N>
  static void copy(const double* from, std::array<double, N>& to) noexcept {
    std::copy(from, from + N, to.begin());
  }

  std::vector<double> p1_, p2_, k_, max_stretch_, series_, buffer_;
  tsk_joint_model model_{};
};

}  // namespace tensegrity_stiffness

#endif  // TENSEGRITY_STIFFNESS__JOINT_KERNEL_HPP_
