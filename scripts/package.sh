#!/usr/bin/env bash
# Builds the Debian packages from build/ (scripts/build.sh first):
#   build/packages/densemap-server_<version>_amd64.deb   programs, /etc/densemap, systemd unit
#   build/packages/libdensemap-dev_<version>_amd64.deb   SDK (find_package(densemap)): client, mapper
#   build/packages/python3-densemap_<version>_amd64.deb  import densemap
# Usage: scripts/package.sh      (prints the paths)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${DENSEMAP_BUILD_DIR:-build}
out="$BUILD_DIR/packages"
rm -rf "$out"
mkdir -p "$out"
(cd "$BUILD_DIR" && cpack -G DEB -B "$PWD/packages" >packages/cpack.log 2>&1) || {
  cat "$out/cpack.log" >&2
  echo "package.sh: cpack failed" >&2
  exit 1
}
rm -rf "$out/_CPack_Packages"
ls "$out"/*.deb
