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
  libnanoflann-dev                 # the recognizer's model-view index (kd-tree search)
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

# ---- browser UI and its end-to-end tests (web/, tests/browser/) -------------------------------
# Debian's chromium drives the browser tests (playwright-core never downloads a browser of its
# own); three.js and playwright-core come from the npm registry, pinned in web/package-lock.json,
# installed with `npm ci` only when web/node_modules is missing or older than the lock file.
if ! dpkg-query -W -f='${Status}' chromium 2>/dev/null | grep -q "install ok installed"; then
  echo "setup: installing Debian's chromium (browser end-to-end tests)"
  if [[ $(id -u) -ne 0 ]]; then
    echo "setup: root is needed to install chromium (run as root, or: sudo apt-get install chromium)" >&2
    exit 2
  fi
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends chromium
fi
web_dir="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/web"
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  echo "setup: node and npm (Node.js >= 20) are needed for the browser UI's packages; the browser tests skip without them" >&2
elif [[ -f "$web_dir/package-lock.json" ]]; then
  lock_sum=$(sha256sum "$web_dir/package-lock.json" | cut -d' ' -f1)
  stamp="$web_dir/node_modules/.teachsim-lock.sha256"
  if [[ ! -f "$stamp" || "$(cat "$stamp")" != "$lock_sum" ]]; then
    echo "setup: npm ci in web/ (three, playwright-core)"
    (cd "$web_dir" && npm ci --no-audit --no-fund --loglevel=error)
    echo "$lock_sum" > "$stamp"
  else
    echo "setup: web/node_modules up to date"
  fi
fi
# ---- end of the browser block -----------------------------------------------------------------
