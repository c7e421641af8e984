"""EdgePressureForceField: the forces SOFA's addForce applies, against their closed form, with
SOFA's lag (with a binormal, each addForce applies the forces computed from the positions of the
previous one, of init at first), the cases refused, and scenes of SOFA's tree that run."""

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
M, H = 0.5, 0.01

# Two points joined by edge (0 1); point 0 fixed; symplectic explicit Euler; no gravity.
SCENE = """\
<Node name="root" gravity="0 0 0" dt="{h!r}"><DefaultAnimationLoop/>
  <Node name="edge">
    {solver}
    <MechanicalObject name="dofs" position="0 0 0  1 0.5 0"/>
    <EdgeSetTopologyContainer name="edges" edges="0 1"/>
    <UniformMass vertexMass="{m!r}"/>
    <FixedProjectiveConstraint indices="0"/>
    <EdgePressureForceField edgeIndices="0" {load}/>
  </Node>
</Node>
"""
EXPLICIT = "<EulerExplicitSolver/>"


def _load(tmp_path: Path, load: str, solver: str = EXPLICIT) -> sofac.Simulation:
    path = tmp_path / "edge.scn"
    path.write_text(SCENE.format(h=H, m=M, load=load, solver=solver))
    return sofac.load(path)


def test_pressure_times_rest_length_half_on_each_end(tmp_path: Path) -> None:
    """pressure p: the edge pushes each end with p |x1 - x0| / 2 (rest length), constant."""
    sim = _load(tmp_path, 'pressure="0.3 -0.2 0.1"')
    length = np.sqrt(1.0 * 1.0 + 0.5 * 0.5)
    half = np.array([0.3, -0.2, 0.1]) * length / 2
    v = np.zeros(3)
    for _ in range(5):
        sim.step(1)
        v = v + H * half / M
    assert sim["dofs"].velocity[1] == pytest.approx(v, rel=1e-14)
    assert sim["dofs"].velocity[0].tolist() == [0.0, 0.0, 0.0]


def test_binormal_forces_lag_one_evaluation(tmp_path: Path) -> None:
    """binormal b, intensity p: force p L n, n = normalize(b x normalize(x1 - x0)), L the rest
    length; SOFA applies the forces it stored at the end of the previous addForce (init's at the
    first two steps), so the edge's direction is one step old."""
    sim = _load(tmp_path, 'binormal="0 0 2" p_intensity="-3"')
    x1, v1 = np.array([1.0, 0.5, 0.0]), np.zeros(3)
    rest = np.sqrt(1.25)

    def stored(point: np.ndarray) -> np.ndarray:
        t = point / np.sqrt(point @ point)
        n = np.cross([0.0, 0.0, 1.0], t)
        return n / np.sqrt(n @ n) * -3.0 * rest

    force = stored(x1)  # init
    for _ in range(30):
        sim.step(1)
        applied, force = force, stored(x1)  # addForce: apply, then store from x of this moment
        v1 = v1 + H * (applied / 2) / M
        x1 = x1 + H * v1
    assert sim["dofs"].position[1] == pytest.approx(x1, rel=1e-12)
    no_lag = np.array([1.0, 0.5, 0.0])
    w = np.zeros(3)
    for _ in range(30):
        w = w + H * (stored(no_lag) / 2) / M
        no_lag = no_lag + H * w
    assert np.abs(no_lag - x1).max() > 1e-6  # the lag shows


@pytest.mark.parametrize(
    ("load", "solver", "attribute"),
    [
        ("", EXPLICIT, None),  # SOFA's forces would be uninitialised
        ('p_intensity="1"', EXPLICIT, "p_intensity"),  # normals from a triangle topology
        ('binormal="0 0 1" p_intensity="1"', "<RungeKutta4Solver/>", "binormal"),  # x of the stages
        ('edgeIndices="0 3" pressure="1 0 0"', EXPLICIT, "edgeIndices"),
    ],
)
def test_cases_sofac_refuses(tmp_path: Path, load: str, solver: str, attribute: str | None) -> None:
    path = tmp_path / "edge.scn"
    text = SCENE.format(h=H, m=M, load=load, solver=solver)
    path.write_text(text.replace('edgeIndices="0" edgeIndices', "edgeIndices"))
    checked, diags = checker.check_file(path)
    assert diags.errors == []
    with pytest.raises(sofac.SceneError) as error:
        plan_scene(checked)
    (diagnostic,) = error.value.diagnostics
    assert diagnostic.code == ("E218" if attribute == "edgeIndices" else "E222")
    assert (diagnostic.loc.line, diagnostic.loc.attribute) == (8, attribute)


@pytest.mark.skipif(not TREE.is_dir(), reason="SOFA's examples tree is not extracted")
@pytest.mark.parametrize(
    "scene",
    [
        "Component/MechanicalLoad/EdgePressureForceField.scn",  # Triangle2Edge, pressure
        "Component/Constraint/Projective/PointProjectiveConstraint.scn",  # GridMeshCreator, binormal
    ],
)
def test_tree_scenes_run(scene: str) -> None:
    """Triangle2EdgeTopologicalMapping's border under a pressure: the net force is the weight plus
    -0.1 x the perimeter 4; the point-constrained square under a binormal pull settles."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = compile_scene(TREE / "examples" / scene).instantiate()
    state = sim[sim.objects()[0]]
    sim.step(1)
    if "MechanicalLoad" in scene:
        assert state.force.sum(axis=0) == pytest.approx([0.0, 0.0, 0.15 * 3 - 0.4], abs=1e-12)
    sim.step(299)
    assert np.isfinite(state.position).all()
    if "Point" in scene:
        assert np.abs(state.velocity).max() < 1e-3 and np.abs(state.position).max() < 2.0
