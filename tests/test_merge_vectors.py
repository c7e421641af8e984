"""MergeVectors, evaluated at compile time: its inputs one after the other (SOFA's doUpdate)."""

from __future__ import annotations

from pathlib import Path

from sofac.check.checker import check_file
from sofac.pipeline import plan_file

SCENE = """\
<Node name="root" gravity="0 -10 0" dt="0.01"><DefaultAnimationLoop/>
  <EulerExplicitSolver/>
  <MechanicalObject name="dofs" position="0 0 0  1 0 0  2 0 0  3 0 0"/>
  <UniformMass vertexMass="1"/>
  <BoxROI name="box1" box="2.5 -1 -1  3.5 1 1"/>
  <BoxROI name="box2" box="-0.5 -1 -1  1.5 1 1"/>
  <MergeVectors template="Data&lt;int&gt;" name="merged" nbInputs="{count}" input1="@box1.indices"
      input2="@box2.indices"/>
  <FixedProjectiveConstraint indices="@merged.output"/>
</Node>
"""


def _fixed(tmp_path: Path, count: int) -> list[int]:
    path = tmp_path / "merge.scn"
    path.write_text(SCENE.format(count=count))
    (buffer,) = [b for b in plan_file(path).buffers if b.key.endswith("FixedProjectiveConstraint8.indices")]
    return buffer.initial.tolist()


def test_inputs_are_concatenated_in_order(tmp_path: Path) -> None:
    assert _fixed(tmp_path, 2) == [3, 0, 1]  # box1's, then box2's, duplicates kept as SOFA does
    assert _fixed(tmp_path, 1) == [3]  # only input1 counts


def test_more_inputs_than_declared_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "many.scn"
    path.write_text(SCENE.format(count=9))
    _, diags = check_file(path)
    assert [(d.code, d.loc.line) for d in diags.errors] == [("E222", 7)]
