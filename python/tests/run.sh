#!/usr/bin/env bash
# The Python package's tests: build the wheel as `pip install ./python` does (maturin, release profile), check that
# it is one abi3 wheel, install that file into a fresh venv with no Rust toolchain on PATH (as a user of a wheel
# has none), then pytest. Exits non-zero on any failure, and when pytest collected no test (its exit 5).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="${ABYSSLIGHT_TEST_VENV:-$(mktemp -d)/venv}"
dist="$(mktemp -d)"
python3 -m venv "$venv"
"$venv/bin/python" -m pip install --quiet --upgrade pip
"$venv/bin/python" -m pip install --quiet pytest numpy
start=$(date +%s)
"$venv/bin/python" -m pip wheel --quiet --no-deps --wheel-dir "$dist" "$root/python"
echo "== the wheel of ./python: $(( $(date +%s) - start )) s"
wheels=("$dist"/abysslight-*-abi3-*.whl)
if [ "${#wheels[@]}" -ne 1 ] || [ ! -f "${wheels[0]}" ]; then
    echo "expected one abi3 wheel, got: $(ls "$dist")" >&2
    exit 1
fi
# Only the venv and the system on PATH: no cargo, no rustc; and the file alone, no index, no source build.
env -i HOME="$HOME" PATH="$venv/bin:/usr/bin:/bin" "$venv/bin/python" -m pip install --quiet --no-index \
    --no-deps --only-binary=:all: "${wheels[0]}"
echo "== installed ${wheels[0]##*/} without a Rust toolchain"
cd "$here"
set +e
"$venv/bin/python" -m pytest -q -p no:cacheprovider "$here"
code=$?
set -e
if [ "$code" -eq 5 ]; then
    echo "pytest collected no test" >&2
    exit 1
fi
exit "$code"
