"""Patch tests of every finite element sofac compiles, through compiled scenes.

A box meshed with a 4 x 4 x 4 grid of nodes (8 interior nodes, moved off the grid so that the
elements are distorted) is given a linear displacement field. Its internal forces must be those of
the constant stress sigma = lambda tr(eps) I + 2 mu eps, eps = sym(A):

- at interior nodes, zero (to round-off): the element forces balance;
- at a boundary node i, f_i = -integral over the boundary of N_i sigma n dA, the exact nodal
  traction (N_i: the shape function of node i on the boundary faces; linear on the tetrahedra's
  triangles, area / 3 each; bilinear on the hexahedra's rectangles, area / 4 each).

Linear (small-strain) elements get a general A (with a rotation part) and a translation:
f = -K u exactly. Corotational elements get a symmetric strain S, then a large rigid rotation Q
and a translation on top, x = Q (I + S) X + b: their forces are the rotated small-strain ones, Q f(S), up to
O(|S|^2). None of SOFA's element rotations is the polar factor of the deformation gradient F (the
"large" / "triangle" / "hexahedron" frames are built from a few edges; "polar", "svd" and
"stable_polar" decompose F times an element-shape matrix), so a homogeneous strain turns each
distorted element's frame by its own O(|S|) angle: the forces relative to their size must be
O(|S|) off, and the error must fall in proportion to |S| (measured: 1.4e-4 to 5.9e-4 at
|S| = 1e-3, ten times less at 1e-4, for every variant). A pure rigid motion (S = 0) gives zero
force to round-off (tests/test_fem_kernels.py, tests/test_element_fem.py).

Forces are read through sofac.load: every variant is a node of one scene, stepped once by explicit
Euler from rest with unit nodal masses and dt = 1, so that each node's new velocity is its force.
"""

from __future__ import annotations

import numpy as np
import pytest
import sofac
from sofac.geometry.fem_topology import hexahedra_from_grid, tetrahedra_from_grid

YOUNG, NU = 3000.0, 0.3
COUNTS = (4, 4, 4)
SIZE = np.array([1.0, 0.8, 1.2])

# name -> (kind, component line); {e} and {nu} are filled in.
TET_VARIANTS = {
    "tet_small": 'TetrahedronFEMForceField method="small"',
    "tet_large": 'TetrahedronFEMForceField method="large"',
    "tet_polar": 'TetrahedronFEMForceField method="polar"',
    "tet_svd": 'TetrahedronFEMForceField method="svd"',
    "corot_small": 'TetrahedralCorotationalFEMForceField method="small"',
    "corot_large": 'TetrahedralCorotationalFEMForceField method="large"',
    "corot_polar": 'TetrahedralCorotationalFEMForceField method="polar"',
    "elem_tet_linear": 'LinearSmallStrainFEMForceField template="Vec3d,Tetrahedron"',
    "elem_tet_corot": 'CorotationalFEMForceField template="Vec3d,Tetrahedron"',
    "elem_tet_polar": 'CorotationalFEMForceField template="Vec3d,Tetrahedron" rotationMethod="polar"',
    "elem_tet_stable": 'CorotationalFEMForceField template="Vec3d,Tetrahedron" rotationMethod="stable_polar"',
}
HEX_VARIANTS = {
    "hex_small": 'HexahedronFEMForceField method="small"',
    "hex_large": 'HexahedronFEMForceField method="large"',
    "hex_polar": 'HexahedronFEMForceField method="polar"',
    "elem_hex_linear": 'LinearSmallStrainFEMForceField template="Vec3d,Hexahedron"',
    "elem_hex_corot": 'CorotationalFEMForceField template="Vec3d,Hexahedron"',
    "elem_hex_polar": 'CorotationalFEMForceField template="Vec3d,Hexahedron" rotationMethod="polar"',
    "elem_hex_stable": 'CorotationalFEMForceField template="Vec3d,Hexahedron" rotationMethod="stable_polar"',
}
LINEAR = {"tet_small", "corot_small", "elem_tet_linear", "hex_small", "elem_hex_linear"}


def patch_points() -> np.ndarray:
    nx, ny, nz = COUNTS
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    grid = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
    points = grid / (np.asarray(COUNTS) - 1) * SIZE
    interior = ((grid > 0) & (grid < np.asarray(COUNTS) - 1)).all(axis=1)
    spacing = SIZE / (np.asarray(COUNTS) - 1)
    offsets = np.random.default_rng(21).uniform(-0.2, 0.2, (int(interior.sum()), 3)) * spacing
    points[interior] += offsets
    return points


def interior_mask() -> np.ndarray:
    points = patch_points()
    eps = 1e-9
    on_boundary = ((points < eps) | (points > SIZE - eps)).any(axis=1)
    return ~on_boundary


def boundary_faces(elements: np.ndarray, faces: list[list[int]]) -> np.ndarray:
    """The element faces that belong to one element only."""
    all_faces = np.concatenate([elements[:, f] for f in faces])
    _, first, counts = np.unique(np.sort(all_faces, axis=1), axis=0, return_index=True, return_counts=True)
    return all_faces[first[counts == 1]]


