// A C++ consumer of tensegrity_stiffness in another package of a colcon workspace (built by
// test/package/test_workspace_build.py, as docs/kernel.md shows): find_package, the target
// tensegrity_stiffness::kernel and joint_kernel.hpp.
//
// Usage: joint_stiffness INPUT. INPUT has one array per line, its name first: p1 and p2 (3n
// values, the string ends in {1} and {2}), k, max_stretch, rest (n each), xi (6), law (0 Hooke,
// 1 paper). Prints F, K and K_c at xi, one line each: the name, then the values (%.17g).
#include <array>
#include <cstdio>
#include <exception>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "tensegrity_stiffness/joint_kernel.hpp"

namespace tsk = tensegrity_stiffness;

namespace {

std::map<std::string, std::vector<double>> read_arrays(const char* path) {
  std::ifstream in(path);
  if (!in) {
    throw std::runtime_error(std::string("cannot read ") + path);
  }
  std::map<std::string, std::vector<double>> arrays;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream words(line);
    std::string name, word;
    if (!(words >> name)) {
      continue;
    }
    std::vector<double>& values = arrays[name];
    while (words >> word) {
      values.push_back(std::stod(word));  // also "inf"
    }
  }
  return arrays;
}

std::vector<tsk::Vector3> points(const std::vector<double>& flat) {
  std::vector<tsk::Vector3> out(flat.size() / 3);
  for (std::size_t j = 0; j < out.size(); ++j) {
    out[j] = {flat[3 * j], flat[3 * j + 1], flat[3 * j + 2]};
  }
  return out;
}

template <std::size_t N>
void print(const char* name, const std::array<double, N>& values) {
  std::printf("%s", name);
  for (double v : values) {
    std::printf(" %.17g", v);
  }
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: " << argv[0] << " INPUT\n";
    return 2;
  }
  try {
    auto arrays = read_arrays(argv[1]);
    const std::vector<double>& xi = arrays.at("xi");
    if (xi.size() != 6) {
      throw std::runtime_error("xi needs 6 values");
    }
    const auto law = arrays.at("law").at(0) == TSK_LAW_PAPER ? tsk::ForceLaw::kPaper
                                                              : tsk::ForceLaw::kHooke;
    tsk::JointKernel joint(points(arrays.at("p1")), points(arrays.at("p2")), arrays.at("k"),
                           arrays.at("max_stretch"), law);
    const tsk::Screw screw{xi[0], xi[1], xi[2], xi[3], xi[4], xi[5]};
    const tsk::JointState state = joint.evaluate(screw, arrays.at("rest"));
    print("F", state.wrench);
    print("K", state.K);
    print("K_c", state.K_c);
  } catch (const std::exception& error) {
    std::cerr << "joint_stiffness: " << error.what() << "\n";
    return 1;
  }
  return 0;
}
