"""SOFA's topology masses (DiagonalMass, MeshMatrixMass) computed at compile time: analytic cases,
SOFA's precedence rules and element-type choice, the consistent matrix and its product, degenerate
input, and the DiagonalMass of Demos/liver.scn."""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import numpy as np
import pytest
from sofac.front import meshes
from sofac.geometry.masses import (
    diagonal_mass,
    element_measures,
    mesh_matrix_mass,
    mesh_matrix_mass_multiply,
    topology_edges,
)

CUBE = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float
)
HEXA = np.array([[0, 1, 2, 3, 4, 5, 6, 7]])
# The unit cube as 6 tetrahedra around the diagonal 0-6 (all positively oriented).
CUBE_TETS = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]])


def regular_tetrahedron(a: float) -> np.ndarray:
    return np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float) * (
        a / (2 * math.sqrt(2))
    )


def dense(data, width: int = 1) -> np.ndarray:
    rows, cols, values = data.triplets(width)
    n = len(data.vertex_mass) * width
    matrix = np.zeros((n, n))
    np.add.at(matrix, (rows, cols), values)
    return matrix


# ---- measures ----------------------------------------------------------------------------------------


def test_element_measures_analytic() -> None:
    a = 1.7
    tet = regular_tetrahedron(a)
    assert element_measures(tet, [[0, 1, 2, 3]], "tetrahedra")[0] == pytest.approx(a**3 / (6 * math.sqrt(2)))
    assert element_measures(CUBE, HEXA, "hexahedra")[0] == pytest.approx(1.0, abs=1e-15)
    assert element_measures(CUBE, CUBE_TETS, "tetrahedra").sum() == pytest.approx(1.0, abs=1e-15)
    # A sheared, scaled box (parallelepiped): |det| of its edge vectors.
    frame = np.array([[2.0, 0.3, 0.1], [0.2, 1.5, -0.4], [0.5, 0.1, 0.7]])
    box = CUBE @ frame + [3, -1, 2]
    assert element_measures(box, HEXA, "hexahedra")[0] == pytest.approx(abs(np.linalg.det(frame)), rel=1e-14)
    # A frustum with square faces a (bottom) and b (top), height h: h (a^2 + ab + b^2) / 3.
    a_, b_, h = 2.0, 0.8, 1.3
    bottom = (CUBE[:4] - [0.5, 0.5, 0]) * [a_, a_, 0]
    top = (CUBE[4:] - [0.5, 0.5, 1]) * [b_, b_, 0] + [0, 0, h]
    frustum = np.vstack([bottom, top])
    expected = h * (a_ * a_ + a_ * b_ + b_ * b_) / 3
    assert element_measures(frustum, HEXA, "hexahedra")[0] == pytest.approx(expected, rel=1e-14)
    # Quads: two triangles; triangles in 2-D are signed, edges are lengths.
    square = CUBE[:4, :2] * 3
    assert element_measures(square, [[0, 1, 2, 3]], "quads")[0] == pytest.approx(9.0)
    assert element_measures(square, [[0, 2, 1]], "triangles")[0] == pytest.approx(-4.5)
    assert element_measures(CUBE, [[0, 6]], "edges")[0] == pytest.approx(math.sqrt(3))


# ---- DiagonalMass ------------------------------------------------------------------------------------


def test_diagonal_mass_cube_of_tetrahedra() -> None:
    density = 2.5
    masses = diagonal_mass(CUBE, tetrahedra=CUBE_TETS, mass_density=density)
    assert masses.sum() == pytest.approx(density * 1.0, rel=1e-15)
    # Vertices 0 and 6 are in all six tetrahedra, the others in two.
    share = density * (1 / 6) / 4
    assert masses == pytest.approx(
        [6 * share, 2 * share, 2 * share, 2 * share, 2 * share, 2 * share, 6 * share, 2 * share]
    )


