"""Self-collision under penalty contact (issue #16): the pairs SOFA's broad phase makes of the
models of one node (a model with itself, and the node's models with each other, when they have
selfCollision), BVHNarrowPhase's element filter (canCollideWith: e1 < e2 in one model, a
triangle never against its own vertices, a line never against its neighbours...), and where the
response goes (the pipeline's node: explicit, or inside the group of a solver integrating it).

The scene: a strip of cloth (MeshSpringForceField) folded back over itself, its lower half, the
fold and the first row of its upper half held; the rest of the upper half falls onto the lower
half. With self-collision no point of the upper half ever goes through the lower half's plane;
without it the upper half falls through."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.diagnostics import SceneError
from sofac.pipeline import generate, plan_file
from sofac.plan.ir import SelfFilter

MODELS = ("Triangle", "Line", "Point")


def folded_cloth(
    *,
    cells: int = 8,
    width: int = 3,
    height: float = 0.1,
    self_collision: bool = True,
    method: str = "MinProximityIntersection",
    solver_at_root: bool = False,
    stiffness: float = 1.0,
    models: tuple[str, ...] = MODELS,
    linear_solver: str = '<CGLinearSolver iterations="100" tolerance="1e-12" threshold="1e-20"/>',
    response: str = "PenalityContactForceField",
    loop: str = "DefaultAnimationLoop",
) -> str:
    """The scene text: `cells` x `width` quads each side of the fold (1 m x 0.5 m), the upper half
    `height` above the lower one; the lower half at y = 0."""
    us = np.linspace(0.0, 2.0, 2 * cells + 1)
    vs = np.linspace(0.0, 0.5, width + 1)
    points, held = [], []
    for i, u in enumerate(us):
        for v in vs:
            points.append((float(u), 0.0, float(v)) if u <= 1.0 else (float(2.0 - u), height, float(v)))
            if i <= cells + 1:  # the lower half, the fold and the upper half's first row
                held.append(len(points) - 1)
    triangles = grid_triangles(2 * cells, width)
    position = " ".join(f"{x!r} {y!r} {z!r}" for x, y, z in points)
    flag = "1" if self_collision else "0"
    collision = "\n".join(
        f'        <{m}CollisionModel selfCollision="{flag}" contactStiffness="{stiffness!r}"/>'
        for m in models
    )
    solver = f'<EulerImplicitSolver rayleighMass="2" rayleighStiffness="0"/>\n    {linear_solver}'
    return f"""<?xml version="1.0"?>
<Node name="root" dt="0.005" gravity="0 -9.81 0">
    <{loop}/>
    <CollisionPipeline depth="6"/>
    <BruteForceBroadPhase/>
    <BVHNarrowPhase/>
    <{method} alarmDistance="0.05" contactDistance="0.02"/>
    <CollisionResponse response="{response}"/>
    {solver if solver_at_root else ""}
    <Node name="Cloth">
        {"" if solver_at_root else solver}
        <MeshTopology name="mesh" position="{position}"
            triangles="{" ".join(f"{a} {b} {c}" for a, b, c in triangles)}"/>
        <MechanicalObject name="dofs"/>
        <UniformMass totalMass="1"/>
        <MeshSpringForceField stiffness="200" damping="0"/>
        <FixedProjectiveConstraint indices="{" ".join(map(str, held))}"/>
{collision}
    </Node>
</Node>
"""


def grid_triangles(rows: int, columns: int) -> list[tuple[int, int, int]]:
    """Two triangles per cell of a grid of (rows + 1) x (columns + 1) points numbered row by row:
    (a, b, c) and (a, c, d), a the cell's first corner, b the next row's, d the next column's."""
    n = columns + 1
    triangles = []
    for i in range(rows):
        for j in range(columns):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            triangles += [(a, b, c), (a, c, d)]
    return triangles


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_pairs_of_one_node_and_their_filters(tmp_path: Path) -> None:
    """SOFA's broad phase pairs each model of the node with itself, then with the earlier ones;
    each pair of one node gets the filter its first model's canCollideWithElement applies. One
    point model's pairs never pass (index < index2 and index > index2): no narrow phase is run."""
    plan = plan_file(write(tmp_path, "new.scn", folded_cloth(method="NewProximityIntersection")))
    (collision,) = plan.collisions
    names = [m.origin.split("'")[1].rsplit("/", 1)[1] for m in collision.models]
    pairs = [
        (names[p.first], names[p.second], collision.tests[p.test].name.split("::")[1], p.self_filter)
        for p in collision.pairs
    ]
    triangles, lines, points = names
    assert pairs == [
        (triangles, triangles, "triangle_triangle", SelfFilter.SAME_MODEL),
        (lines, lines, "line_line", SelfFilter.SAME_LINES),
        (triangles, lines, "triangle_line", SelfFilter.NONE),  # Triangle's filter lets lines through
        (points, points, "point_point", SelfFilter.NEVER),
        (triangles, points, "triangle_point", SelfFilter.TRIANGLE_POINT),
        (lines, points, "line_point", SelfFilter.LINE_POINT),
    ]
    assert all(p.one_node and p.root and not p.grouped for p in collision.pairs)  # no solver at the root
    triangle_triangle = collision.tests[collision.pairs[0].test]
    assert triangle_triangle.options == (True, False)  # one model: neighbouring triangles skipped
    source = generate(plan)
    assert "no element pair of one point model passes SOFA's filter" in source
    assert source.count("if (p.filter(e1, e2))") == 4  # T-T, L-L, T-P, L-P; not T-L
    effects = [e for e in plan.effects if e[0] == "contact pair"]
    assert sum("SOFA's element filter" in e[2] for e in effects) == 5

    plan = plan_file(write(tmp_path, "min.scn", folded_cloth()))
    (collision,) = plan.collisions
    assert len(collision.pairs) == 4  # MinProximity registers no triangle-triangle, triangle-line test
    assert {why for *_, why in collision.left_out} == {
        "min_proximity has no triangle-triangle test",
        "min_proximity has no triangle-line test",
    }

    plan = plan_file(write(tmp_path, "off.scn", folded_cloth(self_collision=False)))
    assert not plan.collisions  # one node without selfCollision: nothing to touch


