#!/usr/bin/env bash
# Builds deploy/container/Containerfile with podman (or docker) and runs it: --version, then a simulated dive
# corrected inside the container, every photo written. Skips (exit 0, with the reason) where neither engine is
# installed and working, or where the base images cannot be pulled. Takes minutes (a whole cargo build); not
# part of .ci/run.
set -euo pipefail
cd "$(dirname "$0")/../.."
say() { echo "container test: $*"; }
fail() { echo "container test: FAILED: $*" >&2; exit 1; }

engine=
for e in podman docker; do
    if command -v "$e" >/dev/null && "$e" info >/dev/null 2>&1; then engine=$e; break; fi
done
if [[ -z $engine ]]; then
    say "skipped: neither podman nor docker is installed and working here (docker's daemon not running?)"
    exit 0
fi
# The base images the Containerfile names (pinned by digest where it pins them).
for base in $(awk 'toupper($1) == "FROM" { print $2 }' deploy/container/Containerfile); do
    if ! "$engine" pull -q "$base" >/dev/null 2>&1; then
        say "skipped: $engine cannot pull $base (no registry access)"
        exit 0
    fi
done
tag=abysslight-test:$$
tmp=$(mktemp -d)
trap '"$engine" rmi -f "$tag" >/dev/null 2>&1 || true; rm -rf "$tmp"' EXIT
t=$SECONDS
"$engine" build -q -f deploy/container/Containerfile -t "$tag" . >/dev/null || fail "$engine build failed"
say "built in $((SECONDS - t)) s: $("$engine" image inspect -f '{{.Size}}' "$tag") bytes"
"$engine" run --rm "$tag" --version | grep -q '^abysslight ' || fail "--version"
chmod 777 "$tmp"
"$engine" run --rm -v "$tmp:/data" -w /data "$tag" simulate --out sim --frames 12 --water-column 6 ||
    fail "simulate in the container"
"$engine" run --rm -v "$tmp:/data" -w /data "$tag" correct --water-column sim/water --survey sim/survey \
    --out out --quiet || fail "correct in the container"
n=$(find "$tmp/out" -path "$tmp/out/_abysslight" -prune -o -type f -print | wc -l)
((n == 12)) || fail "$n photos corrected in the container, 12 expected"
[[ -f $tmp/out/_abysslight/report.json ]] || fail "no report"
if command -v apptainer >/dev/null; then
    "$engine" save --format docker-archive -o "$tmp/abysslight.tar" "$tag" 2>/dev/null ||
        "$engine" save -o "$tmp/abysslight.tar" "$tag"
    (cd "$tmp" && apptainer build -F abysslight.sif "$OLDPWD/deploy/container/abysslight.def") ||
        fail "apptainer build"
    apptainer exec "$tmp/abysslight.sif" abysslight --version || fail "apptainer exec"
    say "apptainer image built and run"
else
    say "apptainer not installed: the .def was not built"
fi
echo "container: 1 passed, 0 failed"
