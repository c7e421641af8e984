#!/usr/bin/env bash
# The long suite: everything scripts/test.sh runs plus the tests marked `long` (every regression
# scene, the slow scene-compiling tests). Arguments are passed to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
SOFAC_LONG=1 exec bash scripts/test.sh "$@"