TET_FACES = [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]
HEX_FACES = [[0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]


def stress(strain: np.ndarray) -> np.ndarray:
    lam = YOUNG * NU / ((1 + NU) * (1 - 2 * NU))
    mu = YOUNG / (2 * (1 + NU))
    return lam * np.trace(strain) * np.eye(3) + 2 * mu * strain


def traction_forces(points: np.ndarray, faces: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """-integral of N_i sigma n over the box's boundary, face by face (flat boundary faces)."""
    forces = np.zeros_like(points)
    centre = SIZE / 2
    for face in faces:
        p = points[face]
        if len(face) == 3:
            area_vector = np.cross(p[1] - p[0], p[2] - p[0]) / 2
        else:  # a rectangle: the bilinear shape functions integrate to area / 4
            area_vector = np.cross(p[1] - p[0], p[3] - p[0])
            assert np.allclose(p[2] - p[1], p[3] - p[0])
        if area_vector @ (p.mean(axis=0) - centre) < 0:
            area_vector = -area_vector  # outward
        forces[face] -= sigma @ area_vector / len(face)
    return forces


def scene_text(kind: str, variants: dict[str, str], elements: np.ndarray) -> str:
    points = patch_points()
    position = " ".join(repr(float(v)) for v in points.ravel())
    topology = "tetrahedra" if kind == "tet" else "hexahedra"
    indices = " ".join(str(int(v)) for v in elements.ravel())
    nodes = []
    for name, component in variants.items():
        nodes.append(
            f'  <Node name="{name}"><EulerExplicitSolver symplectic="0"/>\n'
            f'    <MeshTopology name="mesh" position="{position}" {topology}="{indices}"/>\n'
            '    <MechanicalObject template="Vec3d" name="dofs"/>\n'
            '    <UniformMass vertexMass="1"/>\n'
            f'    <{component} name="fem" youngModulus="{YOUNG!r}" poissonRatio="{NU!r}"/>\n'
            "  </Node>\n"
        )
    return f'<Node name="root" gravity="0 0 0" dt="1"><DefaultAnimationLoop/>\n{"".join(nodes)}</Node>\n'


def forces_of(
    sim: sofac.Simulation, variants: list[str], placed: dict[str, np.ndarray]
) -> dict[str, np.ndarray]:
    sim.reset()
    for name in variants:
        sim[f"{name}/dofs"].position[:] = placed[name]
    sim.step(1)
    return {name: sim[f"{name}/dofs"].velocity.copy() for name in variants}


@pytest.fixture(scope="module", params=["tet", "hex"])
def patch(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> tuple:
    kind = request.param
    if kind == "tet":
        elements, variants, faces = tetrahedra_from_grid(COUNTS), TET_VARIANTS, TET_FACES
    else:
        elements, variants, faces = hexahedra_from_grid(COUNTS), HEX_VARIANTS, HEX_FACES
    path = tmp_path_factory.mktemp("patch") / f"patch_{kind}.scn"
    path.write_text(scene_text(kind, variants, elements))
    sim = sofac.load(path)
    return sim, list(variants), boundary_faces(np.asarray(elements), faces)


def rotation(axis: list[float], angle: float) -> np.ndarray:
    axis_ = np.asarray(axis) / np.linalg.norm(axis)
    k = np.array([[0, -axis_[2], axis_[1]], [axis_[2], 0, -axis_[0]], [-axis_[1], axis_[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def test_boundary_faces_cover_the_box(patch: tuple) -> None:
    _, _, faces = patch
    points = patch_points()
    area = 0.0
    for face in faces:
        p = points[face]
        area += np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])) / (2 if len(face) == 3 else 1)
    sx, sy, sz = SIZE
    assert area == pytest.approx(2 * (sx * sy + sy * sz + sz * sx), rel=1e-12)


def test_linear_elements_pass_the_patch_test(patch: tuple) -> None:
    sim, variants, faces = patch
    linear = [v for v in variants if v in LINEAR]
    rest = patch_points()
    a = np.array([[0.8, -0.3, 0.5], [0.2, -0.6, 0.1], [-0.4, 0.7, 0.3]]) * 1e-2
    placed = rest + rest @ a.T + [0.3, -0.2, 0.1]
    forces = forces_of(sim, linear, dict.fromkeys(linear, placed))
    expected = traction_forces(rest, faces, stress(0.5 * (a + a.T)))
    interior = interior_mask()
    scale = np.abs(expected).max()
    assert scale > 1.0
    for name in linear:
        f = forces[name]
        assert np.abs(f[interior]).max() < 1e-11 * scale, name
        assert np.abs(f - expected).max() < 1e-11 * scale, name


def corotational_errors(patch: tuple, strain_scale: float) -> dict[str, tuple[float, float]]:
    """(interior force, max error to Q f(S)) relative to max |Q f(S)|, per corotational variant."""
    sim, variants, faces = patch
    corotational = [v for v in variants if v not in LINEAR]
    rest = patch_points()
    s = np.array([[0.9, 0.3, -0.2], [0.3, -0.5, 0.4], [-0.2, 0.4, 0.6]]) * strain_scale
    q = rotation([1.0, -2.0, 0.7], 1.3)
    placed = (rest + rest @ s.T) @ q.T + [1.5, -0.4, 2.0]
    forces = forces_of(sim, corotational, dict.fromkeys(corotational, placed))
    expected = traction_forces(rest, faces, stress(s)) @ q.T
    interior = interior_mask()
    scale = np.abs(expected).max()
    return {
        name: (np.abs(forces[name][interior]).max() / scale, np.abs(forces[name] - expected).max() / scale)
        for name in corotational
    }


def test_corotational_elements_pass_the_patch_test_under_rotation(patch: tuple) -> None:
    coarse = corotational_errors(patch, 1e-3)
    fine = corotational_errors(patch, 1e-4)
    for name, (interior, error) in coarse.items():
        # O(|S|) relative to the force (second order absolutely), and falling in proportion to |S|
        assert error < 1e-3 and interior < 1e-3, (name, interior, error)
        assert 0.08 * error < fine[name][1] < 0.12 * error, (name, fine[name][1], error)
        assert fine[name][0] < 0.12 * interior, (name, fine[name][0], interior)
