"""Hard contact cases (issue #16), each with its expected outcome: a body started deep inside the
contact distance is pushed out and settles where the contact balances its weight; a penalty
contact far too stiff for an explicit step is reported (energy guard), never a silent blow-up."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac

FLOOR = Path(__file__).resolve().parents[1] / "data" / "contact_sphere_floor.scn"


def test_deep_initial_penetration_recovers_and_settles(tmp_path: Path) -> None:
    """The sphere's centre starts 0.01 above the floor, 0.29 into its contact distance (0.3): the
    contact force (97 N on 1 kg) throws it up; implicit Euler with Rayleigh mass damping brings it
    back to rest at d - m g / ks, finite at every step."""
    scene = tmp_path / "deep.scn"
    scene.write_text(FLOOR.read_text().replace('position="0.1 0.4 -0.2"', 'position="0.1 0.01 -0.2"'))
    sim = sofac.load(scene)
    heights = []
    for _ in range(100):
        sim.step(10)
        heights.append(sim["/Particle/dofs"].position[0, 1])
    assert np.all(np.isfinite(heights)) and max(heights) < 2.0
    ks = 100.0 / 0.3
    assert heights[-1] == pytest.approx(0.3 - 9.81 / ks, abs=1e-9)


def test_contact_too_stiff_for_an_explicit_step_is_reported(tmp_path: Path) -> None:
    """ks = 1e8 / 0.3 on 1 kg: omega dt = 183 with dt = 0.01, far past symplectic Euler's limit of 2.
    The first contact step throws the sphere off with a huge velocity; the energy guard names the
    step instead of letting the run go on."""
    scene = tmp_path / "stiff.scn"
    text = FLOOR.read_text().replace('contactStiffness="10"', 'contactStiffness="1e4"')
    text = text.replace(
        '<EulerImplicitSolver rayleighMass="2" rayleighStiffness="0"/>',
        '<EulerExplicitSolver symplectic="1"/>',
    )
    scene.write_text(
        text.replace('<CGLinearSolver iterations="50" tolerance="1e-12" threshold="1e-20"/>', "")
    )
    sim = sofac.load(scene)
    sim.guard_energy(10.0)
    with pytest.raises(sofac.SimulationDiverged) as diverged:
        for _ in range(200):
            sim.step()
    assert "energy" in str(diverged.value)
    assert sim.steps < 40  # it reaches the contact distance after about 12 steps; stopped soon after


def test_a_fast_body_tunnelling_through_a_thin_floor_is_reported(tmp_path: Path) -> None:
    """At 100 m/s with dt = 0.01 the sphere moves 1 m per step, past the floor's reach (alarm 0.5)
    between two detections: it goes through. The run says so (ContactWarning), it is not silent."""
    scene = tmp_path / "fast.scn"
    text = FLOOR.read_text().replace('position="0.1 0.4 -0.2"', 'position="0.1 3.5 -0.2" velocity="0 -100 0"')
    scene.write_text(text)
    sim = sofac.load(scene)
    with pytest.warns(sofac.ContactWarning, match="tunnelling") as caught:
        sim.step(10)
    assert sim["/Particle/dofs"].position[0, 1] < -1.0  # it did go through
    assert "contactReport" not in str(caught[0].message) and "CollisionPipeline" in str(caught[0].message)
