#!/usr/bin/env bash
# The whole test suite (what .ci/run calls): install what is missing, lint, run the tests.
# Arguments are passed to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/setup.sh
# shellcheck source=scripts/python.sh
source scripts/python.sh

status=0
echo "== ruff check ."
"$PYTHON" -m ruff check . || status=1

echo "== pytest"
pytest_status=0
# One worker per core (pytest-xdist), a test file per worker at a time: a file's module fixtures
# (compiled scenes) are built once. SOFAC_TEST_WORKERS=0 runs everything in this process.
"$PYTHON" -m pytest -q -n "${SOFAC_TEST_WORKERS:-auto}" --dist loadfile "$@" || pytest_status=$?
if ((pytest_status == 5)); then
    echo "test.sh: pytest ran no test; that counts as a failure" >&2
    status=1
elif ((pytest_status != 0)); then
    status=1
fi
exit "$status"
