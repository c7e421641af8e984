"""Lagrangian (FreeMotionAnimationLoop) contact's hard cases, each against a closed-form answer:
more contacts than the rows reserved at creation (the capacity grows, no contact dropped), a resting
stack, a mass ratio of 1e4 (the Gauss-Seidel solve hits its iteration limit: reported with its
residual), and a rank-deficient W (a rigid cube's face: 12 rows on 6 DOFs).

Units: every contact holds its body up with the impulse m g dt per step, at the contact distance
(UnilateralLagrangianConstraint: dfree = (P - Q).n - contactDistance)."""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import sofac
from lagrangian_scenes import CONTACT, DT, G, contact_root, particles, static_floor
from sofac.simulation.loader import ContactWarning

MASS = 0.01  # each particle's


def _header(mu: float, solver: str) -> str:
    return contact_root(solver, mu) + static_floor("-3 0 -3  3 0 -3  3 0 3  -3 0 3")


def grid(n: int, x0: float, z0: float) -> np.ndarray:
    """n x n particles 0.1 apart, 3 cm above their rest height (off the floor's diagonal x = z)."""
    i, k = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    x, z = x0 + 0.1 * i.ravel(), z0 + 0.1 * k.ravel()
    return np.column_stack([x, np.full(n * n, CONTACT + 0.03), z])


BGS = '<BlockGaussSeidelConstraintSolver tolerance="1e-12" maxIterations="1000"/>'


NNCG = '<NNCGConstraintSolver tolerance="1e-12" maxIterations="1000"/>'
LCP = '<LCPConstraintSolver maxIt="1000" tolerance="1e-12" initial_guess="true" build_lcp="true" mu="0.5"/>'


def grids_scene(path: Path, solver: str = BGS) -> Path:
    """A 20 x 20 grid (400 contacts of 3 rows: 1200 rows, past the 384 reserved) and a 5 x 5 one."""
    text = _header(0.5, solver)
    text += particles("Big", grid(20, -2.5, 0.05), MASS)
    text += particles("Small", grid(5, 1.0, -1.9), MASS)
    path.write_text(text + "</Node>\n")
    return path


STACK = 3


def stack_scene(path: Path) -> Path:
    """Three particles stacked one contact distance apart on the floor (point-point contacts), and a
    rigid cube resting on its four bottom corners (12 rows on 6 DOFs)."""
    text = _header(0.5, BGS)
    for k in range(STACK):
        text += particles(f"P{k}", np.array([[-1.0, CONTACT * (k + 1), 0.5]]), MASS)
    half = 0.1
    corners = [[sx * half, -half, sz * half] for sx in (-1, 1) for sz in (-1, 1)]
    text += f"""    <Node name="Cube">
        <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0" />
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-20" />
        <MechanicalObject name="dofs" template="Rigid3d" position="1 {half + CONTACT!r} -1  0 0 0 1" />
        <UniformMass totalMass="{CUBE_MASS!r}" />
        <UncoupledConstraintCorrection />
        <Node name="Corners">
            <MechanicalObject name="points" position="{"  ".join(" ".join(map(repr, c)) for c in corners)}" />
            <PointCollisionModel />
            <RigidMapping />
        </Node>
    </Node>
"""
    path.write_text(text + "</Node>\n")
    return path


CUBE_MASS = 2.0
HEAVY, LIGHT = 1e4 * MASS, MASS
LIMIT = 1000


def ratio_scene(path: Path) -> Path:
    """Mass ratio 1e4 on the floor: a heavy particle resting on a light one (the Gauss-Seidel sweep
    contracts by 1 / (1 + 1e-4) only: it hits its iteration limit), and a light one on a heavy one
    (it converges at once)."""
    solver = f'<BlockGaussSeidelConstraintSolver tolerance="1e-12" maxIterations="{LIMIT}"/>'
    text = _header(0.5, solver)
    text += particles("Light", np.array([[0.5, CONTACT, 0.2]]), LIGHT)
    text += particles("Heavy", np.array([[0.5, 2 * CONTACT, 0.2]]), HEAVY)
    text += particles("Base", np.array([[-0.5, CONTACT, 0.7]]), HEAVY)
    text += particles("Top", np.array([[-0.5, 2 * CONTACT, 0.7]]), LIGHT)
    path.write_text(text + "</Node>\n")
    return path


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("lagrangian")


