"""Lagrangian contact and constraint rows carried through a BarycentricMapping onto the DOFs of a
deformable body (runtime/sofac/lagrangian_contact.h ``barycentric_rows``, plan/lower/corrections.py
``contact_bodies`` and ``carry_through_linear_mappings``): SOFA's BarycentricMapping::applyJT on
the constraint matrix, each row of the mapped collision state spread on its element's nodes.

Checked against: the parent's λ = Jᵀ f with J computed by NumPy from the barycentric weights of the
mapped points (one contact, one bilateral pair); a stiff FEM cube whose barycentric-mapped bottom
points rest on a floor at the contact distance with the normal impulses adding up to m g dt, under
LinearSolverConstraintCorrection and UncoupledConstraintCorrection alike; a cube hanging from an
anchor by a bilateral row on a mapped point (IdentityMapping, SubsetMapping, BarycentricMapping).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from lagrangian_scenes import CONTACT, DT, G, contact_root, static_floor

MASS = 1.0
# A unit cube from y = 0 up, split into six tetrahedra about its diagonal 0-7 (corner i at
# (i & 1, (i >> 1) & 1, (i >> 2) & 1) - 0.5 in x and z).
CORNERS = np.array([[(i & 1) - 0.5, (i >> 1) & 1, ((i >> 2) & 1) - 0.5] for i in range(8)], dtype=float)
TETRAHEDRA = np.array([[0, 1, 3, 7], [0, 5, 1, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 6, 4, 7]])


# The cube's correction: its factorised system, or its eight nodes' mass (compliance 1/m each)
CORRECTIONS = ["<LinearSolverConstraintCorrection/>", '<UncoupledConstraintCorrection compliance="8"/>']


def _text(values: np.ndarray) -> str:
    return " ".join(f"{v:.17g}" for v in np.asarray(values, dtype=float).ravel())


def cube_node(rest: np.ndarray, young: float, correction: str, child: str) -> str:
    """Node /Cube: the cube's tetrahedra at ``rest``, mass MASS, FEM of Young's modulus ``young``
    (its deformation damped), ``correction``, and the ``child`` node of its mapped points."""
    return f"""    <Node name="Cube">
        <EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0" />
        <SparseLDLSolver/>
        <MechanicalObject name="dofs" position="{_text(rest)}" />
        <MeshTopology tetrahedra="{_text(TETRAHEDRA).replace(".0", "")}" />
        <UniformMass totalMass="{MASS}" />
        <TetrahedronFEMForceField youngModulus="{young}" poissonRatio="0.3" method="large" />
        {correction}
        {child}
    </Node>
