// Internal to the compiled kernel (not installed, not part of the ABI): one string's tension
// law, shared by src/joint_kernel.cpp (a joint's strings) and src/structure_kernel.cpp (a
// structure's strings); the numpy reference is mechanics/joint.py's force law.

#ifndef TENSEGRITY_STIFFNESS__SRC__STRING_LAW_HPP_
#define TENSEGRITY_STIFFNESS__SRC__STRING_LAW_HPP_

#include <cmath>
#include <cstdint>

#include "tensegrity_stiffness/kernel.h"

namespace tensegrity_stiffness {
namespace detail {

// A string of length l > 0: slack (l <= r0), saturated (l >= r0 + max_stretch), its tension
// and dT/dl (zero off the taut range).
struct StringForce {
  bool slack;
  bool saturated;
  double tension;
  double dtension;
};

// The tension of a string of stiffness k, rest length r0 and law TSK_LAW_HOOKE
// (k (l - r0)) or the other (k (l - r0) / l), its length clipped to [r0, r0 + max_stretch].
inline StringForce string_force(double l, double r0, double max_stretch, double k,
                                int64_t law) {
  const double lmax = r0 + max_stretch;
  StringForce out;
  out.slack = l <= r0;
  out.saturated = l >= lmax;
  const bool taut = !(out.slack || out.saturated);
  const double clipped = std::fmin(std::fmax(l, r0), lmax);
  if (law == TSK_LAW_HOOKE) {
    out.tension = k * (clipped - r0);
    out.dtension = taut ? k : 0.0;
  } else {
    out.tension = k * (clipped - r0) / clipped;
    out.dtension = taut ? k * r0 / (clipped * clipped) : 0.0;
  }
  return out;
}

}  // namespace detail
}  // namespace tensegrity_stiffness

#endif  // TENSEGRITY_STIFFNESS__SRC__STRING_LAW_HPP_