def _report(sim: sofac.Simulation) -> np.ndarray:
    return sim.output("/CollisionPipeline3.contactReport")


@pytest.mark.parametrize("name", ["BGS", "NNCG", "LCP"])
def test_more_contacts_than_reserved_rows_grow_the_capacity(folder: Path, name: str) -> None:
    # the solvers on the grown W, dfree, f, d and scratch: BlockGaussSeidel, NNCG, LCP built with
    # its initial guess (the previous forces, kept by persistent id in the grown lists)
    sim = sofac.load(grids_scene(folder / f"grids_{name}.scn", {"BGS": BGS, "NNCG": NNCG, "LCP": LCP}[name]))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sim.step(30)  # landed (a plastic impact) within 5 steps, then at rest
    grown = [w for w in caught if issubclass(w.category, ContactWarning)]
    assert len(grown) == 1 and "were grown" in str(grown[0].message), [str(w.message) for w in caught]
    assert _report(sim)[1] == 1  # one growth: 384 rows doubled twice, to 1536, in one step
    for _ in range(20):
        sim.step(1)
        assert _report(sim)[0] == 425  # every contact kept
        big, small = sim["/Big/dofs"], sim["/Small/dofs"]
        # both grids at the contact distance, at rest
        assert np.abs(big.position[:, 1] - CONTACT).max() < 1e-12
        assert np.abs(small.position[:, 1] - CONTACT).max() < 1e-12
        assert np.abs(big.velocity).max() < 1e-12 and np.abs(small.velocity).max() < 1e-12
        f = sim.output("/.constraint_f")
        assert f.size >= 3 * 425
        # each contact: the normal impulse m g dt, no tangential one
        assert np.allclose(f[0 : 3 * 425 : 3], MASS * G * DT, rtol=1e-12, atol=0)
        assert np.abs(f[1 : 3 * 425 : 3]).max() < 1e-15 and np.abs(f[2 : 3 * 425 : 3]).max() < 1e-15
    assert _report(sim)[1] == 1  # no growth since
    kept = sim.output("/.constraint_f")  # a view of the grown buffer
    sim.reset()  # the grown buffers stay; the pipeline's own reserve grows again (reported)
    with pytest.warns(ContactWarning, match="were grown"):
        sim.step(30)
    assert sim.output("/.constraint_f").size == kept.size == 1536
    assert np.allclose(kept[0 : 3 * 425 : 3], MASS * G * DT, rtol=1e-12, atol=0)
    assert np.abs(sim["/Big/dofs"].position[:, 1] - CONTACT).max() < 1e-12


@pytest.fixture(scope="module")
def stack(folder: Path) -> Iterator[sofac.Simulation]:
    yield sofac.load(stack_scene(folder / "stack.scn"))


def test_a_resting_stack_stays_stacked(stack: sofac.Simulation) -> None:
    start = [stack[f"/P{k}/dofs"].position[0].copy() for k in range(STACK)]
    for _ in range(5):
        stack.step(100)
        for k in range(STACK):
            p = stack[f"/P{k}/dofs"]
            # each body at (k + 1) contact distances: drift below 1e-12 over 500 steps
            assert np.abs(p.position[0] - start[k]).max() < 1e-12
            assert np.abs(p.velocity[0]).max() < 1e-12
    report = stack.output("/FreeMotionAnimationLoop1.constraint_report")
    assert report[3] == 0  # no solve hit its iteration limit


