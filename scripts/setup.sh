#!/usr/bin/env bash
# Installs everything teachsim needs to build, test and run, from Debian's packages (and, for the
# browser UI, the npm registry). Idempotent: a second run installs nothing and takes a second.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git
  libeigen3-dev nlohmann-json3-dev libcli11-dev libspdlog-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libfcl-dev libccd-dev            # peer in the distance benchmark and tests only
  libmujoco-dev                    # the work site's simulated world; peer in the simulator benchmark
  libqhull-dev                     # MuJoCo's CMake target names its headers
  libopencv-dev libopencv-contrib-dev
  libnanoflann-dev libflann-dev
  libboost-dev libboost-system-dev
  libompl-dev liburdfdom-dev        # OMPL: peer in the planner benchmark; links Boost.Serialization
  libboost-serialization-dev libboost-filesystem-dev
  clang libclang-rt-14-dev         # libFuzzer harnesses
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]})); then
  echo "setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
  if [[ $(id -u) -ne 0 ]]; then
    echo "setup: root is needed to install packages (run as root, or install them with sudo)" >&2
    exit 2
  fi
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "setup: all ${#packages[@]} Debian packages present"
fi
