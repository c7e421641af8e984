"""HexahedronFEMForceField(AndMass) on a SparseGridTopology: SOFA scales each cell's element stiffness
(and masses) by the grid's coefficient, 0.5 for a BOUNDARY cell when fillWeighted (the default), 1
otherwise (SparseGridTopology::buildAsFinest). Checked on a closed cube voxelised into 56 BOUNDARY
cells around 8 INSIDE ones: against the same FEM on the explicit hexahedral mesh with each cell's
Young's modulus scaled, against hand-computed masses, and on SOFA's tutorials that use it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.front import meshes
from sofac.geometry import voxelize
from sofac.geometry.barycentric import RegularGrid

# The surface [0.5, 3.5]^3 in a grid of unit cells from -1 to 5 (see test_voxelize.py).
GRID = 'n="7 7 7" min="-1 -1 -1" max="5 5 5"'
FEM_SCENE = """<Node name="root" dt="0.02" gravity="30 -20 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
  <CGLinearSolver iterations="500" tolerance="1e-25" threshold="1e-25"/>
  {topology}
  <MechanicalObject name="state"/>
  <UniformMass totalMass="50"/>
  <HexahedronFEMForceField youngModulus="{young}" poissonRatio="0.3" method="{method}"/>
  <FixedProjectiveConstraint indices="{fixed}"/>
</Node>
"""
MASS_SCENE = """<Node name="root" dt="0.01" gravity="0 -9.81 0">
  <DefaultAnimationLoop/>
  <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
  <CGLinearSolver iterations="500" tolerance="1e-30" threshold="1e-30"/>
  <SparseGridTopology fileTopology="cube.obj" {grid} fillWeighted="{fill}"/>
  <MechanicalObject name="state" position="0 0 0"/>
  <HexahedronFEMForceFieldAndMass youngModulus="1000" poissonRatio="0.3" density="{rho}"
    lumpedMass="{lumped}"/>