"""


def cube_scene(
    tmp_path: Path,
    points: np.ndarray,
    *,
    correction: str = "<LinearSolverConstraintCorrection/>",
    lift: float = 0.1,
    young: float = 1e5,
    mu: float = 0.0,
) -> Path:
    """The cube (FEM, mass MASS, damped), ``lift`` above a static floor at y = 0, its collision
    points ``points`` (cube coordinates) mapped by a BarycentricMapping."""
    up = np.array([0.0, lift, 0.0])
    rest = CORNERS + up
    surface = f"""<Node name="Surface">
            <MechanicalObject name="points" position="{_text(points + up)}" />
            <PointCollisionModel />
            <BarycentricMapping />
        </Node>"""
    text = (
        contact_root('<BlockGaussSeidelConstraintSolver tolerance="1e-12" maxIterations="1000"/>', mu)
        + cube_node(rest, young, correction, surface)
        + static_floor("-2 0 -2  2 0 -2  2 0 2  -2 0 2")
        + "</Node>\n"
    )
    path = tmp_path / f"cube_{abs(hash(text))}.scn"
    path.write_text(text)
    return path


def barycentric_weights(point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """NumPy's (nodes, weights) of a point of the cube: the tetrahedron holding it, its four
    barycentric coordinates (solved, not SOFA's arithmetic)."""
    for tetra in TETRAHEDRA:
        a = CORNERS[tetra]
        w = np.linalg.solve(np.vstack([a.T, np.ones(4)]), np.append(point, 1.0))
        if (w >= -1e-12).all():
            return tetra, w
    raise AssertionError(f"{point} is in no tetrahedron")


def correction_lambda(sim: sofac.Simulation, name: str) -> np.ndarray:
    """The λ = Jᵀ f the correction ``name`` moved its state by this step (a scratch buffer: the
    step writes it, nothing keeps it)."""
    (view,) = [
        v
        for b, v in zip(sim.spec.buffers, sim._views, strict=True)
        if b.key.endswith(".lambda") and name in b.key
    ]
    return view


@pytest.mark.parametrize("correction", CORRECTIONS)
def test_a_contact_row_lands_on_the_nodes_with_the_barycentric_weights(
    tmp_path: Path, correction: str
) -> None:
    # one collision point inside a tetrahedron, 0.05 above the bottom: one contact, one row n = +y
    point = np.array([0.2, 0.05, -0.1])
    nodes, weights = barycentric_weights(point)
    sim = sofac.load(cube_scene(tmp_path, point[None, :], correction=correction, lift=0.05))
    name = correction[1:].split("/")[0].split()[0]
    rows = 0
    for _ in range(30):
        sim.step(1)
        if sim.output("/CollisionPipeline3.contactReport")[0] == 0:
            continue
        rows += 1
        f = sim.output("/.constraint_f")[0]
        expected = np.zeros((8, 3))
        expected[nodes, 1] = weights * f  # Jᵀ f: the row's +y on each node, times its weight
        lam = correction_lambda(sim, name).reshape(8, 3)
        # (the floor's normal is +y to 1e-15: its triangle's cross product)
        np.testing.assert_allclose(lam, expected, rtol=1e-12, atol=1e-14 * abs(f))
    assert rows > 10 and f > 0


def test_a_contact_on_a_mapped_triangle_sums_each_node_three_times(tmp_path: Path) -> None:
    # a small horizontal triangle inside one tetrahedron (corners 0 1 3 7), a static point below
    # its centroid: the contact row's three collision points each spread on the same four nodes,
    # so each (row, node) gets three blocks, summed after SOFA's sort. At the first push the cube
    # has only fallen (a rigid translation): the contact point is the centroid, the normal -y,
    # so Jᵀ f puts on each node its weight at the centroid times f, upwards.
    tetra = CORNERS[[0, 1, 3, 7]]
    triangle = np.array([[0.5, 0.3, 0.1, 0.1], [0.3, 0.5, 0.1, 0.1], [0.4, 0.4, 0.05, 0.15]]) @ tetra
    centroid = triangle.mean(axis=0)
    path = cube_scene(tmp_path, triangle, lift=0.05)
    text = path.read_text().replace(
        "<PointCollisionModel />",
        '<MeshTopology triangles="0 1 2" /> <TriangleCollisionModel />',
    )
    floor = static_floor("-2 0 -2  2 0 -2  2 0 2  -2 0 2")
    below = f"""    <Node name="Floor">
        <MechanicalObject name="dofs" position="{centroid[0]:.17g} 0 {centroid[2]:.17g}" />
        <PointCollisionModel simulated="0" moving="0" />
    </Node>
"""
    path.write_text(text.replace(floor, below))
    nodes, weights = barycentric_weights(centroid)
    assert list(nodes) == [0, 1, 3, 7]
    sim = sofac.load(path)
    contacts = []
    for _ in range(40):
        sim.step(1)
        contacts.append(sim.output("/CollisionPipeline3.contactReport")[0])
        if sim.output("/.constraint_f")[0] > 0:
            break
    assert contacts[0] == 0 and contacts[-1] == 1  # falls into the alarm distance, then is pushed
    f = sim.output("/.constraint_f")[0]
    expected = np.zeros((8, 3))
    expected[nodes, 1] = weights * f
    lam = correction_lambda(sim, "LinearSolverConstraintCorrection").reshape(8, 3)
    np.testing.assert_allclose(lam, expected, rtol=1e-12, atol=1e-14 * f)


@pytest.mark.filterwarnings("ignore:.*iteration limit:RuntimeWarning")
@pytest.mark.parametrize("correction", CORRECTIONS)
def test_a_stiff_cube_rests_on_its_mapped_points_at_the_contact_distance(
    tmp_path: Path, correction: str
) -> None:
    # four points near the bottom face's corners (off the diagonal x = z the floor's triangles
    # share, where LocalMinDistance finds neither), each on a face of some tetrahedra; friction
    # holds the cube still (without it, the impact's slight twist would spin it on the floor)
    corners = np.array([[x, 0.0, z] for z in (-0.4, 0.4) for x in (-0.45, 0.45)])
    sim = sofac.load(cube_scene(tmp_path, corners, correction=correction, mu=0.5))
    sim.step(300)
    points = sim["/Cube/Surface/points"].position
    cube = sim["/Cube/dofs"]
    assert sim.output("/CollisionPipeline3.contactReport")[0] == 4
    np.testing.assert_allclose(points[:, 1], CONTACT, atol=1e-9)  # measured: 3e-10
    # at rest but for the solve's residual: a stiff body on four points is the slow case of
    # Gauss-Seidel (the linear correction's solves stop at 1000 iterations, residual 4e-9)
    assert np.abs(cube.velocity).max() < 1e-6  # measured: 7e-8
    normals = sim.output("/.constraint_f")[:12:3]
    assert normals.min() > 0.0
    assert normals.sum() == pytest.approx(MASS * G * DT, rel=1e-9)


def hanging_scene(tmp_path: Path, handle: str, second_points: str, anchors: np.ndarray) -> Path:
    """The cube held up by bilateral rows: pair k joins anchor k to point ``second_points[k]`` of
    the cube's mapped state /Cube/Handle/points (``handle``: its MechanicalObject and mapping)."""
    pairs = " ".join(str(k) for k in range(len(anchors)))
    text = f"""<?xml version="1.0"?>
<Node name="root" dt="{DT}" gravity="0 -{G} 0">
    <FreeMotionAnimationLoop />
    <BlockGaussSeidelConstraintSolver tolerance="1e-14" maxIterations="1000"/>
    <Node name="Anchor">
        <MechanicalObject name="points" position="{_text(anchors)}" />
    </Node>
{cube_node(CORNERS, 1e4, "<LinearSolverConstraintCorrection/>", f'<Node name="Handle"> {handle} </Node>')}
    <BilateralLagrangianConstraint object1="@Anchor/points" object2="@Cube/Handle/points"
        first_point="{pairs}" second_point="{second_points}"/>
</Node>
"""
    path = tmp_path / f"hanging_{abs(hash(text))}.scn"
    path.write_text(text)
    return path


TOP = [2, 3, 6, 7]  # the cube's top corners
NEAR_TOP = np.array([[x, 0.95, z] for z in (-0.4, 0.4) for x in (-0.4, 0.4)])  # inside, near them
HANDLES = {
    "identity": ('<MechanicalObject name="points"/> <IdentityMapping/>', "2 3 6 7", CORNERS[TOP]),
    "subset": (
        f'<MechanicalObject name="points" position="{_text(CORNERS[TOP])}"/> '
        '<SubsetMapping indices="2 3 6 7"/>',
        "0 1 2 3",
        CORNERS[TOP],
    ),
    "barycentric": (
        f'<MechanicalObject name="points" position="{_text(NEAR_TOP)}"/> <BarycentricMapping/>',
        "0 1 2 3",
        NEAR_TOP,
    ),
}


@pytest.mark.parametrize("mapping", list(HANDLES))
def test_a_cube_hangs_from_bilateral_rows_on_mapped_points(tmp_path: Path, mapping: str) -> None:
    handle, second, anchors = HANDLES[mapping]
    sim = sofac.load(hanging_scene(tmp_path, handle, second, anchors))
    sim.step(1)
    # the rows' impulses (kept forces, 3 per pair), and what they moved the cube by: λ = Jᵀ f, J
    # the mapping's weights (1 on a corner through identity and subset)
    f = sim.output("/.constraint_kept_forces").reshape(4, 3)
    expected = np.zeros((8, 3))
    for k, point in enumerate(anchors):
        nodes, weights = barycentric_weights(point)
        expected[nodes] += np.outer(weights, f[k])
    lam = correction_lambda(sim, "LinearSolverConstraintCorrection").reshape(8, 3)
    np.testing.assert_allclose(lam, expected, rtol=1e-12, atol=1e-15)
    sim.step(1499)
    # at rest: the handle's points at the anchors, the impulses carrying the weight over a step
    points = sim["/Cube/Handle/points"].position[[int(s) for s in second.split()]]
    np.testing.assert_allclose(points, anchors, atol=1e-12)
    assert np.abs(sim["/Cube/dofs"].velocity).max() < 1e-9
    f = sim.output("/.constraint_kept_forces").reshape(4, 3)
    assert f[:, 1].sum() == pytest.approx(MASS * G * DT, rel=1e-9)
    np.testing.assert_allclose(f[:, [0, 2]].sum(axis=0), 0.0, atol=1e-12)


def _distance_to_surface(points: np.ndarray, corners: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Each point's distance to the nearest of the triangles (corner positions, index triples)."""
    a, b, c = (corners[triangles[:, i]] for i in range(3))
    p = points[:, None, :]
    ab, ac, ap = b - a, c - a, points[:, None, :] - a
    normal = np.cross(ab, ac)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    d00, d01, d11 = (ab * ab).sum(1), (ab * ac).sum(1), (ac * ac).sum(1)
    d20, d21 = (ap * ab).sum(2), (ap * ac).sum(2)
    v = (d11 * d20 - d01 * d21) / (d00 * d11 - d01 * d01)
    w = (d00 * d21 - d01 * d20) / (d00 * d11 - d01 * d01)
    inside = (v >= 0) & (w >= 0) & (v + w <= 1)
    best = np.where(inside, np.abs((ap * normal).sum(2)), np.inf)  # onto the face
    for s, e in ((a, b), (b, c), (c, a)):  # onto its edges
        edge = e - s
        t = np.clip(((p - s) * edge).sum(2) / (edge * edge).sum(1), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(p - (s + t[..., None] * edge), axis=2))
    return best.min(axis=1)


@pytest.mark.long
@pytest.mark.filterwarnings("ignore:.*iteration limit:RuntimeWarning")
def test_sofas_chain_of_tori_hangs_linked_at_the_contact_distance(shared_dir: Path) -> None:
    # SOFA's Component/AnimationLoop/FreeMotionAnimationLoop.scn: a fixed torus, an FEM torus
    # linked through it (LinearSolverConstraintCorrection, its collision surface BarycentricMapping'd
    # on its tetrahedra) and a rigid torus linked through that one, gravity +y, LCPConstraintSolver,
    # LocalMinDistance with contactDistance 1. No reference: the chain swings down and hangs, the
    # links never closer than the contact distance (less the solve's tolerance, 1e-3).
    from sofac.front.meshes import read_mesh

    corpus = shared_dir / "corpus" / "sofa"
    sim = sofac.load(corpus / "Component/AnimationLoop/FreeMotionAnimationLoop.scn")
    link = np.asarray(read_mesh(corpus / "mesh/torus2_for_collision.obj").triangles)  # fixed, rigid
    ring = np.asarray(read_mesh(corpus / "mesh/torus_for_collision.obj").triangles)  # FEM
    fixed = sim["/Torus1/MechanicalObject3"].position
    fem, rigid = sim["/TorusFEM/Surf2/MechanicalObject3"], sim["/Torus3/Surf2/MechanicalObject3"]
    gaps = []
    for step in range(200):
        sim.step(1)
        if step >= 10:
            assert sim.output("/CollisionPipeline23.contactReport")[0] > 10  # 25 to 47 contacts
        if step % 10 == 9:
            upper = min(
                _distance_to_surface(fem.position, fixed, link).min(),
                _distance_to_surface(fixed, fem.position, ring).min(),
            )
            lower = min(
                _distance_to_surface(rigid.position, fem.position, ring).min(),
                _distance_to_surface(fem.position, rigid.position, link).min(),
            )
            gaps.append((upper, lower))
    gaps_arr = np.array(gaps[1:])  # from step 20 on, both links in contact
    assert gaps_arr.min() > 1.0 - 2e-3 and gaps_arr.max() < 1.2  # measured: 0.99915 to 1.13
    x_fem = sim["/TorusFEM/MechanicalObject5"].position
    x_rigid = sim["/Torus3/MechanicalObject3"].position
    assert np.isfinite(x_fem).all() and np.isfinite(x_rigid).all()
    assert 8.0 < x_fem[:, 1].mean() < x_rigid[0, 1]  # hanging below the fixed torus (+y), in order


def test_rows_through_a_mesh_of_tetrahedra_and_hexahedra_take_each_element_s_nodes(tmp_path: Path) -> None:
    # SOFA's mesh mapper over tetrahedra and hexahedra: the mapping's table pads a tetrahedron's
    # point to eight columns; its rows go to the tetrahedron's four nodes only (applyJT adds
    # those), a hexahedron's point to its eight in the mapper's order
    from sofac.check.checker import check_file
    from sofac.plan.planner import plan_scene

    hexa = [[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)]  # nodes 0..7, SOFA's order
    positions = np.array([*hexa, [2.0, 0.0, 0.0]])  # node 8: a tetrahedron on the hexahedron's side
    hexahedra = "0 1 3 2 4 5 7 6"
    points = np.array([[1.2, 0.2, 0.1], [0.3, 0.6, 0.2]])  # in the tetrahedron, in the hexahedron
    text = f"""<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <FreeMotionAnimationLoop/>
    <Node name="Anchor"> <MechanicalObject name="points" position="{_text(points)}"/> </Node>
    <Node name="Body">
        <EulerImplicitSolver/> <SparseLDLSolver/>
        <MechanicalObject name="dofs" position="{_text(positions)}"/>
        <MeshTopology tetrahedra="1 8 3 5" hexahedra="{hexahedra}"/>
        <UniformMass totalMass="1"/>
        <LinearSolverConstraintCorrection/>
        <Node name="Handle">
            <MechanicalObject name="points" position="{_text(points)}"/> <BarycentricMapping/>
        </Node>
    </Node>
    <BilateralLagrangianConstraint object1="@Anchor/points" object2="@Body/Handle/points"
        first_point="0 1" second_point="0 1"/>
</Node>
"""
    path = tmp_path / "mixed.scn"
    path.write_text(text)
    checked, _ = check_file(path)
    assert checked is not None
    phase = plan_scene(checked).constraints
    assert phase is not None
    (correction,) = phase.corrections
    assert correction.state.path == "/Body/dofs"
    by_row: dict[int, list[tuple[int, tuple[float, ...]]]] = {}
    for row, dof, values in phase.entries[correction.state.ident]:
        by_row.setdefault(row, []).append((dof, values))
    # rows 0-2: the tetrahedron's point (x of row 0 only: +e_x times each weight)
    a, b, c, d = positions[[1, 8, 3, 5]]
    w = np.linalg.solve(np.vstack([np.array([a, b, c, d]).T, np.ones(4)]), np.append(points[0], 1.0))
    assert [dof for dof, _ in by_row[0]] == [1, 8, 3, 5]
    np.testing.assert_allclose([values[0] for _, values in by_row[0]], w, rtol=1e-12, atol=1e-15)
    # rows 3-5: the hexahedron's point, trilinear weights on hexa[0] hexa[1] hexa[3] hexa[2]
    # hexa[4] hexa[5] hexa[7] hexa[6]: nodes 0 to 7 here (x + 2 y + 4 z)
    assert [dof for dof, _ in by_row[3]] == list(range(8))
    fx, fy, fz = points[1]
    trilinear = [
        (1 - fx) * (1 - fy) * (1 - fz),
        fx * (1 - fy) * (1 - fz),
        (1 - fx) * fy * (1 - fz),
        fx * fy * (1 - fz),
        (1 - fx) * (1 - fy) * fz,
        fx * (1 - fy) * fz,
        (1 - fx) * fy * fz,
        fx * fy * fz,
    ]
    np.testing.assert_allclose([values[0] for _, values in by_row[3]], trilinear, rtol=1e-12)
