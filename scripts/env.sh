# shellcheck shell=bash
# Source this file (after `bash scripts/setup_env.sh`) to use the built workspace:
#   source scripts/env.sh
# It activates .venv (ROS 2 Jazzy wheels), sources the colcon overlay install/setup.bash (which puts
# the executables' folder install/tensegrity_stiffness/bin, with `tensegrity-stiffness`, on PATH,
# and the package on PYTHONPATH, LD_LIBRARY_PATH and AMENT_PREFIX_PATH), and sets
#   AMENT_PREFIX_PATH             install/<pkg> prefixes (from setup.bash) + $VIRTUAL_ENV (the wheels'
#                                 ament prefix; nothing else sets it for the wheels)
#   ROS_AUTOMATIC_DISCOVERY_RANGE LOCALHOST (DDS discovery on loopback only; override with
#                                 TENSEGRITY_DISCOVERY_RANGE)
#   ROS_DOMAIN_ID                 kept if set, else TENSEGRITY_DEFAULT_DOMAIN_ID (default 42)
#   RMW_IMPLEMENTATION            rmw_fastrtps_cpp if unset (the only RMW in the wheels)
# Safe under `set -u` / `set -e` in the calling shell, and safe to source more than once.

_tsi_strip_empty() {
  local name="$1" value
  value="${!name:-}"
  while [[ "$value" == *::* ]]; do value="${value//::/:}"; done
  value="${value#:}"
  value="${value%:}"
  if [[ -n "$value" ]]; then export "$name=$value"; else unset "$name"; fi
}

_tsi_env_main() {
  local repo venv
  repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
  venv="$repo/.venv"
  if [[ ! -x "$venv/bin/python" ]]; then
    echo "scripts/env.sh: $venv missing; run: bash scripts/setup_env.sh" >&2
    return 1
  fi

  # shellcheck disable=SC1091
  source "$venv/bin/activate"

  # The wheels' bootstrapper re-executes python once with LD_LIBRARY_PATH extended and sets the
  # guard _ROS_WHEELS_BOOTSTRAP_COMPLETE=1. A guard inherited without the matching library path
  # (e.g. from another venv) would make rclpy imports fail: only then drop it, so it re-runs.
  if [[ -n "${_ROS_WHEELS_BOOTSTRAP_COMPLETE:-}" && ":${LD_LIBRARY_PATH:-}:" != *":$venv/lib:"* ]]; then
    unset _ROS_WHEELS_BOOTSTRAP_COMPLETE
  fi

  if [[ ":${AMENT_PREFIX_PATH:-}:" != *":$VIRTUAL_ENV:"* ]]; then
    export AMENT_PREFIX_PATH="${AMENT_PREFIX_PATH:+$AMENT_PREFIX_PATH:}$VIRTUAL_ENV"
  fi
  if [[ ":${CMAKE_PREFIX_PATH:-}:" != *":$VIRTUAL_ENV:"* ]]; then
    export CMAKE_PREFIX_PATH="${CMAKE_PREFIX_PATH:+$CMAKE_PREFIX_PATH:}$VIRTUAL_ENV"
  fi

  if [[ -f "$repo/install/setup.bash" ]]; then
    # colcon's setup scripts reference unset variables: never source them under `set -u`.
    # shellcheck disable=SC1091
    source "$repo/install/setup.bash"
  else
    echo "scripts/env.sh: $repo/install/setup.bash missing; run: bash scripts/setup_env.sh" >&2
  fi

  # An empty entry (leading/trailing/double ':') means the current directory: remove them.
  _tsi_strip_empty LD_LIBRARY_PATH
  _tsi_strip_empty PYTHONPATH

  export ROS_AUTOMATIC_DISCOVERY_RANGE="${TENSEGRITY_DISCOVERY_RANGE:-LOCALHOST}"
  export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-${TENSEGRITY_DEFAULT_DOMAIN_ID:-42}}"
  export RMW_IMPLEMENTATION="${RMW_IMPLEMENTATION:-rmw_fastrtps_cpp}"
  export TENSEGRITY_ENV_SOURCED="$repo"
}

# Run with nounset and errexit off, then restore the caller's options (read from $-, since
# `$(set +o)` would report errexit as off inside the command substitution).
_tsi_saved_flags="$-"
set +eu
_tsi_env_main
_tsi_env_rc=$?
[[ "$_tsi_saved_flags" == *u* ]] && set -u
[[ "$_tsi_saved_flags" == *e* ]] && set -e
unset -f _tsi_env_main _tsi_strip_empty
unset _tsi_saved_flags
# Status of the last command = status of `source scripts/env.sh` (a `set -e` caller stops on a
# failure).
_tsi_env_finish() {
  local rc="$_tsi_env_rc"
  unset _tsi_env_rc
  unset -f _tsi_env_finish
  return "$rc"
}
_tsi_env_finish