def test_a_stack_carries_its_weight_down(stack: sofac.Simulation) -> None:
    stack.step(1)
    f = stack.output("/.constraint_f")
    contacts = stack.output("/CollisionPipeline3.contactReport")[0]
    normals = np.sort(f[0 : 3 * int(contacts) : 3])
    normals = normals[normals > 0]
    # the floor carries three weights, the next contact two, the top one one: k m g dt
    assert np.allclose(normals[:STACK], MASS * G * DT * np.arange(1, STACK + 1), rtol=1e-9)


def test_a_cube_resting_on_four_corners_converges(stack: sofac.Simulation) -> None:
    cube = stack["/Cube/dofs"]
    start = cube.position[0].copy()
    stack.step(500)
    assert np.isfinite(cube.position).all()
    # 12 rows (4 corners, mu 0.5) on 6 DOFs: W is rank-deficient, the solve still converges
    assert stack.output("/FreeMotionAnimationLoop1.constraint_report")[3] == 0
    f = stack.output("/.constraint_f")
    rows = 3 * int(_report(stack)[0])
    normal, tangent = f[0:rows:3], np.hypot(f[1:rows:3], f[2:rows:3])
    assert (tangent <= 0.5 * normal * (1 + 1e-12) + 1e-18).all()  # Coulomb's cone
    # all normal impulses: the stack's (1 + 2 + 3) m g dt and the cube's weight M g dt
    assert np.isclose(normal.sum(), (6 * MASS + CUBE_MASS) * G * DT, rtol=1e-9)
    # the cube rests: its corners at the contact distance, no drift, no spin
    assert np.abs(cube.position[0] - start).max() < 1e-9
    assert np.abs(cube.velocity[0]).max() < 1e-9
    corners = stack["/Cube/Corners/points"].position
    assert np.abs(corners[:, 1] - CONTACT).max() < 1e-9


def test_a_mass_ratio_of_1e4_stays_finite_and_reports_the_residual(folder: Path) -> None:
    sim = sofac.load(ratio_scene(folder / "ratio.scn"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sim.step(500)
    limited = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert limited and "reached its iteration limit" in limited[0] and "residual" in limited[0]
    report = sim.output("/FreeMotionAnimationLoop1.constraint_report")
    # every solve ran to the limit (heavy on light: GS contracts by 1 / (1 + 1e-4) a sweep), its
    # residual reported: finite, of the order of the violation left
    assert report[0] == 500 and report[3] == 500
    assert report[1] == LIMIT + 1 and 1e-3 < report[5] < 0.1
    for name in ("Light", "Heavy", "Base", "Top"):
        assert np.isfinite(sim[f"/{name}/dofs"].position).all()
        assert np.abs(sim[f"/{name}/dofs"].velocity).max() < 1e-6  # at rest
    # light on heavy: exact (one contact distance apart)
    assert abs(sim["/Base/dofs"].position[0, 1] - CONTACT) < 1e-12
    assert abs(sim["/Top/dofs"].position[0, 1] - 2 * CONTACT) < 1e-12
    # heavy on light: the light one held at the contact distance, the heavy one sunk into the
    # contact distance by the violation the unconverged solve leaves (measured 9.3e-3), never
    # through: below a fifth of the contact distance
    assert abs(sim["/Light/dofs"].position[0, 1] - CONTACT) < 1e-12
    sunk = 2 * CONTACT - sim["/Heavy/dofs"].position[0, 1]
    assert 0 < sunk < CONTACT / 5
    # at rest, the impulses still carry the weights: (M + m) g dt on the floor, M g dt between
    f = sim.output("/.constraint_f")
    normals = np.sort(f[0 : 3 * int(_report(sim)[0]) : 3])
    expected = np.sort([LIGHT, HEAVY, LIGHT + HEAVY, LIGHT + HEAVY]) * G * DT
    assert np.allclose(normals[normals > 0], expected, rtol=1e-6)