def _upper(sim: sofac.Simulation) -> np.ndarray:
    """The free points: the upper half's but its first row (folded_cloth's defaults: 8 x 3 cells)."""
    return np.arange((8 + 2) * 4, (2 * 8 + 1) * 4)


@pytest.mark.parametrize(
    ("solver_at_root", "stiffness", "rest"),
    [(False, 1.0, (0.01, 0.025, 0.2)), (True, 10.0, (0.0195, 0.0201, 1e-3))],
    ids=["explicit (solver in the cloth's node)", "implicit (solver at the pipeline's node)"],
)
def test_folded_cloth_does_not_pass_through_itself(
    tmp_path: Path, solver_at_root: bool, stiffness: float, rest: tuple[float, float, float]
) -> None:
    """The upper half falls 0.1 m onto the lower half: no free point ever goes below the lower
    half's plane (y = 0), and after 2 s the layer lies on it, within the contact distance (0.02).
    With the solver in the cloth's node the contacts act explicitly (SOFA evaluates them at the
    pipeline's node before the solve): a soft contact (ks = 1 / 0.02), still trembling (|v| up to
    0.2 m/s); with the solver at the root they are inside its group, implicit: a ten times stiffer
    contact, at rest at the contact distance."""
    text = folded_cloth(solver_at_root=solver_at_root, stiffness=stiffness)
    plan = plan_file(write(tmp_path, "cloth.scn", text))
    assert all(p.grouped == solver_at_root for p in plan.collisions[0].pairs)
    sim = sofac.load(tmp_path / "cloth.scn")
    free = _upper(sim)
    assert len(free) == 28 and np.all(sim["/Cloth/dofs"].position[free, 1] == 0.1)
    for _ in range(400):
        sim.step()
        assert np.all(sim["/Cloth/dofs"].position[free, 1] > 0.0), sim.steps  # the lower half spans x, z
    low, high, speed = rest
    heights = sim["/Cloth/dofs"].position[free, 1]
    assert low < heights.min() and heights.max() < high
    assert np.abs(sim["/Cloth/dofs"].velocity[free]).max() < speed
    report = sim.output("/CollisionPipeline2.contactReport")
    assert report[0] > 100 and report[7] == 0  # contacts, none pushed through


def test_without_self_collision_the_cloth_falls_through(tmp_path: Path) -> None:
    sim = sofac.load(write(tmp_path, "through.scn", folded_cloth(self_collision=False)))
    free = _upper(sim)
    sim.step(300)
    assert sim["/Cloth/dofs"].position[free, 1].min() < -0.05


def _refusals(path: Path) -> list[tuple[int, str]]:
    with pytest.raises(SceneError) as error:
        plan_file(path)
    return [(d.loc.line, d.message) for d in error.value.diagnostics if d.code == "E222"]


def test_unsupported_self_collision_setups_are_refused(tmp_path: Path) -> None:
    """Two line models of one node with selfCollision: SOFA's LineCollisionModel filter hands the
    question to the other model, which hands it back, for ever; the Lagrangian response; and pairs
    placed in the group of an assembled (direct) solver, whose matrix pattern is fixed."""
    text = folded_cloth(models=("Line", "Line"))
    found = _refusals(write(tmp_path, "lines.scn", text))
    assert found and all("passes the question between them without end" in m for _, m in found)
    assert {line for line, _ in found} == {19, 20}  # both line models

    text = folded_cloth(
        loop="FreeMotionAnimationLoop", response="FrictionContactConstraint", models=("Triangle", "Point")
    )
    found = _refusals(write(tmp_path, "friction.scn", text))
    assert found and all("self-collision under FrictionContactConstraint" in m for _, m in found)

    text = folded_cloth(solver_at_root=True, linear_solver="<SparseLDLSolver/>")
    ((line, message),) = _refusals(write(tmp_path, "ldl.scn", text))
    assert line == 10 and "SparseLDLSolver" in message and "pattern" in message


def test_the_parallel_broad_phase_hands_on_self_pairs_first(tmp_path: Path) -> None:
    """ParallelBruteForceBroadPhase adds each model's pair with itself as the models come, and the
    other pairs after its tasks (in the sequential order): the self pairs lead the contact order."""
    parallel = folded_cloth(method="NewProximityIntersection").replace(
        "<BruteForceBroadPhase/>", "<ParallelBruteForceBroadPhase/>"
    )
    plan = plan_file(
        write(tmp_path, "parallel.scn", parallel.replace("<BVHNarrowPhase/>", "<ParallelBVHNarrowPhase/>"))
    )
    (collision,) = plan.collisions
    names = [m.origin.split("'")[1].rsplit("/", 1)[1] for m in collision.models]
    triangles, lines, points = names
    assert [(names[p.first], names[p.second]) for p in collision.pairs] == [
        (triangles, triangles),
        (lines, lines),
        (points, points),
        (triangles, lines),
        (triangles, points),
        (lines, points),
    ]
