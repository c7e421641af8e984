#!/usr/bin/env bash
# The main job on a bundled scene: install what is missing, check the hybrid pendulum, then
# compile it (cached after the first time) and run 1 s of it, printing where its bodies are and
# the compile and step times; last, draw it after that second, off-screen, into
# out/hybrid_pendulum.png. Then the other bundled scenes run for a few steps each (a line each):
# the liver (scenes/liver.scn, corotational tetrahedra and a visual surface), the cantilever beam
# (scenes/beam.scn, corotational hexahedra) and the cloth (scenes/cloth.scn, springs).
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/setup.sh
# shellcheck source=scripts/python.sh
source scripts/python.sh
"$PYTHON" -m sofac check scenes/hybrid_pendulum.scn
"$PYTHON" -m sofac run scenes/hybrid_pendulum.scn --steps 100 --mapped
"$PYTHON" -m sofac render scenes/hybrid_pendulum.scn --steps 100 --grid --out out/hybrid_pendulum.png
for scene in scenes/liver.scn scenes/beam.scn scenes/cloth.scn; do
    printf '%s: ' "$scene"
    "$PYTHON" -m sofac run "$scene" --steps 20
done
