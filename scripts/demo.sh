#!/usr/bin/env bash
# The main job on a bundled scene: install what is missing, check the scene, show its tree.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/setup.sh
# shellcheck source=scripts/python.sh
source scripts/python.sh
sofac check scenes/hybrid_pendulum.scn && sofac inspect scenes/hybrid_pendulum.scn
