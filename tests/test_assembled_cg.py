"""CGLinearSolver on an assembled matrix (templates other than GraphScattered).

SOFA then assembles A = mfact M + kfact K once per solve, clears the rows and columns of the
projected DOFs (diagonal 1), and runs its CG on global vectors with a sparse matrix-vector product.
sofac does the same (runtime/sofac/assembly.h: AssembledCg, rows of 3x3 blocks or scalar rows).
Checked here: the runtime's product is SOFA's CompressedRowSparseMatrix product to the bit (each
row summed over increasing columns), identical for both block sizes; CG capped at 25 iterations on
the assembled matrix follows the matrix-free CG to round-off, and so do the static, Newmark and
variational solvers' solves; a scene whose states are not in
threes runs on scalar rows; and an assembled CG with forces on mapped states is refused (E222)."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
import sofac
from kernel_shim import build_shim, doubles, indices

SHIM = r"""
#include <algorithm>
#include "sofac/assembly.h"

using sofac::Index;

// Assembles the 3x3 blocks (rows[k], cols[k]) with add_block3 and the diagonal with add, projects
// the fixed DOFs, then y = A x and CG on A solution = b (`iterations`, tolerance 0).
template <int B>
void run(const Index* rows, const Index* cols, const double* blocks, Index count, const double* diagonal,
         Index n, const Index* fixed, Index fixed_count, const double* x, double* y, const double* b,
         double* solution, Index iterations, Index* pattern_size) {
    sofac::AssembledCg<B> cg;
    cg.resize(n);
    for (int pass = 0; pass < 2; ++pass) {
        if (pass == 0) cg.assembler.start_pattern();
        else cg.assembler.start_values(cg.matrix);
        for (Index k = 0; k < count; ++k)
            cg.assembler.add_block3(3 * rows[k], 3 * cols[k], blocks + 9 * k, 3, -2.0);
        for (Index i = 0; i < n; ++i) cg.assembler.add(i, i, diagonal[i]);
        if (pass == 0) {
            cg.assembler.finish_pattern(cg.matrix, n);
            for (Index k = 0; k < fixed_count; ++k) cg.fixed[fixed[k]] = 1;
            cg.find_projected();
        }
    }
    cg.project();
    cg.matrix.multiply(x, y);
    std::copy(b, b + n, cg.rhs.begin());
    cg.solve(iterations, 0.0, 0.0, false);
    std::copy(cg.solution.begin(), cg.solution.end(), solution);
    *pattern_size = static_cast<Index>(cg.matrix.values.size());
}

#define API extern "C" __attribute__((visibility("default")))

