"""Mappings against an independent model of them: SubsetMapping and IdentityMapping (Vec3d and
Rigid3d), RigidMapping Rigid2d -> Vec2d.

For each mapping: the child's positions are the mapping of the parent's (also after the parent
moves); J (the child's velocity) matches finite differences of the positions; J^T (forces on the
child) gives the parent the right generalized force: one explicit Euler step from rest with a
ConstantForceField on the child leaves the parent at velocity dt M^-1 J^T f. Also: a torque-free
Rigid2d body (uniform rotation, with mapped points on their circles) and
PartialFixedProjectiveConstraint (the fixed coordinates stay, the free one falls as a free particle).

Each scene is compiled once per module (the session shares one compile cache) and instantiated
freshly by each test.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from sofac.front.meshes import quaternion_multiply
from sofac.pipeline import compile_scene
from sofac.simulation.loader import Compiled, Simulation

DT = 1e-3
ROOT = '<Node name="root" gravity="{gravity}" dt="{dt}"><DefaultAnimationLoop/>{solver}\n{body}</Node>\n'


def nums(values: object) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def quat(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return np.array([*(axis * math.sin(angle / 2)), math.cos(angle / 2)])


def rotvec_quat(w: np.ndarray) -> np.ndarray:
    """The unit quaternion of the rotation by the vector ``w`` (angle |w| about w / |w|)."""
    angle = float(np.linalg.norm(w))
    return np.array([0.0, 0.0, 0.0, 1.0]) if angle == 0 else quat(w, angle)


def quat_rotvec(q: np.ndarray) -> np.ndarray:
    """The rotation vector of a unit quaternion (x, y, z, w)."""
    q = q if q[3] >= 0 else -q
    s = float(np.linalg.norm(q[:3]))
    return np.zeros(3) if s == 0 else q[:3] / s * 2 * math.atan2(s, q[3])


def conjugate(q: np.ndarray) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


def rot2(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


# --- the state spaces: moving a state by h v, and the velocity between two states --------------


def advance(template: str, x: np.ndarray, v: np.ndarray, h: float) -> np.ndarray:
    """Positions after moving at velocity ``v`` for ``h`` (rigid frames turn about world axes)."""
    if template != "Rigid3d":
        return x + h * v
    out = x.copy()
    out[:, :3] += h * v[:, :3]
    for k in range(len(x)):
        out[k, 3:] = quaternion_multiply(rotvec_quat(h * v[k, 3:]), x[k, 3:])
    return out


def difference(template: str, after: np.ndarray, before: np.ndarray, h: float) -> np.ndarray:
    """The velocity that moves ``before`` to ``after`` in ``h`` (inverse of :func:`advance`)."""
    if template != "Rigid3d":
        return (after - before) / h
    out = np.empty((len(after), 6))
    out[:, :3] = (after[:, :3] - before[:, :3]) / h
    for k in range(len(after)):
        out[k, 3:] = quat_rotvec(quaternion_multiply(after[k, 3:], conjugate(before[k, 3:]))) / h
    return out


# --- the mappings under test, as an independent model ------------------------------------------


@dataclass(frozen=True)
class Case:
    id: str
    parent: str  # MechanicalObject names
    child: str
    template: str  # the parent's
    child_template: str
    apply: Callable[[np.ndarray], np.ndarray]  # parent positions -> child positions
    apply_jt: Callable[[np.ndarray, np.ndarray], np.ndarray]  # (parent positions, child forces) -> J^T f
    mass: Callable[[np.ndarray], np.ndarray]  # generalized force -> M^-1 of it (per parent DOF)
    forces: np.ndarray  # the ConstantForceField's forces on the child


def subset_jt(indices: list[int], size: int, width: int) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    def jt(_x: np.ndarray, f: np.ndarray) -> np.ndarray:
        out = np.zeros((size, width))
        np.add.at(out, indices, f)  # an index given twice gets both forces
        return out

    return jt


def point_mass(m: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda g: g / m


def rigid3_mass(m: float, inertia: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    # SOFA's UniformMass<Rigid3d>: m for the translation, m I for the rotation, in world axes.
    def solve(g: np.ndarray) -> np.ndarray:
        return np.hstack([g[:, :3] / m, np.linalg.solve(m * inertia, g[:, 3:].T).T])

    return solve


def rigid2_mass(m: float, inertia: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda g: np.hstack([g[:, :2] / m, g[:, 2:] / (m * inertia)])


def frames(*poses: tuple[list[float], np.ndarray]) -> np.ndarray:
    return np.array([[*c, *q] for c, q in poses])


# Vec3d: 4 parent points, a subset "3 0 3" (point 3 twice) and an identity.
P3 = np.array([[0.1, 0.2, 0.3], [1.0, -0.5, 0.25], [2.0, 0.0, -1.0], [-0.7, 1.5, 0.9]])
SUB3 = [3, 0, 3]
F_SUB3 = np.array([[1.0, -2.0, 0.5], [0.25, 0.0, -1.0], [-3.0, 0.5, 2.0]])
Q3 = P3[:2]
F_ID3 = np.array([[0.5, 1.0, -1.5], [-2.0, 0.75, 0.0]])
# Rigid3d: 3 parent frames (subset "2 0") and 2 (identity); an anisotropic inertia, so that the
# angular part of M^-1 is not a plain division.
PR = frames(
    ([0.5, -1.0, 2.0], quat(np.array([1.0, 2.0, -0.5]), 0.8)),
    ([1.0, 0.0, 0.0], quat(np.array([0.0, 0.0, 1.0]), 0.3)),
    ([-2.0, 0.5, 1.0], quat(np.array([-1.0, 0.3, 0.2]), 2.1)),
)
INERTIA = np.array([[1.0, 0.1, 0.0], [0.1, 2.0, 0.0], [0.0, 0.0, 4.0]])
SUBR = [2, 0]
F_SUBR = np.array([[1.0, -2.0, 0.5, 0.3, -0.1, 0.7], [0.0, 1.0, -1.0, -0.4, 0.9, 0.2]])
QR = PR[:2]
F_IDR = np.array([[-0.5, 0.25, 1.0, 0.6, 0.0, -0.3], [2.0, 0.0, -1.0, 0.1, 0.5, 0.0]])
# Rigid2d -> Vec2d: 2 frames (x y theta), 3 points in local coordinates on frames 0, 1, 1.
P2 = np.array([[0.5, -1.0, 0.3], [2.0, 1.0, -1.2]])
LOCAL2 = np.array([[0.4, -0.3], [1.0, 0.5], [-0.2, 0.8]])
FRAME_OF = [0, 1, 1]
F_RIG2 = np.array([[1.0, -2.0], [0.5, 0.25], [-1.5, 1.0]])


M3, M3_ID = point_mass(2.0), point_mass(0.5)  # the UniformMass of each body, as M^-1
MR, M2 = rigid3_mass(3.0, INERTIA), rigid2_mass(3.0, 0.5)


def rigid2_apply(x: np.ndarray) -> np.ndarray:
    return np.array([x[c, :2] + rot2(x[c, 2]) @ r for c, r in zip(FRAME_OF, LOCAL2, strict=True)])


def rigid2_jt(x: np.ndarray, f: np.ndarray) -> np.ndarray:
    out = np.zeros((len(x), 3))
    for c, r, force in zip(FRAME_OF, LOCAL2, f, strict=True):
        arm = rot2(x[c, 2]) @ r
        out[c] += [force[0], force[1], arm[0] * force[1] - arm[1] * force[0]]
    return out


CASES = [
    Case("subset-vec3", "p3", "s3", "Vec3d", "Vec3d", lambda x: x[SUB3], subset_jt(SUB3, 4, 3), M3, F_SUB3),
    Case("identity-vec3", "q3", "i3", "Vec3d", "Vec3d", lambda x: x, subset_jt([0, 1], 2, 3), M3_ID, F_ID3),
    Case(
        "subset-rigid3",
        "pr",
        "sr",
        "Rigid3d",
        "Rigid3d",
        lambda x: x[SUBR],
        subset_jt(SUBR, 3, 6),
        MR,
        F_SUBR,
    ),
    Case(
        "identity-rigid3", "qr", "ir", "Rigid3d", "Rigid3d", lambda x: x, subset_jt([0, 1], 2, 6), MR, F_IDR
    ),
    Case("rigid-rigid2-vec2", "p2", "m2", "Rigid2d", "Vec2d", rigid2_apply, rigid2_jt, M2, F_RIG2),
]

RIGID3_MASS = '<UniformMass vertexMass="3 1 [{}]"/>'.format(", ".join(nums(row) for row in INERTIA))


def _pair(name: str, parent: tuple[str, np.ndarray], child: tuple[str, np.ndarray], extra: str) -> str:
    """A body: a parent state with ``extra`` (mass), a child node with the mapping and the forces."""
    template = ' template="Rigid3d"' if parent[1].shape[1] == 7 else ""
    return (
        f'<Node name="{name}"><MechanicalObject name="{parent[0]}"{template} position="{nums(parent[1])}"/>'
        f'{extra}\n  <Node name="{name}_child">'
        f'<MechanicalObject name="{child[0]}"{template} position="{nums(child[1])}"/>{{mapping}}'
        '<ConstantForceField forces="{forces}"/></Node></Node>\n'
    )


def _subset(indices: list[int]) -> str:
    return f'<SubsetMapping indices="{" ".join(map(str, indices))}"/>'


# One scene for the four linear mappings: independent bodies under one explicit Euler solver. The
# subsets' children are written at other positions than their mapped ones (init overwrites them).
LINEAR = "".join(
    [
        _pair("sub3", ("p3", P3), ("s3", np.zeros((3, 3))), '<UniformMass vertexMass="2"/>').format(
            mapping=_subset(SUB3), forces=nums(F_SUB3)
        ),
        _pair("id3", ("q3", Q3), ("i3", Q3), '<UniformMass vertexMass="0.5"/>').format(
            mapping="<IdentityMapping/>", forces=nums(F_ID3)
        ),
        _pair("subr", ("pr", PR), ("sr", PR[[0, 1]]), RIGID3_MASS).format(
            mapping=_subset(SUBR), forces=nums(F_SUBR)
        ),
        _pair("idr", ("qr", QR), ("ir", QR), RIGID3_MASS).format(
            mapping="<IdentityMapping/>", forces=nums(F_IDR)
        ),
    ]
)

RIGID2 = (
    f'<Node name="body"><MechanicalObject name="p2" template="Rigid2d" position="{nums(P2)}"/>'
    '<UniformMass vertexMass="3 1 0.5"/>\n'
    f'  <Node name="pts"><MechanicalObject name="m2" template="Vec2d" position="{nums(LOCAL2)}"/>'
    f'<RigidMapping rigidIndexPerPoint="{" ".join(map(str, FRAME_OF))}"/>'
    f'<ConstantForceField forces="{nums(F_RIG2)}"/></Node></Node>\n'
)


def _write(folder: Path, name: str, body: str, *, gravity: str = "0 0 0", solver: str = "") -> Path:
    path = folder / f"{name}.scn"
    path.write_text(ROOT.format(gravity=gravity, dt=repr(DT), solver=solver, body=body))
    return path


EXPLICIT = '<EulerExplicitSolver symplectic="0"/>'


@pytest.fixture(scope="module")
def compiled(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Compiled]:
    folder = tmp_path_factory.mktemp("mappings")
    return {
        "linear": compile_scene(_write(folder, "linear", LINEAR, solver=EXPLICIT)),
        "rigid2": compile_scene(_write(folder, "rigid2", RIGID2, solver=EXPLICIT)),
    }


def _sim(compiled: dict[str, Compiled], case: Case) -> Simulation:
    return compiled["rigid2" if case.template == "Rigid2d" else "linear"].instantiate()


def _propagate(sim: Simulation) -> None:
    sim._native.init()  # x and v down the mappings, as after SOFA's init


def _moved(case: Case, x: np.ndarray) -> np.ndarray:
    """Another pose of the parent: shifted, and turned for rigid frames."""
    rng = np.random.default_rng(7)
    width = 6 if case.template == "Rigid3d" else x.shape[1]
    return advance(case.template, x, rng.normal(size=(len(x), width)), 0.6)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_positions(compiled: dict[str, Compiled], case: Case) -> None:
    sim = _sim(compiled, case)
    parent, child = sim[case.parent], sim[case.child]
    assert child.position == pytest.approx(case.apply(parent.position), abs=1e-14)
    parent.position[:] = _moved(case, parent.position)
    _propagate(sim)
    assert child.position == pytest.approx(case.apply(parent.position), abs=1e-14)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_velocities_match_finite_differences(compiled: dict[str, Compiled], case: Case) -> None:
    sim = _sim(compiled, case)
    parent, child = sim[case.parent], sim[case.child]
    parent.position[:] = _moved(case, parent.position)
    v = np.random.default_rng(3).normal(size=parent.velocity.shape)
    parent.velocity[:] = v
    _propagate(sim)
    mapped = child.velocity.copy()
    before = child.position.copy()
    h = 1e-7
    parent.position[:] = advance(case.template, parent.position.copy(), v, h)
    _propagate(sim)
    fd = difference(case.child_template, child.position, before, h)
    assert mapped == pytest.approx(fd, abs=1e-6 * max(1.0, float(np.abs(mapped).max())))


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_child_forces_reach_the_parent_through_jt(compiled: dict[str, Compiled], case: Case) -> None:
    sim = _sim(compiled, case)
    parent = sim[case.parent]
    x0 = parent.position.copy()
    sim.step(1)  # explicit Euler from rest: v1 = dt M^-1 J^T f, x1 = x0
    expected = DT * case.mass(case.apply_jt(x0, case.forces))
    assert parent.velocity == pytest.approx(expected, rel=1e-12, abs=1e-15)
    assert parent.position == pytest.approx(x0, abs=1e-15)
    # The same generalized force, seen through J: power f . (J u) = u . (J^T f) for any u.
    u = np.random.default_rng(5).normal(size=parent.velocity.shape)
    check = _sim(compiled, case)
    check[case.parent].velocity[:] = u
    _propagate(check)
    power = float(np.sum(case.forces * check[case.child].velocity))
    assert power == pytest.approx(float(np.sum(u * case.apply_jt(x0, case.forces))), rel=1e-12)


# --- torque-free Rigid2d, PartialFixedProjectiveConstraint --------------------------------------

SPIN_X0 = np.array([0.5, -1.0, 0.3])
SPIN_V = np.array([0.4, -0.2, 2.5])
SPIN_LOCAL = np.array([[0.6, 0.0], [-0.3, 0.45]])
SPIN = (
    f'<Node name="spin"><MechanicalObject name="frame" template="Rigid2d" position="{nums(SPIN_X0)}" '
    f'velocity="{nums(SPIN_V)}"/><UniformMass vertexMass="3 1 0.5"/>\n'
    f'  <Node name="rim"><MechanicalObject name="rim" template="Vec2d" position="{nums(SPIN_LOCAL)}"/>'
    "<RigidMapping/></Node></Node>\n"
)

PARTIAL_X0 = np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [-1.0, 0.5, 0.0]])
GRAVITY = np.array([1.5, -9.81, 2.0])
PARTIAL = (
    f'<Node name="pts"><MechanicalObject name="pts" position="{nums(PARTIAL_X0)}"/>'
    '<UniformMass vertexMass="0.7"/>'
    '<PartialFixedProjectiveConstraint indices="0 2" fixedDirections="1 0 1"/></Node>\n'
)


def test_torque_free_rigid2d_turns_uniformly(tmp_path: Path) -> None:
    sim = compile_scene(_write(tmp_path, "spin", SPIN, solver="<EulerExplicitSolver/>")).instantiate()
    energy = sim.energy()
    m, inertia = 3.0, 0.5
    assert energy.kinetic == pytest.approx(
        0.5 * m * SPIN_V[:2] @ SPIN_V[:2] + 0.5 * m * inertia * SPIN_V[2] ** 2
    )
    sim.step(1500)
    t = sim.time
    frame, rim = sim["frame"], sim["rim"]
    assert frame.position[0] == pytest.approx(SPIN_X0 + SPIN_V * t, abs=1e-12)  # theta unwrapped
    assert np.array_equal(frame.velocity[0], SPIN_V)
    expected = [frame.position[0, :2] + rot2(SPIN_X0[2] + SPIN_V[2] * t) @ r for r in SPIN_LOCAL]
    assert rim.position == pytest.approx(np.array(expected), abs=1e-12)
    speed = SPIN_V[2] * np.linalg.norm(SPIN_LOCAL, axis=1)  # relative to the centre, on the circle
    relative = rim.velocity - SPIN_V[:2]
    assert np.linalg.norm(relative, axis=1) == pytest.approx(speed, rel=1e-12)
    assert sim.energy().kinetic == pytest.approx(energy.kinetic, rel=1e-12)


def test_partial_fixed_keeps_fixed_directions_and_frees_the_others(tmp_path: Path) -> None:
    sim = compile_scene(
        _write(tmp_path, "partial", PARTIAL, gravity=nums(GRAVITY), solver="<EulerExplicitSolver/>")
    ).instantiate()
    steps = 200
    sim.step(steps)
    x, v = sim["pts"].position, sim["pts"].velocity
    # DOF 1 is free: symplectic Euler's exact discrete free fall, v_n = g n dt, x_n = x0 + g dt^2 n (n+1)/2.
    assert v[1] == pytest.approx(GRAVITY * steps * DT, rel=1e-12)
    assert x[1] == pytest.approx(PARTIAL_X0[1] + GRAVITY * DT**2 * steps * (steps + 1) / 2, rel=1e-12)
    for k in (0, 2):  # x and z held, y falls exactly as the free particle's
        assert x[k, [0, 2]].tolist() == PARTIAL_X0[k, [0, 2]].tolist()
        assert v[k, [0, 2]].tolist() == [0.0, 0.0]
        assert v[k, 1] == v[1, 1]
        assert x[k, 1] - PARTIAL_X0[k, 1] == pytest.approx(x[1, 1] - PARTIAL_X0[1, 1], abs=1e-12)