def test_diagonal_mass_regular_tetra_and_hexa() -> None:
    tet = regular_tetrahedron(2.0)
    volume = 8 / (6 * math.sqrt(2))
    assert diagonal_mass(tet, tetrahedra=[[0, 1, 2, 3]], mass_density=3.0) == pytest.approx(
        [3 * volume / 4] * 4
    )
    assert diagonal_mass(CUBE * 2, hexahedra=HEXA, mass_density=1.0) == pytest.approx([1.0] * 8)
    assert diagonal_mass(CUBE, hexahedra=HEXA, total_mass=4.0) == pytest.approx([0.5] * 8)


def test_diagonal_mass_precedence() -> None:
    notes: list[str] = []
    # totalMass wins over massDensity and vertexMass (SOFA warns).
    masses = diagonal_mass(CUBE, tetrahedra=CUBE_TETS, total_mass=12.0, mass_density=5.0, notes=notes)
    assert masses.sum() == pytest.approx(12.0) and any("totalMass overrides" in n for n in notes)
    # massDensity wins over vertexMass.
    masses = diagonal_mass(CUBE, tetrahedra=CUBE_TETS, mass_density=6.0, vertex_mass=[1.0] * 8)
    assert masses.sum() == pytest.approx(6.0)
    # vertexMass alone is used as given; a short list is padded with its last value.
    assert diagonal_mass(CUBE, tetrahedra=CUBE_TETS, vertex_mass=np.arange(8.0)) == pytest.approx(
        np.arange(8.0)
    )
    assert diagonal_mass(CUBE, tetrahedra=CUBE_TETS, vertex_mass=[1.0, 2.0]) == pytest.approx(
        [1.0] + [2.0] * 7
    )
    # A vertexMass with a negative value, or too long, falls back to totalMass = 1.
    notes.clear()
    masses = diagonal_mass(CUBE, tetrahedra=CUBE_TETS, vertex_mass=[1.0] * 7 + [-1.0], notes=notes)
    assert masses.sum() == pytest.approx(1.0) and notes
    assert diagonal_mass(CUBE, tetrahedra=CUBE_TETS, vertex_mass=[1.0] * 9).sum() == pytest.approx(1.0)
    # A negative massDensity falls back to totalMass = 1; nothing set means totalMass = 1 too.
    assert diagonal_mass(CUBE, tetrahedra=CUBE_TETS, mass_density=-2.0).sum() == pytest.approx(1.0)
    assert diagonal_mass(CUBE * 3, tetrahedra=CUBE_TETS).sum() == pytest.approx(1.0)


def test_diagonal_mass_uses_highest_dimension_elements() -> None:
    # Hexahedra > tetrahedra > quads > triangles > edges: the others are ignored.
    masses = diagonal_mass(
        CUBE,
        hexahedra=HEXA,
        tetrahedra=CUBE_TETS[:1],
        triangles=[[0, 1, 2]],
        edges=[[0, 1]],
        mass_density=1.0,
    )
    assert masses == pytest.approx([1 / 8] * 8)
    masses = diagonal_mass(CUBE, tetrahedra=CUBE_TETS[:1], triangles=[[3, 4, 5]], mass_density=24.0)
    assert masses[[0, 1, 2, 6]] == pytest.approx([1.0] * 4) and not masses[[3, 4, 5, 7]].any()
    masses = diagonal_mass(CUBE[:4], quads=[[0, 1, 2, 3]], triangles=[[0, 1, 2]], mass_density=4.0)
    assert masses == pytest.approx([1.0] * 4)
    masses = diagonal_mass(CUBE[:3], triangles=[[0, 1, 2]], edges=[[0, 1]], mass_density=6.0)
    assert masses == pytest.approx([1.0] * 3)
    assert diagonal_mass(CUBE[:2], edges=[[0, 1]], mass_density=3.0) == pytest.approx([1.5, 1.5])
    # 2-D positions: triangles are fine (SOFA's signed formula), tetrahedra give no mass.
    assert diagonal_mass(CUBE[:3, :2], triangles=[[0, 1, 2]], mass_density=6.0) == pytest.approx([1.0] * 3)
    with pytest.raises(ValueError, match="3-D positions"):
        diagonal_mass(CUBE[:, :2], tetrahedra=CUBE_TETS)