API void run1(const Index* r, const Index* c, const double* v, Index m, const double* d, Index n,
              const Index* f, Index nf, const double* x, double* y, const double* b, double* s, Index it,
              Index* p) {
    run<1>(r, c, v, m, d, n, f, nf, x, y, b, s, it, p);
}
API void run3(const Index* r, const Index* c, const double* v, Index m, const double* d, Index n,
              const Index* f, Index nf, const double* x, double* y, const double* b, double* s, Index it,
              Index* p) {
    run<3>(r, c, v, m, d, n, f, nf, x, y, b, s, it, p);
}
"""


@pytest.fixture(scope="module")
def shim(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    return build_shim(tmp_path_factory, "assembled_cg", SHIM)


def test_product_is_sofas_row_order_for_both_block_sizes(shim: ctypes.CDLL) -> None:
    rng = np.random.default_rng(3)
    nodes = 9
    n = 3 * nodes
    pairs = [(i, i) for i in range(nodes)] + [(i, (i + 2) % nodes) for i in range(nodes)]
    pairs += [(j, i) for i, j in pairs if i != j] + [(4, 7), (4, 7)]  # a repeated block adds up
    rows = np.array([p[0] for p in pairs], dtype=np.int64)
    cols = np.array([p[1] for p in pairs], dtype=np.int64)
    blocks = rng.standard_normal((len(pairs), 3, 3)) * 0.1
    blocks = np.ascontiguousarray(blocks)
    diagonal = 10.0 + rng.random(n)
    fixed = np.array([0, 1, 2, 13], dtype=np.int64)
    x = rng.standard_normal(n)
    b = rng.standard_normal(n)
    b[fixed] = 0.0  # a projected right-hand side, as the ODE solver passes it
    results = {}
    for name in ("run1", "run3"):
        y, solution, size = np.zeros(n), np.zeros(n), np.zeros(1, dtype=np.int64)
        getattr(shim, name)(
            indices(rows), indices(cols), doubles(blocks), ctypes.c_int64(len(pairs)), doubles(diagonal),
            ctypes.c_int64(n), indices(fixed), ctypes.c_int64(fixed.size), doubles(x), doubles(y), doubles(b),
            doubles(solution), ctypes.c_int64(200), indices(size),
        )  # fmt: skip
        results[name] = (y, solution, int(size[0]))
    # The matrix as SOFA's MatrixLinearSystem leaves it: entries summed in the order added, the
    # projected rows and columns cleared, their diagonal 1.
    dense = np.zeros((n, n))
    for (i, j), block in zip(pairs, blocks, strict=True):
        for a in range(3):
            for c in range(3):
                dense[3 * i + a, 3 * j + c] += -2.0 * block[a, c]
    dense[np.diag_indices(n)] += diagonal
    dense[fixed, :] = 0.0
    dense[:, fixed] = 0.0
    dense[fixed, fixed] = 1.0
    expected = np.zeros(n)
    for i in range(n):  # one product at a time, increasing columns, from 0: CompressedRowSparseMatrix::tmul
        total = 0.0
        for j in range(n):
            if pairs_touch(pairs, i // 3, j // 3):
                total += float(dense[i, j]) * float(x[j])
        expected[i] = total
    y1, s1, size1 = results["run1"]
    y3, s3, size3 = results["run3"]
    assert np.array_equal(y1, expected) and np.array_equal(y3, expected)
    assert np.array_equal(s1, s3)  # the same CG, to the bit, on both layouts
    assert size1 == size3 == 9 * len(set(pairs))  # the blocks touched (the diagonal ones included)
    assert np.abs(dense @ s1 - b).max() < 1e-12 * np.abs(b).max()


def pairs_touch(pairs: list[tuple[int, int]], i: int, j: int) -> bool:
    return (i, j) in pairs


BEAM = """<Node name="root" gravity="0 -9.81 0" dt="0.02"><DefaultAnimationLoop/>
<Node name="beam"><EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>{solver}
<RegularGridTopology n="4 4 12" min="0 0 0" max="1 1 3"/>
<MechanicalObject name="dofs"/><UniformMass totalMass="1"/>
<BoxROI name="box" box="-1 -1 -0.001 2 2 0.001"/><FixedProjectiveConstraint indices="@box.indices"/>
<TetrahedronFEMForceField youngModulus="1e4" poissonRatio="0.3" method="large"/></Node></Node>"""

CAPPED = 'iterations="25" tolerance="0" threshold="0"'


def run(tmp_path: Path, name: str, text: str, steps: int, state: str) -> list[np.ndarray]:
    """The displacements of ``state`` after each step."""
    path = tmp_path / f"{name}.scn"
    path.write_text(text)
    sim = sofac.load(path)
    start = sim[state].position.copy()
    moved = []
    for _ in range(steps):
        sim.step(1)
        moved.append(sim[state].position - start)
    return moved


def test_capped_cg_on_the_assembled_matrix_follows_the_matrix_free_one(tmp_path: Path) -> None:
    """25 iterations, no early stop (SOFA's W3 setting): the same iterates computed in another
    order, so the displacements agree to round-off. A truncated CG amplifies round-off from step to
    step (as on W2/W3, benchmarks/README.md): measured 4e-13 of the largest displacement after one
    step, 2e-12 after 10 (and 6e-11 after 20) on this 576-DOF beam."""
    templates = ("GraphScattered", "CompressedRowSparseMatrixd", "CompressedRowSparseMatrixMat3x3d")
    solver = '<CGLinearSolver template="{}" ' + CAPPED + "/>"
    moved = {t: run(tmp_path, t, BEAM.format(solver=solver.format(t)), 10, "beam/dofs") for t in templates}
    free = moved["GraphScattered"]
    scale = np.abs(free[-1]).max()
    assert scale > 0.01  # the beam sags
    for template in templates[1:]:
        assert np.abs(moved[template][0] - free[0]).max() < 2e-12 * np.abs(free[0]).max(), template
        assert np.abs(moved[template][-1] - free[-1]).max() < 1e-11 * scale, template
    for first, second in zip(moved[templates[1]], moved[templates[2]], strict=True):
        assert np.array_equal(first, second)  # scalar and 3x3-block rows: the same numbers


SMALL_BEAM = """<Node name="root" gravity="0 -9.81 0" dt="0.02"><DefaultAnimationLoop/>
<Node name="beam">{ode}{solver}
<RegularGridTopology n="3 3 6" min="0 0 0" max="1 1 3"/>
<MechanicalObject name="dofs"/><UniformMass totalMass="1"/>
<BoxROI name="box" box="-1 -1 -0.001 2 2 0.001"/><FixedProjectiveConstraint indices="@box.indices"/>
<TetrahedronFEMForceField youngModulus="1e4" poissonRatio="0.3" method="large"/></Node></Node>"""


@pytest.mark.parametrize(
    "ode",
    [
        '<StaticSolver newton_iterations="3"/>',
        '<NewmarkImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>',
        '<VariationalSymplecticSolver steps="3" newtonError="0"/>',
    ],
)
def test_other_odes_solve_on_the_assembled_matrix(tmp_path: Path, ode: str) -> None:
    """The static, Newmark and variational solvers assemble the system with their own factors
    (measured: 2e-14 to 9e-14 of the largest displacement from the matrix-free CG, both converged)."""
    tight = 'iterations="3000" tolerance="1e-15" threshold="1e-40"'
    moved = []
    for template in ("GraphScattered", "CompressedRowSparseMatrixMat3x3d"):
        text = SMALL_BEAM.format(ode=ode, solver=f'<CGLinearSolver template="{template}" {tight}/>')
        moved.append(run(tmp_path, template, text, 5, "beam/dofs")[-1])
    scale = np.abs(moved[0]).max()
    assert scale > 0.01
    assert np.abs(moved[1] - moved[0]).max() < 1e-12 * scale


CHAIN = """<Node name="root" gravity="0 -9.81 0" dt="0.01"><DefaultAnimationLoop/>
<Node name="chain"><EulerImplicitSolver rayleighStiffness="0.05" rayleighMass="0.1"/>{solver}
<MechanicalObject template="Vec2d" name="dofs" position="0 0  1 0  2 0  3 0  4 0"/>
<UniformMass vertexMass="0.2"/><FixedProjectiveConstraint indices="0"/>
<SpringForceField spring="0 1 500 2 1  1 2 500 2 1  2 3 500 2 1  3 4 500 2 1  0 2 50 0 2"/></Node></Node>"""


def test_states_not_in_threes_run_on_scalar_rows(tmp_path: Path) -> None:
    """Vec2d springs: the assembled CG (scalar rows) against the matrix-free one, both converged."""
    tight = 'iterations="200" tolerance="1e-15" threshold="1e-40"'
    free = run(tmp_path, "free", CHAIN.format(solver=f"<CGLinearSolver {tight}/>"), 30, "chain/dofs")[-1]
    text = CHAIN.format(solver=f'<CGLinearSolver template="CompressedRowSparseMatrixd" {tight}/>')
    assembled = run(tmp_path, "assembled", text, 30, "chain/dofs")[-1]
    source = sofac.load(tmp_path / "assembled.scn").compiled.source  # cached
    assert "sofac::AssembledCg<1>" in source
    assert np.abs(free).max() > 0.1
    assert np.abs(assembled - free).max() < 1e-12 * np.abs(free).max()


MAPPED = """<Node name="root" gravity="0 -9.81 0" dt="0.01"><DefaultAnimationLoop/>
<Node name="body"><EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>{solver}
<MechanicalObject template="Rigid3d" name="frame" position="0 0 0 0 0 0 1" velocity="0 0 0 1 2 3"/>
<UniformMass vertexMass="1"/>
<Node name="skin"><MechanicalObject name="points" position="1 0 0  0 1 0  0 0 1  1 1 1"/>
<RigidMapping globalToLocalCoords="false"/><UniformMass vertexMass="0.5"/>
<RestShapeSpringsForceField stiffness="100"/>
<SpringForceField spring="0 1 50 0.5 1.4142  1 2 50 0.5 1.4142  2 3 50 0.5 1.4142"/></Node></Node></Node>"""


def test_forces_on_mapped_states_are_assembled_through_the_mapping(tmp_path: Path) -> None:
    """Masses, rest-shape springs and springs on points rigidly mapped from a frame: the assembled
    CG gets them as J^T K J (the mapping's J refilled from the frame's rotation each step) and
    agrees with the matrix-free CG, where they act through J and J^T, both converged tightly."""
    tight = 'iterations="500" tolerance="1e-15" threshold="1e-40"'
    moved = []
    for template in ("GraphScattered", "CompressedRowSparseMatrixMat3x3d"):
        text = MAPPED.format(solver=f'<CGLinearSolver template="{template}" {tight}/>')
        moved.append(run(tmp_path, template, text, 20, "body/frame")[-1])
    scale = np.abs(moved[0]).max()
    assert scale > 0.01 and np.abs(moved[0][0, 3:6]).max() > 0.05  # the frame falls and turns
    assert np.abs(moved[1] - moved[0]).max() < 1e-11 * scale
