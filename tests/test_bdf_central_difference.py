"""BDFOdeSolver and CentralDifferenceSolver in compiled scenes: a mass on a spring from a fixed point
(no gravity: along the spring the force is exactly -k (x - L)) against the closed forms of SOFA's
steps (see tests/test_solvers.py for the algorithms on their own), the configurations refused, and
scenes of SOFA's tree that run."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.check import checker
from sofac.pipeline import compile_scene
from sofac.plan.planner import plan_scene

TREE = Path(os.environ.get("SOFAC_SOFA_TREE", "/work/sofa-tree"))
M, K, L, A, DT = 0.5, 50.0, 1.0, 0.2, 0.01
STEPS = 60

NODE = """\
  <Node name="{name}">
    {solver}
    <MechanicalObject template="Vec3d" name="dofs" position="0 0 0  {x0!r} 0 0"/>
    <UniformMass vertexMass="{m!r}"/>
    <FixedProjectiveConstraint indices="0"/>
    <SpringForceField spring="0 1 {k!r} 0 {length!r}"/>
  </Node>
"""
BDF = '<BDFOdeSolver order="{order}"/><NewtonRaphsonSolver/><SparseLDLSolver/>'
VARIANTS = {
    "bdf1": BDF.format(order=1),
    "bdf2": BDF.format(order=2),
    "bdf3_cg": '<BDFOdeSolver order="3"/><NewtonRaphsonSolver/>'
    '<CGLinearSolver iterations="50" tolerance="1e-15" threshold="1e-40"/>',
    "central": "<CentralDifferenceSolver/>",
    "central_damped": '<CentralDifferenceSolver rayleighMass="0.6"/>',
}


@pytest.fixture(scope="module")
def history(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    """x - L and v of the moving point after each step, per variant (one scene)."""
    nodes = "".join(NODE.format(name=n, solver=s, x0=L + A, m=M, k=K, length=L) for n, s in VARIANTS.items())
    path = tmp_path_factory.mktemp("integrators") / "integrators.scn"
    path.write_text(
        f'<Node name="root" gravity="0 0 0" dt="{DT!r}"><DefaultAnimationLoop/>\n{nodes}</Node>\n'
    )
    sim = sofac.load(path)
    rows: dict[str, list[tuple[float, float]]] = {n: [(A, 0.0)] for n in VARIANTS}
    for _ in range(STEPS):
        sim.step(1)
        for n in VARIANTS:
            x, v = sim[f"{n}/dofs"].position, sim[f"{n}/dofs"].velocity
            assert x[0].tolist() == [0.0, 0.0, 0.0] and x[1, 1:].tolist() == [0.0, 0.0]
            rows[n].append((x[1, 0] - L, v[1, 0]))
    return {n: np.array(r) for n, r in rows.items()}


def bdf_reference(order: int) -> np.ndarray:
    """SOFA's BDF steps in closed form (the order grows 1, 2, ... at the start): with the state's own
    x_n, v_n in every slot below k, r1 = 0 and r2 = 0 give x_k = -s x_n + hb v_k and
    m (v_k + s v_n) = -hb k x_k, s = sum_j<k a_j / a_k, hb = h / a_k (a from uneven times: exact)."""
    b_of = {1: 1.0, 2: 2 / 3, 3: 6 / 11}
    x, v, rows = A, 0.0, [(A, 0.0)]
    for step in range(STEPS):
        hb = DT * b_of[min(order, step + 1)]
        v = (M * v - hb * K * x) / (M + hb * hb * K)  # s = -1
        x = x + hb * v
        rows.append((x, v))
    return np.array(rows)


@pytest.mark.parametrize(("name", "order"), [("bdf1", 1), ("bdf2", 2), ("bdf3_cg", 3)])
def test_bdf_on_the_spring(history: dict[str, np.ndarray], name: str, order: int) -> None:
    """One Newton iteration is exact on a linear spring (direct solver; a converged CG)."""
    assert history[name] == pytest.approx(bdf_reference(order), rel=1e-8, abs=1e-12)


@pytest.mark.parametrize(("name", "r"), [("central", 0.0), ("central_damped", 0.6)])
def test_central_difference_on_the_spring(history: dict[str, np.ndarray], name: str, r: float) -> None:
    x, v, rows = A, 0.0, [(A, 0.0)]
    for _ in range(STEPS):
        a = -K * x / M
        if r == 0.0:
            v = v + DT * a
        else:
            v = v + (-1.0 + (1 / DT - r / 2) / (1 / DT + r / 2)) * v
            v = v + 1 / (1 / DT + r / 2) * a
        x = x + DT * v
        rows.append((x, v))
    assert history[name] == pytest.approx(np.array(rows), rel=1e-12, abs=1e-15)


@pytest.mark.parametrize(
    ("solver", "extra", "why"),
    [
        ('<BDFOdeSolver order="2"/><SparseLDLSolver/>', "", "NewtonRaphsonSolver"),
        (BDF.format(order=2), '<Node name="child"><MechanicalObject/><IdentityMapping/></Node>', "mapped"),
        ("<CentralDifferenceSolver/>", '<MeshMatrixMass massDensity="1"/>', "consistent mass"),
    ],
)
def test_configurations_refused(tmp_path: Path, solver: str, extra: str, why: str) -> None:
    path = tmp_path / "refused.scn"
    text = NODE.format(name="n", solver=solver, x0=L + A, m=M, k=K, length=L).replace(
        "  </Node>", f"    <EdgeSetTopologyContainer edges='0 1'/>{extra}\n  </Node>"
    )
    if "MeshMatrixMass" in extra:
        text = text.replace(f'<UniformMass vertexMass="{M!r}"/>', "")
    path.write_text(f'<Node name="root" gravity="0 0 0"><DefaultAnimationLoop/>\n{text}</Node>\n')
    checked, diags = checker.check_file(path)
    assert diags.errors == []
    with pytest.raises(sofac.SceneError) as error:
        plan_scene(checked)
    assert [d.code for d in error.value.diagnostics] == ["E222"]
    assert why in error.value.diagnostics[0].message


@pytest.mark.skipif(not TREE.is_dir(), reason="SOFA's examples tree is not extracted")
def test_tree_bdf_springs_run() -> None:
    """BDFOdeSolver_spring1d.scn: three 1-D springs (orders 1, 2, 3) falling to x = -g m / k under
    Rayleigh damping and each scheme's own numerical damping; after 300 steps (3 s) they are finite,
    near -0.0981, the higher orders (a shorter effective step) less damped."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = compile_scene(
            TREE / "examples/Component/ODESolver/Backward/BDFOdeSolver_spring1d.scn"
        ).instantiate()
    sim.step(300)
    spread = {}
    for order in (1, 2, 3):
        x = sim[f"BDF-{order}/dofs"].position[0, 0]
        assert np.isfinite(x) and abs(x + 0.0981) < 0.5
        spread[order] = abs(x + 0.0981)
    assert spread[1] < 0.02