def test_diagonal_mass_degenerate_input() -> None:
    with pytest.raises(ValueError, match="no elements"):
        diagonal_mass(CUBE)
    with pytest.raises(ValueError, match="no elements"):
        diagonal_mass(CUBE, tetrahedra=np.zeros((0, 4), dtype=int), mass_density=1.0)
    flat = CUBE.copy()
    flat[:, 2] = 0.0
    with pytest.raises(ValueError, match="zero"):
        diagonal_mass(flat, tetrahedra=CUBE_TETS, mass_density=1.0)
    with pytest.raises(ValueError, match="zero"):
        diagonal_mass(flat, tetrahedra=CUBE_TETS, total_mass=1.0)
    with pytest.raises(ValueError, match="zero"):
        diagonal_mass(CUBE, tetrahedra=CUBE_TETS, mass_density=0.0)
    with pytest.raises(ValueError, match="negative"):
        diagonal_mass(CUBE, tetrahedra=CUBE_TETS, total_mass=-1.0)
    with pytest.raises(ValueError, match="out of range"):
        diagonal_mass(CUBE, tetrahedra=[[0, 1, 2, 8]])
    with pytest.raises(ValueError, match="shape"):
        diagonal_mass(CUBE, tetrahedra=[[0, 1, 2]])
    with pytest.raises(ValueError, match="finite"):
        diagonal_mass(np.full((4, 3), np.nan), tetrahedra=[[0, 1, 2, 3]])
    # An isolated vertex is not an error (SOFA gives it mass 0) but is noted.
    notes: list[str] = []
    points = np.vstack([CUBE, [[5, 5, 5]]])
    masses = diagonal_mass(points, tetrahedra=CUBE_TETS, mass_density=1.0, notes=notes)
    assert masses[8] == 0.0 and any("no element" in n for n in notes)


# ---- MeshMatrixMass ----------------------------------------------------------------------------------


def test_mesh_matrix_mass_single_tetra_is_the_p1_consistent_matrix() -> None:
    tet = regular_tetrahedron(1.3)
    volume = 1.3**3 / (6 * math.sqrt(2))
    rho = 7.0
    data = mesh_matrix_mass(tet, tetrahedra=[[0, 1, 2, 3]], mass_density=rho)
    expected = rho * volume / 20 * (np.ones((4, 4)) + np.eye(4))
    assert dense(data) == pytest.approx(expected, rel=1e-14)
    assert data.total_mass == pytest.approx(rho * volume) and data.lumping_coefficient == 2.5
    assert data.edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    # Lumped: the row sums on the diagonal (vertex_mass keeps SOFA's rho V / 10).
    lumped = mesh_matrix_mass(tet, tetrahedra=[[0, 1, 2, 3]], mass_density=rho, lumping=True)
    assert lumped.vertex_mass == pytest.approx([rho * volume / 10] * 4)
    assert lumped.lumped_vertex_mass == pytest.approx(expected.sum(axis=1))
    assert not lumped.edge_mass.any() and lumped.total_mass == pytest.approx(rho * volume)


