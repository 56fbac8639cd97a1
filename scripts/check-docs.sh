#!/usr/bin/env bash
# The repository speaks to its users as of now: fails when README.md outgrows 12,500 bytes,
# when docs/configuration.md differs from what idl/densemap.proto prints, when a README, doc,
# source, script or schema narrates project history (stop / issue / item numbers), or when
# README or docs point at a document outside the repository.
# Usage: scripts/check-docs.sh [REPO_ROOT]   (run by CTest as docs.CurrentAndSelfContained)
set -euo pipefail
cd "${1:-$(dirname "$0")/..}"
fail=0
bytes=$(wc -c < README.md)
if [ "$bytes" -gt 12500 ]; then
  echo "check-docs: README.md has $bytes bytes (at most 12,500; detail goes to docs/)"; fail=1
fi
PY=/usr/bin/python3
[ -x "$PY" ] || PY=python3
"$PY" scripts/config-reference.py --check || fail=1
history=$(grep -rnE '\b[Ss]tops? [0-9]+\b|\b[Ii]ssues? [0-9]+|\bitems? [0-9]+ ' \
  --include='*.cpp' --include='*.hpp' --include='*.md' --include='*.sh' --include='*.proto' \
  --include='*.textproto' --include=CMakeLists.txt --include='*.cmake' --include='*.py' --include='*.idl' \
  --exclude-dir=.git --exclude-dir='build*' --exclude-dir=node_modules . || true)
if [ -n "$history" ]; then
  echo "check-docs: history belongs in commit messages, not here:"; echo "$history"; fail=1
fi
outside=$(grep -nE '\.\./shared/[A-Za-z]+\.md|DESIGN\.md' README.md docs/*.md || true)
if [ -n "$outside" ]; then
  echo "check-docs: a document outside the repository is named:"; echo "$outside"; fail=1
fi
# Every relative link in README and docs names a file that exists.
for f in README.md docs/*.md; do
  dir=$(dirname "$f")
  for target in $(grep -oE '\]\([^)#:]+(#[^)]*)?\)' "$f" | sed -E 's/^\]\(([^)#]+).*/\1/' | sort -u); do
    [ -e "$dir/$target" ] || { echo "check-docs: $f links to a missing $target"; fail=1; }
  done
done
[ "$fail" = 0 ] && echo "check-docs: README, docs and comments are current"
exit "$fail"
