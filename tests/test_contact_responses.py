"""A collision model's own contactResponse (issue #16): SOFA's CollisionResponse picks each pair's
response from its two models (getContactResponse: the models' own when set and not in conflict,
else the manager's). Under DefaultAnimationLoop sofac compiles "PenalityContactForceField" and
"nullptr" (SOFA makes no contact for the pair); anything else is refused at the attribute."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.diagnostics import SceneError
from sofac.pipeline import plan_file

PARTICLES = Path(__file__).parent / "data" / "contact_two_particles.scn"
LEFT, RIGHT = (
    '<PointCollisionModel/>\n    </Node>\n    <Node name="Right">',
    "<PointCollisionModel/>\n    </Node>\n</Node>",
)


def scene(tmp_path: Path, name: str, left: str = "", right: str = "", text: str = "") -> Path:
    """contact_two_particles.scn with the models' contactResponse (empty: unset)."""
    text = text or PARTICLES.read_text()
    own = {
        side: f' contactResponse="{value}"' if value else "" for side, value in (("l", left), ("r", right))
    }
    text = text.replace(LEFT, LEFT.replace("<PointCollisionModel/>", f"<PointCollisionModel{own['l']}/>"))
    text = text.replace(RIGHT, RIGHT.replace("<PointCollisionModel/>", f"<PointCollisionModel{own['r']}/>"))
    path = tmp_path / name
    path.write_text(text)
    return path


def run(path: Path) -> np.ndarray:
    sim = sofac.load(path)
    sim.step(1500)
    return np.concatenate([sim["/Left/dofs"].position, sim["/Right/dofs"].velocity])


@pytest.mark.parametrize(
    ("left", "right", "responds"),
    [
        ("PenalityContactForceField", "", True),  # the model's own: the same response
        ("nullptr", "", False),  # the model's own: no contact
        ("nullptr", "nullptr", False),
        ("nullptr", "PenalityContactForceField", True),  # in conflict: the manager's
    ],
)
def test_the_pair_response_follows_sofas_rule(tmp_path: Path, left: str, right: str, responds: bool) -> None:
    """The two particles fly at each other: with a response they bounce apart exactly as without
    any contactResponse (bit for bit); with "nullptr" they fly through each other as if no
    collision model were there (the detection still runs: SOFA keeps the pair in its maps)."""
    path = scene(tmp_path, "own.scn", left, right)
    (pair,) = plan_file(path).collisions[0].pairs
    assert pair.respond is responds
    reference = run(scene(tmp_path, "default.scn"))
    if not responds:
        reference = run(
            scene(tmp_path, "bare.scn", text=PARTICLES.read_text().replace("<PointCollisionModel/>", ""))
        )
    assert np.array_equal(run(path), reference)


def test_unsupported_responses_are_refused_at_the_attribute(tmp_path: Path) -> None:
    """A response sofac does not compile: E222 at the contactResponse attribute, naming what is
    compiled; under FrictionContactConstraint no model's own response is compiled yet."""
    with pytest.raises(SceneError) as error:
        plan_file(scene(tmp_path, "stick.scn", right="StickContactForceField"))
    (found,) = [d for d in error.value.diagnostics if d.code == "E222"]
    assert found.loc.line == 21 and found.loc.attribute == "contactResponse"
    assert "contactResponse='StickContactForceField' is not compiled" in found.message
    assert "'PenalityContactForceField' and 'nullptr'" in found.message

    text = PARTICLES.read_text().replace("DefaultAnimationLoop", "FreeMotionAnimationLoop")
    text = text.replace('response="PenalityContactForceField"', 'response="FrictionContactConstraint"')
    with pytest.raises(SceneError) as error:
        plan_file(scene(tmp_path, "friction.scn", left="FrictionContactConstraint", text=text))
    found = [d for d in error.value.diagnostics if d.code == "E222" and d.loc.line == 15]
    assert (
        len(found) == 1 and "own response under FrictionContactConstraint is not compiled" in found[0].message
    )
