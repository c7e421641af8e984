"""IdentityMapping Rigid3d -> Vec3d (SOFA's core::eq / peq between a rigid coordinate and a vector):
the child is the body's centre, its velocity the linear velocity, and J^T adds a child force to the
body's force only, never a torque."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

BODY = """\
<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <DefaultAnimationLoop/>
    <Node name="body">
        <EulerImplicitSolver rayleighMass="0" rayleighStiffness="0"/>
        {solver}
        <MechanicalObject name="rigid" template="Rigid3d" position="-5 10 0 0 0 0 1"
                          velocity="1 0 0.5 0 0 2"/>
        <UniformMass totalMass="2.0"/>
{load}    </Node>
</Node>
"""
CG = '<CGLinearSolver iterations="250" tolerance="1e-20" threshold="1e-20"/>'
MAPPED_FORCE = """\
        <Node name="point">
            <MechanicalObject name="centre"/>
            <ConstantForceField forces="3 0 -1"/>
            <IdentityMapping input="@../rigid" output="@centre"/>
        </Node>
"""
DIRECT_FORCE = """\
        <ConstantForceField template="Rigid3d" forces="3 0 -1 0 0 0"/>
"""
# The child's own position: its rest position (a mapped state sized by the mapping has rest 0).
MAPPED_SPRING = """\
        <Node name="point">
            <MechanicalObject name="centre" position="-5 10 0"/>
            <RestShapeSpringsForceField stiffness="50" points="0"/>
            <IdentityMapping input="@../rigid" output="@centre"/>
        </Node>
"""


def _load(tmp_path: Path, name: str, load: str, solver: str = CG) -> sofac.Simulation:
    path = tmp_path / f"{name}.scn"
    path.write_text(BODY.format(load=load, solver=solver), encoding="utf-8")
    return sofac.load(path)


def _x(sim: sofac.Simulation, path: str) -> np.ndarray:
    return np.array(sim[path].position)


def test_mapped_point_follows_the_centre_and_its_force_gives_no_torque(tmp_path: Path) -> None:
    mapped = _load(tmp_path, "mapped", MAPPED_FORCE)
    direct = _load(tmp_path, "direct", DIRECT_FORCE)
    assert np.array_equal(_x(mapped, "centre"), _x(mapped, "rigid")[:, :3])
    for _ in range(5):
        mapped.step(4)
        direct.step(4)
        # J^T f: the same numbers as the force written on the body, bit for bit
        assert np.array_equal(_x(mapped, "rigid"), _x(direct, "rigid"))
        assert np.array_equal(np.array(mapped["rigid"].velocity), np.array(direct["rigid"].velocity))
        # the child: the centre and the linear velocity
        assert np.array_equal(_x(mapped, "centre"), _x(mapped, "rigid")[:, :3])
        assert np.array_equal(np.array(mapped["centre"].velocity), np.array(mapped["rigid"].velocity)[:, :3])
    velocity = np.array(mapped["rigid"].velocity)[0]
    assert velocity[5] == 2.0 and not velocity[3:5].any()  # the spin is untouched: no torque
    # (3, -9.81 * 2, -1) / 2 for 20 steps of 0.01
    assert np.allclose(velocity[:3], [1 + 1.5 * 0.2, -9.81 * 0.2, 0.5 - 0.5 * 0.2], rtol=0, atol=1e-12)


@pytest.mark.parametrize("solver", ["SparseLDLSolver", "CGLinearSolver"])
def test_stiffness_through_the_mapping_is_translational(tmp_path: Path, solver: str) -> None:
    """A spring on the mapped centre (K through J^T K J, assembled for SparseLDL, matrix-free for
    CG): the body oscillates about its rest centre and keeps its spin; both solves agree."""
    text = '<SparseLDLSolver template="CompressedRowSparseMatrixd"/>' if solver == "SparseLDLSolver" else CG
    sim = _load(tmp_path, f"spring_{solver}", MAPPED_SPRING, text)
    reference = _load(tmp_path, "spring_cg", MAPPED_SPRING) if solver != "CGLinearSolver" else None
    sim.step(30)
    x, v = _x(sim, "rigid")[0], np.array(sim["rigid"].velocity)[0]
    assert v[5] == pytest.approx(2.0, abs=1e-12) and abs(v[3]) < 1e-12 and abs(v[4]) < 1e-12
    assert x[1] < 10.0 and abs(x[0] + 5) < 1.0  # pulled back towards -5, sagging under gravity
    if reference is not None:
        reference.step(30)
        assert np.allclose(x, _x(reference, "rigid")[0], rtol=0, atol=1e-10)