def test_mesh_matrix_mass_cube_totals_and_product() -> None:
    rng = np.random.default_rng(3)
    for kwargs, measure in (
        ({"tetrahedra": CUBE_TETS}, 1.0),
        ({"hexahedra": HEXA}, 1.0),
        ({"quads": [[0, 1, 2, 3], [4, 5, 6, 7]]}, 2.0),
        ({"triangles": [[0, 1, 2], [0, 2, 3]]}, 1.0),
    ):
        data = mesh_matrix_mass(CUBE * 2, mass_density=0.5, **kwargs)
        scale = 8.0 if "tetrahedra" in kwargs or "hexahedra" in kwargs else 4.0
        total = 0.5 * measure * scale
        matrix = dense(data, width=3)
        assert matrix.sum() / 3 == pytest.approx(total, rel=1e-14)
        assert data.total_mass == pytest.approx(total, rel=1e-14)
        # Gravity uses the lumped row sums, which equal the consistent rows' sums.
        assert (data.lumped_vertex_mass * 3) == pytest.approx(matrix.sum(axis=1).reshape(-1, 3).sum(axis=1))
        dx = rng.normal(size=(8, 3))
        assert mesh_matrix_mass_multiply(data.vertex_mass, data.edges, data.edge_mass, dx, factor=-1.5) == (
            pytest.approx(-1.5 * (matrix @ dx.ravel()).reshape(8, 3), rel=1e-13, abs=1e-15)
        )
        assert data.multiply(dx) == pytest.approx((matrix @ dx.ravel()).reshape(8, 3), rel=1e-13, abs=1e-15)
    # Hexahedra: 8 vertex shares V/20 and 12 edges (no diagonals) at V/40, counted twice.
    hexa = mesh_matrix_mass(CUBE, hexahedra=HEXA, total_mass=1.0)
    assert hexa.vertex_mass == pytest.approx([1 / 20] * 8) and hexa.edge_mass == pytest.approx([1 / 40] * 12)


def test_mesh_matrix_mass_precedence_and_edges() -> None:
    data = mesh_matrix_mass(CUBE, tetrahedra=CUBE_TETS, total_mass=3.0, mass_density=100.0)
    assert data.total_mass == 3.0 and data.notes and data.mass_density == pytest.approx([3.0] * 6)
    # Per-element densities.
    data = mesh_matrix_mass(CUBE, tetrahedra=CUBE_TETS, mass_density=[6.0, 0, 0, 0, 0, 0])
    assert data.total_mass == pytest.approx(1.0)
    # Wrong-sized or negative density -> totalMass = 1.
    assert mesh_matrix_mass(CUBE * 5, tetrahedra=CUBE_TETS, mass_density=[1.0, 2.0]).total_mass == 1.0
    assert mesh_matrix_mass(CUBE * 5, tetrahedra=CUBE_TETS, mass_density=-1.0).total_mass == 1.0
    # vertexMass needs lumping or edgeMass; then used as given.
    vm = np.arange(1.0, 9.0)
    lumped = mesh_matrix_mass(CUBE, tetrahedra=CUBE_TETS, vertex_mass=vm, lumping=True)
    assert lumped.vertex_mass == pytest.approx(vm) and lumped.total_mass == pytest.approx(vm.sum())
    unlumped = mesh_matrix_mass(CUBE * 5, tetrahedra=CUBE_TETS, vertex_mass=vm)
    assert unlumped.total_mass == 1.0 and unlumped.notes
    n_edges = len(topology_edges(8, tetrahedra=CUBE_TETS))
    both = mesh_matrix_mass(CUBE, tetrahedra=CUBE_TETS, vertex_mass=vm, edge_mass=np.ones(n_edges))
    assert both.edge_mass == pytest.approx(np.ones(n_edges)) and both.total_mass == pytest.approx(
        vm.sum() + n_edges
    )
    # The topology's own edges are used when given (any order), and must cover the elements.
    own = topology_edges(8, tetrahedra=CUBE_TETS)[::-1]
    data = mesh_matrix_mass(CUBE, tetrahedra=CUBE_TETS, edges=own, mass_density=1.0)
    assert data.edges.tolist() == own.tolist()
    reference = mesh_matrix_mass(CUBE, tetrahedra=CUBE_TETS, mass_density=1.0)
    assert dense(data) == pytest.approx(dense(reference))
    with pytest.raises(ValueError, match="do not contain edge"):
        mesh_matrix_mass(CUBE, tetrahedra=CUBE_TETS, edges=own[1:], mass_density=1.0)
    with pytest.raises(ValueError, match="edge topology"):
        mesh_matrix_mass(CUBE, edges=[[0, 1]])
    with pytest.raises(ValueError, match="no elements"):
        mesh_matrix_mass(CUBE)
    flat = CUBE.copy()
    flat[:, 2] = 0
    with pytest.raises(ValueError, match="zero"):
        mesh_matrix_mass(flat, tetrahedra=CUBE_TETS)


