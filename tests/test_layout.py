"""Facts shared by the planner and the C++ runtime are stated once, in the runtime's headers, and
checked here: the planner's copies (block size, per-element data sizes, FEM method codes,
constraint resolutions) must be
what the headers say, so a change on one side cannot silently desynchronise the other."""

from __future__ import annotations

import subprocess
from pathlib import Path

from sofac.build import compiler as build
from sofac.plan.ir import FemMethod, Resolution
from sofac.plan.lower.beams import BEAM_FRAME_SIZE, BEAM_STIFFNESS_SIZE
from sofac.plan.lower.common import TETRA_LANES
from sofac.plan.lower.fem import (
    DATA_SIZE_FUNCTIONS,
    FAST_TETRA_DATA,
    FAST_TETRA_METHODS,
    FEM_KINDS,
    QUAD_BENDING_DATA,
    TRIANGLE_FEM_DATA,
)

REPO = Path(__file__).resolve().parents[1]


def _runtime_values(tmp_path: Path, expressions: list[str]) -> list[int]:
    body = "\n".join(f'    std::printf("%d\\n", int({e}));' for e in expressions)
    source = (
        '#include <cstdio>\n#include "sofac/fem.h"\n#include "sofac/shell.h"\n'
        '#include "sofac/quad_bending.h"\n#include "sofac/beam.h"\n#include "sofac/constraints.h"\n'
        '#include "sofac/hexahedral_fem.h"\n#include "sofac/fast_tetra_fem.h"\n'
        f"int main() {{\n{body}\n}}\n"
    )
    (tmp_path / "layout.cpp").write_text(source)
    binary = tmp_path / "layout"
    includes = ["-I", str(REPO / "runtime"), "-isystem", str(build.eigen_include())]
    compile_ = [
        build.compiler(),
        "-std=c++17",
        "-Wall",
        "-Wextra",
        "-Werror",
        *includes,
        str(tmp_path / "layout.cpp"),
    ]
    subprocess.run([*compile_, "-o", str(binary)], check=True, capture_output=True, text=True)
    out = subprocess.run([str(binary)], check=True, capture_output=True, text=True).stdout
    return [int(line) for line in out.split()]


def test_planner_layout_matches_the_runtime(tmp_path: Path) -> None:
    expressions = ["sofac::TETRA_LANES", "sofac::QUAD_BENDING_DATA"]
    expressions += ["sofac::BEAM_STIFFNESS_SIZE", "sofac::BEAM_FRAME_SIZE"]
    expected = [TETRA_LANES, QUAD_BENDING_DATA, BEAM_STIFFNESS_SIZE, BEAM_FRAME_SIZE]
    expressions += ["sofac::triangle_fem_data_size()", "sofac::fast_tetra_fem_data_size()"]
    expected += [TRIANGLE_FEM_DATA, FAST_TETRA_DATA]
    runtime_methods = {"polar": "POLAR", "qr": "QR", "polar2": "POLAR2", "none": "LINEAR"}
    for name, enumerator in runtime_methods.items():
        expressions.append(f"sofac::FAST_TETRA_{enumerator}")
        expected.append(FAST_TETRA_METHODS[name])
    for method in FemMethod:
        expressions.append(f"sofac::FEM_{method.name}")
        expected.append(int(method))
    for resolution in Resolution:
        enumerator = resolution.name.title().replace("_", "")  # BILATERAL_3 -> Bilateral3
        expressions.append(f"sofac::Resolution::{enumerator}")
        expected.append(int(resolution))
    for prefix, (_, _, _, sizes) in FEM_KINDS.items():
        for method, size in sizes.items():
            expressions.append(f"sofac::{DATA_SIZE_FUNCTIONS[prefix]}({method})")
            expected.append(size)
    assert _runtime_values(tmp_path, expressions) == expected
