"""A loader read only by visual models whose file is missing: SOFA logs an error and runs the
scene with an empty visual model; sofac warns (W231) and compiles the mechanics unchanged."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import sofac

MECHANICS = """\
<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <DefaultAnimationLoop/>
    <EulerImplicitSolver/>
    <CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/>
    <MechanicalObject name="dofs" position="0 0 0  1 0 0  2 0 0"/>
    <UniformMass totalMass="3"/>
{visual}</Node>
"""

VISUAL = """\
    <Node name="v">
        <MeshOBJLoader name="loader" filename="missing.obj"/>
        <OglModel name="visual" src="@loader"/>
        <BarycentricMapping input="@.." output="@visual"/>
    </Node>
"""


def test_visual_only_missing_file_runs_like_the_scene_without_it(tmp_path: Path) -> None:
    with_visual = tmp_path / "with_visual.scn"
    with_visual.write_text(MECHANICS.format(visual=VISUAL), encoding="utf-8")
    plain = tmp_path / "plain.scn"
    plain.write_text(MECHANICS.format(visual=""), encoding="utf-8")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sim = sofac.load(with_visual)
    messages = [str(w.message) for w in caught]
    assert any(":8: warning W231 [filename]" in m for m in messages), messages
    reference = sofac.load(plain)
    sim.step(20)
    reference.step(20)
    x, x_ref = np.array(sim["dofs"].position), np.array(reference["dofs"].position)
    assert np.isfinite(x).all() and x[0, 1] < -0.01  # it falls
    assert np.array_equal(x, x_ref)