def test_topology_edges_order() -> None:
    # Volumes: first appearance, stored (min, max); surfaces: triangles as met, quads sorted.
    assert topology_edges(4, tetrahedra=[[3, 1, 2, 0]]).tolist() == [
        [1, 3],
        [2, 3],
        [0, 3],
        [1, 2],
        [0, 1],
        [0, 2],
    ]
    assert topology_edges(4, triangles=[[0, 1, 2], [2, 1, 3]]).tolist() == [
        [1, 2],
        [2, 0],
        [0, 1],
        [1, 3],
        [3, 2],
    ]
    assert topology_edges(4, quads=[[3, 2, 1, 0]]).tolist() == [[1, 2], [0, 1], [0, 3], [2, 3]]
    assert len(topology_edges(8, hexahedra=HEXA)) == 12


# ---- Demos/liver.scn ---------------------------------------------------------------------------------


def test_liver_diagonal_mass(corpus_dir: Path) -> None:
    """Demos/liver.scn: DiagonalMass massDensity=1 on liver.msh's tetrahedra."""
    mesh = meshes.read_mesh(corpus_dir / "mesh" / "liver.msh")
    masses = diagonal_mass(mesh.positions, tetrahedra=mesh.tetrahedra, mass_density=1.0)
    p = mesh.positions[mesh.tetrahedra]
    volumes = np.abs(np.linalg.det(p[:, 1:] - p[:, :1])) / 6
    assert masses.shape == (181,) and (masses > 0).all()
    assert masses.sum() == pytest.approx(volumes.sum(), rel=1e-13)
    assert element_measures(mesh.positions, mesh.tetrahedra, "tetrahedra") == pytest.approx(
        volumes, rel=1e-12
    )
    expected = np.zeros(181)
    np.add.at(expected, mesh.tetrahedra.ravel(), np.repeat(volumes / 4, 4))
    assert masses == pytest.approx(expected, rel=1e-12)
    # MeshMatrixMass on the same mesh: the same total, lumped rows = DiagonalMass.
    data = mesh_matrix_mass(mesh.positions, tetrahedra=mesh.tetrahedra, mass_density=1.0)
    assert data.total_mass == pytest.approx(volumes.sum(), rel=1e-13)
    assert data.lumped_vertex_mass == pytest.approx(masses, rel=1e-12)


@pytest.mark.parametrize(("numbers", "warned"), [(11, False), (12, True), (14, True)])
def test_a_rigid_mass_with_trailing_numbers_reads_the_first_eleven_as_sofa(
    tmp_path: Path, numbers: int, warned: bool
) -> None:
    """RigidMass's operator>> reads m, volume and the 3x3 inertia; Data::read ignores what follows
    (SOFA's BilateralLagrangianConstraint_Rigid.scn writes 12 numbers)."""
    from sofac.pipeline import check_file, plan_file

    mass = [2.0, 1.0, 0.01, 0, 0, 0, 0.1, 0, 0, 0, 0.1, 0, 7, 7][:numbers]
    scene = tmp_path / "rigid.scn"
    scene.write_text(
        '<Node name="root" dt="0.01"><DefaultAnimationLoop/><EulerImplicitSolver/>\n'
        '<CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/>\n'
        '<MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1"/>\n'
        f'<UniformMass name="mass" vertexMass="{" ".join(str(x) for x in mass)}"/>\n</Node>\n'
    )
    _, diagnostics = check_file(scene)
    found = [(d.code, d.loc.line) for d in diagnostics.sorted()]
    assert found == ([("W225", 4)] if warned else [])
    with pytest.warns() if warned else contextlib.nullcontext():
        buffers = {b.key: b.initial for b in plan_file(scene).buffers}
    # the mass, then m times the inertia matrix
    assert buffers["/mass.vertexMass"].tolist() == [2.0, 0.02, 0, 0, 0, 0.2, 0, 0, 0, 0.2]
