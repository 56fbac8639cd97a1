#!/usr/bin/env bash
# Checks what a user installs (scripts/test.sh runs it after the tests):
#  1. builds the .debs (scripts/package.sh) and checks their contents (dpkg-deb -c) and that
#     lintian finds no errors;
#  2. installs the SDK alone to a temporary prefix (cmake --install --component dev), builds the
#     example client (client/examples/wall_scan) against it and runs it against a server;
#  3. as root: installs the three packages with dpkg -i, checks the packaged config with
#     `densemap-server --check-config /etc/densemap/densemap.textproto`, builds the examples
#     against the installed libdensemap-dev, imports densemap with /usr/bin/python3 and maps a
#     point, then purges the packages (the machine is left as it was, but for the `densemap`
#     system user). Not root: the packages are unpacked with dpkg-deb -x, the config checked
#     and the module imported there instead.
# DDS stays on loopback: run it in a private network namespace (test.sh does).
# Usage: scripts/check-packages.sh      Env: DENSEMAP_BUILD_DIR (default build)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${DENSEMAP_BUILD_DIR:-build}
BIN="$PWD/$BUILD_DIR/bin"
work=$(mktemp -d)
installed=0
cleanup() {
  if [ "$installed" -eq 1 ]; then
    dpkg --purge densemap-server libdensemap-dev python3-densemap >/dev/null 2>&1 || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT
say() { echo "check-packages: $*"; }
die() {
  echo "check-packages: FAILED: $*" >&2
  exit 1
}

# --- 1. The packages and their contents -----------------------------------------------------
scripts/package.sh >/dev/null
server_deb=$(ls "$BUILD_DIR"/packages/densemap-server_*.deb)
dev_deb=$(ls "$BUILD_DIR"/packages/libdensemap-dev_*.deb)
python_deb=$(ls "$BUILD_DIR"/packages/python3-densemap_*.deb)
dpkg-deb -c "$python_deb" | awk '{print $6}' >"$work/python.txt"
dpkg-deb -c "$server_deb" | awk '{print $6}' >"$work/server.txt"
dpkg-deb -c "$dev_deb" | awk '{print $6}' >"$work/dev.txt"
for f in ./usr/bin/densemap-server ./usr/bin/densemap ./usr/bin/densemap-map ./usr/bin/densemap-make-pki \
  ./etc/densemap/densemap.textproto ./lib/systemd/system/densemap-server.service \
  ./var/lib/densemap/ ./usr/share/densemap/models/iln.pb \
  ./usr/share/doc/densemap-server/copyright ./usr/share/doc/densemap-server/changelog.Debian.gz \
  ./usr/share/doc/densemap-server/README.md ./usr/share/doc/densemap-server/docs/architecture.md \
  ./usr/share/man/man1/densemap-server.1.gz ./usr/share/man/man1/densemap.1.gz \
  ./usr/share/man/man1/densemap-make-pki.1.gz; do
  grep -qxF "$f" "$work/server.txt" || die "densemap-server lacks $f"
done
# Libraries in Debian's multiarch directory (lib/<triplet>).
multiarch=$(dpkg-architecture -qDEB_HOST_MULTIARCH 2>/dev/null || gcc -print-multiarch)
lib=./usr/lib/$multiarch
for f in ./usr/include/densemap/client/client.hpp $lib/libdensemap_client.a \
  ./usr/include/densemap/mapper/mapper.hpp $lib/libdensemap_mapper.a \
  $lib/cmake/densemap/densemapConfig.cmake $lib/cmake/densemap/densemapTargets.cmake \
  ./usr/share/doc/libdensemap-dev/copyright; do
  grep -qxF "$f" "$work/dev.txt" || die "libdensemap-dev lacks $f"
done
# The Python module in Debian's dist-packages, with its stubs; it depends on NumPy.
for f in ./usr/lib/python3/dist-packages/densemap/__init__.py \
  ./usr/lib/python3/dist-packages/densemap/__init__.pyi ./usr/lib/python3/dist-packages/densemap/py.typed \
  ./usr/share/doc/python3-densemap/copyright; do
  grep -qxF "$f" "$work/python.txt" || die "python3-densemap lacks $f"
done
grep -qE '^\./usr/lib/python3/dist-packages/densemap/_densemap\.cpython-[0-9]+-[^/]*\.so$' "$work/python.txt" ||
  die "python3-densemap lacks the native module _densemap.cpython-*.so"
dpkg-deb -f "$python_deb" Depends | grep -q python3-numpy || die "python3-densemap does not depend on python3-numpy"
# Nothing of the build tree, the tests or the shared data leaks into a package.
if grep -E '/tests?/|_test|/work/|shared/data|\.o$' "$work/server.txt" "$work/dev.txt" "$work/python.txt"; then
  die "unexpected files in a package"
fi
dpkg-deb -f "$server_deb" Depends | grep -q libddsc || die "densemap-server does not depend on Cyclone DDS"
dpkg-deb --fsys-tarfile "$server_deb" | tar -xO ./usr/share/doc/densemap-server/copyright |
  grep -q '^License: Apache-2.0' || die "the copyright file does not name the Apache-2.0 license"
grep -q '/var/lib/densemap/densemap.dmap' <(dpkg-deb --fsys-tarfile "$server_deb" |
  tar -xO ./etc/densemap/densemap.textproto) || die "the packaged config does not keep its snapshot in /var/lib/densemap"
say "contents ok: densemap-server $(wc -l <"$work/server.txt") entries, libdensemap-dev $(wc -l <"$work/dev.txt")"
if command -v lintian >/dev/null 2>&1; then
  lintian --tag-display-limit 0 "$server_deb" "$dev_deb" "$python_deb" >"$work/lintian.txt" 2>&1 || true
  if grep -q '^E:' "$work/lintian.txt"; then
    cat "$work/lintian.txt" >&2
    die "lintian reports errors"
  fi
  # Every installed program has its man page (help2man, cmake/DensemapManPages.cmake).
  if grep -q 'no-manual-page' "$work/lintian.txt"; then
    grep 'no-manual-page' "$work/lintian.txt" >&2
    die "a program without a man page (is help2man installed? scripts/install-deps.sh)"
  fi
  say "lintian: no errors ($(grep -c '^W:' "$work/lintian.txt" || true) warnings)"
else
  say "lintian not installed (scripts/install-deps.sh installs it): skipped"
fi

# --- 2. The SDK in a temporary prefix, and the example built against it ---------------------
cmake --install "$BUILD_DIR" --component dev --prefix "$work/sdk" >/dev/null
cmake -S client/examples/wall_scan -B "$work/example" -DCMAKE_PREFIX_PATH="$work/sdk" \
  -DCMAKE_BUILD_TYPE=Release >"$work/example.log" 2>&1 || { cat "$work/example.log" >&2; die "example: configure"; }
cmake --build "$work/example" >>"$work/example.log" 2>&1 || { cat "$work/example.log" >&2; die "example: build"; }
say "example built against the SDK in a temporary prefix"
# The network client links no engine and no TBB: its link line names neither.
cmake --build "$work/example" --clean-first --verbose >"$work/example-link.log" 2>&1
grep -q 'libdensemap_client\.a' "$work/example-link.log" || die "cannot read the example's link line"
if grep -oE '[^ ]*(tbb|densemap_(pipeline|raycast|kernel|upsample|parallel|mapper))\.(a|so)[^ ]*' \
    "$work/example-link.log"; then
  die "densemap::client links the engine or TBB"
fi
say "densemap::client's link line: no engine, no TBB"
# The in-process Mapper: OctoMap's classic example (insert, query, save .bt), built and run.
build_mapper_example() {
  local dir=$1 prefix=$2
  cmake -S mapper/examples/simple_map -B "$dir" ${prefix:+-DCMAKE_PREFIX_PATH="$prefix"} \
    -DCMAKE_BUILD_TYPE=Release >"$dir.log" 2>&1 && cmake --build "$dir" >>"$dir.log" 2>&1 ||
    { cat "$dir.log" >&2; die "mapper example: build"; }
  (cd "$dir" && ./simple_map "$dir/wall.bt") >"$dir/run.txt" 2>&1 ||
    { cat "$dir/run.txt" >&2; die "mapper example: run"; }
  grep -q '(4.0 0.0 0.0): occupied' "$dir/run.txt" && grep -q '(2.0 0.0 0.0): free' "$dir/run.txt" &&
    [ -s "$dir/wall.bt" ] || { cat "$dir/run.txt" >&2; die "mapper example: wrong answers"; }
}
build_mapper_example "$work/mapper-example" "$work/sdk"
say "mapper example built against the SDK and run: $(tail -1 "$work/mapper-example/run.txt")"

# The SDK's headers name no DDS, protobuf, TBB or map internals, and every one compiles in a
# translation unit that reaches no Cyclone DDS, TBB, protobuf or OctoMap header.
headers=$(cd "$work/sdk/include" && find densemap -name '*.hpp' | sort)
[ -n "$headers" ] || die "the SDK installed no headers"
if grep -nE 'dds_|<dds/|tbb::|<tbb/|BlockStore|google::protobuf|octomap::' \
    $(for h in $headers; do echo "$work/sdk/include/$h"; done); then
  die "an installed SDK header names DDS, TBB, protobuf, OctoMap or the map's internals"
fi
for h in $headers; do echo "#include \"$h\""; done >"$work/sdk_headers.cpp"
eigen=$(pkg-config --cflags eigen3 2>/dev/null || echo -I/usr/include/eigen3)
# shellcheck disable=SC2086
c++ -std=c++23 -M -I"$work/sdk/include" $eigen "$work/sdk_headers.cpp" >"$work/sdk_headers.d" ||
  die "the SDK's headers do not compile on their own"
if grep -E '/(dds|ddsrt|ddsi|tbb|oneapi|google/protobuf|octomap)/' "$work/sdk_headers.d"; then
  die "an SDK header pulls in Cyclone DDS, TBB, protobuf or OctoMap"
fi
say "SDK headers: $(echo "$headers" | wc -l) files, none reaching DDS, TBB, protobuf or OctoMap"

# Run it against a server on loopback (its own domain and snapshot file).
run_example() {
  local server=$1 example=$2 domain=$3
  mkdir -p "$work/run"
  sed -e "s|path: \"densemap.dmap\"|path: \"$work/run/map.dmap\"|" config/densemap.textproto \
    >"$work/run/config.textproto"
  "$server" --config "$work/run/config.textproto" --domain-id "$domain" 2>"$work/run/server.log" &
  local pid=$!
  local rc=0
  timeout 60 "$example" "$domain" >"$work/run/example.txt" 2>&1 || rc=$?
  kill -TERM "$pid" 2>/dev/null || true
  wait "$pid" || true
  cat "$work/run/example.txt"
  [ "$rc" -eq 0 ] || { cat "$work/run/server.log" >&2; die "the example client failed (exit $rc)"; }
  grep -q "on the wall: occupied" "$work/run/example.txt" || die "the example saw no wall"
  grep -q "in front of it: free" "$work/run/example.txt" || die "the example saw no free space"
}
run_example "$BIN/densemap-server" "$work/example/wall_scan" 171

# --- 3. The packages installed (root) or unpacked ---------------------------------------------
if [ "$(id -u)" -eq 0 ] && [ "${DENSEMAP_SKIP_DPKG_INSTALL:-0}" != 1 ]; then
  if dpkg-query -W densemap-server >/dev/null 2>&1; then
    die "densemap-server is already installed on this machine; not touching it"
  fi
  installed=1
  dpkg -i "$server_deb" "$dev_deb" "$python_deb" >"$work/dpkg.log" 2>&1 || { cat "$work/dpkg.log" >&2; die "dpkg -i"; }
  # Debian's python3 imports the installed module from anywhere, with nothing else on its path.
  (cd / && env -u PYTHONPATH /usr/bin/python3 -c '
import densemap, numpy as np
m = densemap.Mapper(resolution=0.1, max_range=10.0)
m.insert_point_cloud(np.array([[4.0, 0.0, 0.0]], np.float32), [0, 0, 0])
assert m.states([[4.0, 0, 0], [2, 0, 0]]).tolist() == [densemap.OCCUPIED, densemap.FREE]
assert densemap.__file__.startswith("/usr/lib/python3/dist-packages/")
print(densemap.__version__)') >"$work/python-import.txt" 2>&1 ||
    { cat "$work/python-import.txt" >&2; die "the installed python3-densemap does not import and map"; }
  /usr/bin/densemap-server --check-config /etc/densemap/densemap.textproto ||
    die "the packaged config does not pass --check-config"
  [ "$(stat -c %U /var/lib/densemap)" = densemap ] || die "/var/lib/densemap is not owned by densemap"
  if command -v systemd-analyze >/dev/null 2>&1; then
    systemd-analyze verify /lib/systemd/system/densemap-server.service ||
      die "systemd-analyze verify rejects the unit"
  fi
  cmake -S client/examples/wall_scan -B "$work/example-usr" >"$work/example-usr.log" 2>&1 &&
    cmake --build "$work/example-usr" >>"$work/example-usr.log" 2>&1 ||
    { cat "$work/example-usr.log" >&2; die "example against the installed libdensemap-dev"; }
  run_example /usr/bin/densemap-server "$work/example-usr/wall_scan" 172 >/dev/null
  build_mapper_example "$work/mapper-example-usr" ""
  say "dpkg -i ok: --check-config passes, the examples build against /usr, one talks to /usr/bin/densemap-server; /usr/bin/python3 imports densemap $(cat "$work/python-import.txt")"
  dpkg --purge densemap-server libdensemap-dev python3-densemap >/dev/null
  installed=0
  [ ! -e /usr/bin/densemap-server ] || die "dpkg --purge left /usr/bin/densemap-server"
else
  dpkg-deb -x "$server_deb" "$work/root"
  sed -e "s|/var/lib/densemap|$work/root/var/lib/densemap|" -e "s|/usr/share/densemap|$work/root/usr/share/densemap|" \
    "$work/root/etc/densemap/densemap.textproto" >"$work/root/check.textproto"
  "$work/root/usr/bin/densemap-server" --check-config "$work/root/check.textproto" ||
    die "the packaged config does not pass --check-config"
  dpkg-deb -x "$python_deb" "$work/root"
  (cd / && PYTHONPATH="$work/root/usr/lib/python3/dist-packages" /usr/bin/python3 -c 'import densemap') ||
    die "the unpacked python3-densemap does not import"
  say "not root: the packages were unpacked (dpkg-deb -x), the config checked and the module imported there"
fi
say "all ok"
