"""DistanceMultiMapping between two states, UniformVelocityDampingForceField (explicit force, implicit
B term), TransformEngine evaluated at compile time."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sofac
from sofac.check.evaluate import UnknownInput, transform_engine

DAMPED = """<Node name="root" dt="{h}" gravity="0 0 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
  <CGLinearSolver iterations="50" tolerance="1e-30" threshold="1e-30"/>
  <MechanicalObject name="dofs" position="0 0 0" velocity="1 -2 0.5"/>
  <UniformMass totalMass="{m}"/>
  <UniformVelocityDampingForceField dampingCoefficient="{c}" implicit="{implicit}"/>
</Node>
"""


@pytest.mark.parametrize("implicit", [True, False])
def test_velocity_damping_by_hand(tmp_path: Path, implicit: bool) -> None:
    """Implicit Euler on m dv = -c (v + dv) h (implicit B term) or -c v h (explicit force only)."""
    h, m, c = 0.1, 2.0, 3.0
    scene = tmp_path / f"damped_{implicit}.scn"
    scene.write_text(DAMPED.format(h=h, m=m, c=c, implicit=str(implicit).lower()))
    sim = sofac.load(scene)
    sim.step(3)
    factor = m / (m + h * c) if implicit else 1 - h * c / m
    expected = np.array([1.0, -2.0, 0.5]) * factor**3
    assert np.abs(np.asarray(sim["/dofs"].velocity)[0] - expected).max() < 1e-14


PAIR = """<Node name="root" dt="0.01" gravity="0 0 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
  <CGLinearSolver iterations="100" tolerance="1e-30" threshold="1e-30"/>
  <Node name="left">
    <MechanicalObject name="a" position="0 0 0  1 0 0" velocity="0 0 0  -1 0.5 0"/>
    <UniformMass totalMass="2"/>
  </Node>
  <Node name="right">
    <TransformEngine name="shift" input_position="0 0 0  1 1 0" translation="3 0 0"/>
    <MechanicalObject name="b" position="@shift.output_position"/>
    <UniformMass totalMass="2"/>
  </Node>
  <Node name="link">
    <MechanicalObject template="Vec1" name="d"/>
    <EdgeSetTopologyContainer name="edges" edges="0 1"/>
    <DistanceMultiMapping template="Vec3,Vec1" topology="@edges" input="@../left @../right" output="@d"
        indexPairs="0 1  1 1" geometricStiffness="0" applyRestPosition="true"/>
    <RestShapeSpringsForceField template="Vec1" stiffness="50"/>
  </Node>
</Node>
"""


def test_multi_mapping_joins_two_states(tmp_path: Path) -> None:
    """Point 1 of a (1, 0, 0) and point 1 of b (4, 1, 0) (TransformEngine's shift): the child holds
    their distance minus the rest length (the initial distance); the mapped spring pulls them back,
    conserving momentum."""
    scene = tmp_path / "pair.scn"
    scene.write_text(PAIR)
    sim = sofac.load(scene)
    assert np.asarray(sim["/right/b"].position).tolist() == [[3.0, 0.0, 0.0], [4.0, 1.0, 0.0]]
    assert np.asarray(sim["/link/d"].position).tolist() == [[0.0]]
    sim.step(20)
    a, b = np.asarray(sim["/left/a"].position), np.asarray(sim["/right/b"].position)
    distance = np.linalg.norm(b[1] - a[1])
    assert abs(float(np.asarray(sim["/link/d"].position)[0, 0]) - (distance - np.sqrt(10.0))) < 1e-14
    assert distance - np.sqrt(10.0) > 1e-3  # point 1 of a moved away along -x
    momentum = np.asarray(sim["/left/a"].velocity).sum(axis=0) + np.asarray(sim["/right/b"].velocity).sum(
        axis=0
    )
    assert np.abs(momentum - [-1.0, 0.5, 0.0]).max() < 1e-12
    assert np.asarray(sim["/right/b"].velocity)[1, 0] < 0  # pulled toward a
    assert (
        not np.asarray(sim["/left/a"].velocity)[0].any() and not np.asarray(sim["/right/b"].velocity)[0].any()
    )


class _Ctx:
    def __init__(self, **values: Any) -> None:
        self.values = {"scale": [1, 1, 1], "translation": [0, 0, 0], "rotation": [0, 0, 0]}
        self.values.update({"quaternion": [0, 0, 0, 1], "inverse": False, **values})

    def value(self, name: str) -> Any:
        return self.values.get(name)


def test_transform_engine_order() -> None:
    """Scale then translate; the inverse undoes them in the opposite order; rotations are refused."""
    points = [1.0, 2.0, 3.0, -1.0, 0.5, 4.0]
    out = transform_engine(_Ctx(input_position=points, scale=[2, 3, 4], translation=[1, 1, 1]))  # type: ignore[arg-type]
    assert out["output_position"].tolist() == [3.0, 7.0, 13.0, -1.0, 2.5, 17.0]
    back = transform_engine(  # type: ignore[arg-type]
        _Ctx(input_position=out["output_position"], scale=[2, 3, 4], translation=[1, 1, 1], inverse=True)
    )
    assert np.abs(back["output_position"] - points).max() < 1e-15
    with pytest.raises(UnknownInput):
        transform_engine(_Ctx(input_position=points, rotation=[0, 90, 0]))  # type: ignore[arg-type]
