#!/usr/bin/env bash
# The Python package's tests: build and install the wheel into a fresh venv as a user would (`pip install ./python`),
# then pytest. Exits non-zero on any failure, and when pytest collected no test (its exit 5).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="${ABYSSLIGHT_TEST_VENV:-$(mktemp -d)/venv}"
python3 -m venv "$venv"
"$venv/bin/python" -m pip install --quiet --upgrade pip
start=$(date +%s)
"$venv/bin/python" -m pip install --quiet "$root/python"
echo "== pip install ./python: $(( $(date +%s) - start )) s"
"$venv/bin/python" -m pip install --quiet pytest numpy
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
