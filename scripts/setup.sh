#!/usr/bin/env bash
# Set up flatland on Debian 12: install the Debian packages that are missing, then configure and
# build into build/ (Release, Ninja). Safe to run again: it installs and rebuilds only what is
# needed.
#
# Usage: scripts/setup.sh [--no-build]
set -euo pipefail

usage() { echo "usage: scripts/setup.sh [--no-build]" >&2; }

build=1
for arg in "$@"; do
  case "$arg" in
    --no-build) build=0 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "setup: unknown argument: $arg" >&2; usage; exit 2 ;;
  esac
done

log() { echo "setup: $*" >&2; }

packages=(
  cmake g++ ninja-build pkg-config
  libeigen3-dev libyaml-cpp-dev libcli11-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  gnuplot-nox python3
  python3-dev pybind11-dev python3-numpy python3-pytest python3-matplotlib python3-scipy
  python3-venv python3-pip
  libmujoco-dev
  libopencv-dev libavutil-dev libavcodec-dev libavformat-dev libswscale-dev libosmesa6-dev mesa-common-dev libegl-dev libegl-mesa0 ffmpeg
  libceres-dev libboost-dev libnlopt-dev
  clang libclang-rt-14-dev
  openmpi-bin libopenmpi-dev python3-mpi4py
)

missing=()
for p in "${packages[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
  [ "$status" = "install ok installed" ] || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  log "all ${#packages[@]} Debian packages already installed"
else
  as_root=()
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then
      as_root=(sudo)
    else
      log "missing packages (${missing[*]}) and not root, and sudo is not available"
      exit 1
    fi
  fi
  log "installing missing packages: ${missing[*]}"
  "${as_root[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update >&2
  "${as_root[@]}" env DEBIAN_FRONTEND=noninteractive \
    apt-get install -y --no-install-recommends "${missing[@]}" >&2
fi

if [ "$build" -eq 0 ]; then
  log "--no-build: skipping configure and build"
  exit 0
fi

cd "$(dirname "${BASH_SOURCE[0]}")/.."
log "configuring: cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >&2
log "building: cmake --build build -j$(nproc)"
cmake --build build -j"$(nproc)" >&2
log "done: build/bin/flatland"