</Node>
"""


# The surface's 8 corners and 6 outward quads.
CORNERS = np.array([[x, y, z] for z in (0.5, 3.5) for y in (0.5, 3.5) for x in (0.5, 3.5)])
QUADS = np.array([(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)])


def _cube_obj(folder: Path) -> None:
    lines = [f"v {x} {y} {z}" for x, y, z in CORNERS] + [
        f"f {a + 1} {b + 1} {c + 1} {d + 1}" for a, b, c, d in QUADS
    ]
    (folder / "cube.obj").write_text("\n".join(lines) + "\n")


def _sparse_cube() -> voxelize.SparseGrid:
    grid = RegularGrid((7, 7, 7), (-1.0, -1.0, -1.0), (5.0, 5.0, 5.0))
    triangles = voxelize.triangulate(np.zeros((0, 3), dtype=np.int64), QUADS)
    return voxelize.sparse_grid(voxelize.classify(grid, CORNERS, triangles))


def _expected_coefficients(points: np.ndarray, hexahedra: np.ndarray) -> np.ndarray:
    """From the geometry alone: the cells within [1, 3]^3 lie inside the surface, the others cut it."""
    corners = points[hexahedra]  # (cells, 8, 3)
    inside = ((corners >= 1) & (corners <= 3)).all(axis=(1, 2))
    return np.where(inside, 1.0, 0.5)


def _numbers(values: np.ndarray) -> str:
    """Scene text for an array: integers as such, floats in their exact repr."""
    if np.issubdtype(values.dtype, np.integer):
        return " ".join(str(int(v)) for v in values.ravel())
    return " ".join(repr(float(v)) for v in values.ravel())


def test_cell_coefficients_of_a_closed_cube() -> None:
    """The 56 BOUNDARY cells get 0.5 and the 8 INSIDE ones 1 (all 1 without fillWeighted)."""
    sparse = _sparse_cube()
    weights = voxelize.cell_coefficients(sparse.boundary, True)
    assert np.array_equal(weights, _expected_coefficients(sparse.points, sparse.hexahedra))
    assert weights.sum() == 56 * 0.5 + 8
    assert (voxelize.cell_coefficients(sparse.boundary, False) == 1.0).all()


def _run_fem(tmp_path: Path, name: str, topology: str, young: str, method: str, steps: int) -> np.ndarray:
    points = _sparse_cube().points
    fixed = np.flatnonzero(points[:, 1] == 0)  # the bottom face y = 0
    scene = tmp_path / f"{name}.scn"
    scene.write_text(FEM_SCENE.format(topology=topology, young=young, method=method, fixed=_numbers(fixed)))
    sim = sofac.load(scene)
    sim.step(steps)
    return np.asarray(sim["/state"].position).copy()


@pytest.mark.parametrize("method", ["large", "polar", "small"])
def test_sparse_grid_fem_is_the_mesh_fem_with_weighted_cells(tmp_path: Path, method: str) -> None:
    """A cube fixed at its bottom, pushed sideways, 5 implicit steps: on the sparse grid, exactly (to
    the bit: a factor 0.5 on Ke or on E is exact) the FEM on the explicit mesh of its hexahedra with
    E halved on the boundary cells; not the mesh with a uniform E; and fillWeighted=false is."""
    _cube_obj(tmp_path)
    sparse = _sparse_cube()
    weights = _expected_coefficients(sparse.points, sparse.hexahedra)
    mesh = f'<MeshTopology position="{_numbers(sparse.points)}" hexahedra="{_numbers(sparse.hexahedra)}"/>'
    grid = f'<SparseGridTopology fileTopology="cube.obj" {GRID}/>'
    unweighted = f'<SparseGridTopology fileTopology="cube.obj" {GRID} fillWeighted="false"/>'
    on_grid = _run_fem(tmp_path, "grid", grid, "1000", method, 5)
    on_mesh = _run_fem(tmp_path, "mesh", mesh, _numbers(1000.0 * weights), method, 5)
    assert np.array_equal(on_grid, on_mesh)
    uniform = _run_fem(tmp_path, "uniform", mesh, "1000", method, 5)
    moved = np.abs(uniform - sparse.points).max()
    assert moved > 0.05  # the load deforms the cube visibly
    assert np.abs(on_grid - uniform).max() > 0.05 * moved  # half-stiff boundary cells: a softer cube
    assert np.array_equal(_run_fem(tmp_path, "unweighted", unweighted, "1000", method, 5), uniform)


@pytest.mark.parametrize("lumped", [False, True])
@pytest.mark.parametrize("fill", [True, False])
def test_sparse_grid_masses_are_weighted(tmp_path: Path, lumped: bool, fill: bool) -> None:
    """HexahedronFEMForceFieldAndMass: each cell's particle masses (vol rho / 8 per corner, its
    weight) and element mass (vol rho 8/27 on each node pair) times the cell's coefficient. The
    initial potential energy is the weight's, -sum m_i g.x_i; after one free-fall step every node
    has dv = h g 27/512, and the kinetic energy 1/2 v^T M v counts 64 node pairs per cell."""
    _cube_obj(tmp_path)
    rho = 3.0
    scene = tmp_path / "mass.scn"
    scene.write_text(
        MASS_SCENE.format(grid=GRID, fill=str(fill).lower(), rho=rho, lumped=str(lumped).lower())
    )
    sim = sofac.load(scene)
    sparse = _sparse_cube()
    points = np.asarray(sim["/state"].position)
    assert np.array_equal(points, sparse.points)  # position="0 0 0" gives way to the grid's points
    weights = _expected_coefficients(sparse.points, sparse.hexahedra) if fill else np.ones(64)
    particle = np.zeros(len(points))
    np.add.at(particle, sparse.hexahedra, np.repeat(weights * rho / 8.0, 8).reshape(-1, 8))
    assert sim.energy().potential == pytest.approx(9.81 * (particle * points[:, 1]).sum(), rel=1e-12)
    sim.step(1)
    dv = 0.01 * -9.81 * 27.0 / 512.0
    velocity = np.asarray(sim["/state"].velocity)
    assert np.abs(velocity[:, 1] - dv).max() < 1e-12 and np.abs(velocity[:, [0, 2]]).max() < 1e-12
    kinetic = 0.5 * dv**2 * (64 * rho * 8.0 / 27.0 * weights).sum()
    assert sim.energy().kinetic == pytest.approx(kinetic, rel=1e-10)


# ---- SOFA's tutorials on sparse grids ------------------------------------------------------------

LIVER = "Tutorials/ForceFields/TutorialForceFieldLiverHexaFEM.scn"
FULL_OBJECT = "Tutorials/StepByStep/FullObject/{}_FullObject.scn"


def test_liver_hexa_fem_hangs_stably(corpus_dir: Path) -> None:
    """TutorialForceFieldLiverHexaFEM (polar HexahedronFEMForceField on an 8x6x6 sparse grid of the
    liver, 3 fixed points): 100 steps stay finite, the liver sags under gravity and settles."""
    sim = sofac.load(corpus_dir / LIVER)
    rest = np.asarray(sim["/LiverHexaFEM/dofs"].position).copy()
    assert rest.shape == (218, 3)
    kinetic = []
    for _ in range(100):
        sim.step(1)
        kinetic.append(sim.energy().kinetic)
    x = np.asarray(sim["/LiverHexaFEM/dofs"].position)
    assert np.isfinite(x).all()
    moved = np.abs(x - rest).max()
    assert 0.05 < moved < 1.0  # a sag, small next to the liver's size (about 10)
    assert (x[[81, 80, 166]] == rest[[81, 80, 166]]).all()
    assert kinetic[-1] < 0.2 * max(kinetic)  # the motion is damped out


def _free_fall(steps: int, h: float, g: float, rayleigh_mass: float) -> tuple[float, float]:
    """Velocity and displacement of a rigid translation under implicit Euler with Rayleigh mass
    damping: (1 + h rm) M dv = h (M g - rm M v), x += h v (a translation has no stiffness)."""
    v = x = 0.0
    for _ in range(steps):
        v += h * (g - rayleigh_mass * v) / (1 + h * rayleigh_mass)
        x += h * v
    return v, x


def _check_free_fall(sim: sofac.Simulation, rest: np.ndarray, steps: int) -> None:
    """The dragon falls along the root's gravity (0 0 -9.81) as one rigid body over ``steps``."""
    v, dz = _free_fall(steps, 0.005, -9.81, 0.1)
    velocity = np.asarray(sim["/Object/Particles"].velocity)
    x = np.asarray(sim["/Object/Particles"].position)
    assert np.isfinite(x).all()
    assert np.abs(velocity[:, 2] - v).max() < 1e-6 * abs(v)
    assert np.abs(x[:, 2] - rest[:, 2] - dz).max() < 1e-6 * abs(dz)
    assert np.abs(x[:, :2] - rest[:, :2]).max() < 1e-6


