#!/usr/bin/env bash
# Installs every Debian package densemap needs to build, test, benchmark and demo.
# Idempotent: packages already present are skipped. Uses sudo when not root.
# Usage: scripts/install-deps.sh [--iln]   (--iln: also PyTorch and protobuf for Python, to train
# the ILN model with tools/iln/iln.py; never needed to build, test or run densemap)
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config ccache
  liboctomap-dev octomap-tools libdynamicedt3d-dev
  libtbb-dev libeigen3-dev
  libgtest-dev libgmock-dev
  cyclonedds-dev cyclonedds-tools
  libprotobuf-dev protobuf-compiler
  libcli11-dev libspdlog-dev
  libbz2-dev zlib1g-dev libzstd-dev liblz4-dev libsqlite3-dev iproute2 util-linux
  clang-format clang-tidy
  dpkg-dev fakeroot lintian adduser help2man
  clang-16 libclang-rt-16-dev libsystemd-dev
  openssl tcpdump
  libfastrtps-dev fastddsgen  # the foreign-vendor test: eProsima Fast DDS, ROS 2's default
  python3-dev pybind11-dev python3-numpy python3-pytest python3-matplotlib  # import densemap
  libboost-dev libssl-dev  # the Foxglove WebSocket endpoint (Boost.Beast; wss)
  nodejs  # its test client, @foxglove/ws-protocol (tests/foxglove: npm ci)
)
# Debian's nodejs comes without npm (the npm package); a Node.js that brings its own npm
# (NodeSource's) conflicts with that package: it is only needed when no npm is on the PATH.
command -v npm >/dev/null 2>&1 || PACKAGES+=(npm)
if [ "${1:-}" = "--iln" ]; then
  PACKAGES+=(python3-torch python3-protobuf libopenblas0-pthread)
elif [ $# -gt 0 ]; then
  echo "usage: scripts/install-deps.sh [--iln]" >&2
  exit 2
fi

missing=()
for pkg in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages already installed"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "install-deps: not root and sudo is missing; install: ${missing[*]}" >&2
    exit 1
  fi
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