def test_full_object_4_falls_freely(corpus_dir: Path) -> None:
    """4_FullObject: HexahedronFEMForceField (large) on a sparse grid of the dragon whose state says
    position="0 0 0" (SOFA takes the grid's 171 points instead); before reaching the plane at
    z = -10 it falls as a rigid body, as implicit Euler with rayleighMass 0.1 gives it."""
    sim = sofac.load(corpus_dir / FULL_OBJECT.format(4))
    rest = np.asarray(sim["/Object/Particles"].position).copy()
    assert rest.shape == (171, 3)
    sim.step(100)
    _check_free_fall(sim, rest, 100)


@pytest.mark.parametrize("k", [6, 8])
def test_full_object_with_collision_models(corpus_dir: Path, tmp_path: Path, k: int) -> None:
    """6_ and 8_FullObject compile: their position="0 0 0" states take the sparse grid's points, and
    the collision meshes mapped onto them sit where their files put them. With the obstacle (whose
    contact sofac does not compile: its guard stops the scene) removed, 100 steps fall freely."""
    scene = corpus_dir / FULL_OBJECT.format(k)
    sim = sofac.load(scene)
    rest = np.asarray(sim["/Object/Particles"].position).copy()
    assert rest.shape == (171, 3)
    mapped = np.asarray(sim["/Object/CollisionNode/CollisionObject"].position)
    surface = meshes.read_mesh(corpus_dir / "mesh" / ("cube.obj" if k == 6 else "dragon.obj")).positions
    assert np.abs(mapped - surface * (6.0 if k == 6 else 1.0)).max() < 1e-9
    text = scene.read_text()
    start = text.index('<Node name="Obstacle"')
    alone = tmp_path / f"{k}_FullObject_alone.scn"
    alone.write_text(text[:start] + text[text.index("</Node>", start) + len("</Node>") :])
    sim = sofac.load(alone, data_roots=[corpus_dir])
    sim.step(100)
    _check_free_fall(sim, rest, 100)


@pytest.mark.parametrize(
    "component",
    ['TetrahedronFEMForceField youngModulus="1000"', 'DiagonalMass massDensity="1"'],
)
def test_other_components_on_a_sparse_grid_are_refused(tmp_path: Path, component: str) -> None:
    """What reads a sparse grid's cells without its coefficients is not compiled: a clear E222."""
    _cube_obj(tmp_path)
    scene = tmp_path / "refused.scn"
    scene.write_text(
        '<Node name="root" dt="0.01">\n  <EulerImplicitSolver/> <CGLinearSolver/>\n'
        f'  <SparseGridTopology fileTopology="cube.obj" {GRID}/>\n  <MechanicalObject/>\n'
        f"  <UniformMass/>\n  <{component}/>\n</Node>\n"
    )
    with pytest.raises(sofac.SceneError, match=r"E222.*on a SparseGridTopology it is not compiled yet"):
        sofac.load(scene)
