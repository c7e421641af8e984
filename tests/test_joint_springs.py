"""JointSpringForceField (runtime/sofac/joint_springs.h): the `spring` list read as SOFA's
operator>> reads it, the torque of a torsion spring (k angle), K dx against finite differences of
the force where SOFA's addDForce is the force's derivative, the assembled blocks against K dx, and
explicit, matrix-free implicit and direct solves of a scene against the closed form."""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i
from sofac.check.checker import check_file
from sofac.pipeline import compile_scene
from sofac.registry.fields import JOINT_SPRING_COLUMNS, FieldValueError, JointSprings

COLUMN = {name: i for i, name in enumerate(JOINT_SPRING_COLUMNS)}

# ---- the stream format ----------------------------------------------------------------------


def parse(text: str) -> np.ndarray:
    return JointSprings().parse(text)


def test_defaults_of_one_spring() -> None:
    """BEGIN_SPRING m1 m2 END_SPRING: translations blocked, rotations free, KS_T 0 10000, KS_R 0 10000,
    KS_B = hard / 100, no limits, no rest offset (REST_T not given: no initialisation)."""
    (row,) = parse("BEGIN_SPRING 3 4 END_SPRING")
    assert row[:2].tolist() == [3, 4]
    assert row[2:8].tolist() == [0, 0, 0, 1, 1, 1]
    assert row[8:14].tolist() == [0, 10000, 0, 10000, 100, 0]
    assert row[14:20].tolist() == [-100000, 100000] * 3
    assert row[20:27].tolist() == [0, 0, 0, 0, 0, 0, 1] and row[27] == 0


def test_values_kept_from_the_previous_spring() -> None:
    """vector<JointSpring>::read reads every spring into one object: KS_T, KS_R and KD carry over,
    FREE_AXIS, limits, KS_B and the rest offset do not; equal limits block the axis (SOFA's)."""
    first, second = parse(
        "BEGIN_SPRING 0 1 FREE_AXIS 1 0 0 0 1 0 KS_T 5 300 KS_R 7 90 KS_B 3 KD 0.5 R_LIM_Y -0.8 0.8 "
        "R_LIM_Z 0 0 REST_T 1 2 3 REST_R 0 0 0.6 0.8 END_SPRING\n"
        " BEGIN_SPRING 1 2 R_LIM_X 0.2 0.2 END_SPRING"
    )
    assert first[2:8].tolist() == [1, 0, 0, 0, 1, 0]
    assert first[8:14].tolist() == [5, 300, 7, 90, 3, 0.5]
    assert first[16:18].tolist() == [-0.8, 0.8] and first[18:20].tolist() == [0, 0]
    assert first[20:27].tolist() == [1, 2, 3, 0, 0, 0.6, 0.8] and first[27] == 1
    assert second[2:8].tolist() == [0, 0, 0, 0, 1, 1]  # R_LIM_X 0.2 0.2: rotation about x blocked
    assert second[8:14].tolist() == [5, 300, 7, 90, 0.9, 0.5]  # KS_B afresh: 90 / 100
    assert second[20:28].tolist() == [0, 0, 0, 0, 0, 0, 1, 0]


def test_format_reads_back() -> None:
    springs = parse(
        "BEGIN_SPRING 0 1 FREE_AXIS 0 0 0 0 1 0 KS_R 0 200000 KD 1 R_LIM_Z 0 0 REST_T 1 0 0 END_SPRING"
    )
    assert np.array_equal(parse(JointSprings().format(springs)), springs)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("0 1 KS_T 1 2", "starts with '0', not BEGIN_SPRING"),
        ("BEGIN_SPRING 0 1 KS_T 1 END_SPRING", "KS_T needs 2 numbers"),
        ("BEGIN_SPRING 0 1 STIFFNESS 3 END_SPRING", "unknown attribute 'STIFFNESS'"),
        ("BEGIN_SPRING 0 1 FREE_AXIS 0 0 0 2 1 1 END_SPRING", "is not six 0/1 flags"),
        ("BEGIN_SPRING 0 -1 END_SPRING", "DOF index '-1'"),
        ("BEGIN_SPRING 0 1 KD 2", "no END_SPRING"),
    ],
)
def test_malformed_lists_are_diagnosed(text: str, message: str) -> None:
    with pytest.raises(FieldValueError, match=message) as caught:
        parse(text)
    assert caught.value.code == "E204" and caught.value.hint


SCENE = """\
<Node name="root" gravity="0 0 0" dt="0.01"><DefaultAnimationLoop/>
  <Node name="pair">{solver}
    <MechanicalObject template="Rigid3d" name="dofs" position="0 0 0 0 0 0 1  {second}"/>
    <UniformMass vertexMass="1 1 [1 0 0,0 1 0,0 0 1]"/>
    <FixedProjectiveConstraint indices="0"/>
    <JointSpringForceField spring="{spring}"/>
  </Node>
</Node>
"""


def test_check_reports_the_attribute_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.scn"
    path.write_text(
        SCENE.format(
            solver="<EulerExplicitSolver/>",
            second="1 0 0 0 0 0 1",
            spring="BEGIN_SPRING 0 1 KS_Q 1 END_SPRING  BEGIN_SPRING 0 5 END_SPRING",
        )
    )
    _, diags = check_file(path)
    assert [(d.code, d.loc.line) for d in diags.errors] == [("E204", 6)]
    assert "unknown attribute 'KS_Q'" in diags.errors[0].message
    path.write_text(
        SCENE.format(
            solver="<EulerExplicitSolver/>", second="1 0 0 0 0 0 1", spring="BEGIN_SPRING 0 5 END_SPRING"
        )
    )
    _, diags = check_file(path)
    assert [(d.code, d.loc.line) for d in diags.errors] == [("E218", 6)]
    assert "index 5" in diags.errors[0].message


# ---- the kernels ----------------------------------------------------------------------------

SHIM = r"""
#include "sofac/joint_springs.h"
using sofac::Index;
#define API extern "C" __attribute__((visibility("default")))
#define TABLE const Index *a, const Index *b, const double *p, double *rest, Index *pending, \
              double *memory, Index count
#define SPRINGS sofac::JointSprings{a, b, p, rest, pending, memory, count}
struct Dense {
    double* m;
    Index n;
    void add(Index r, Index c, double v) { m[r * n + c] += v; }
};
API void force(TABLE, const double* x1, const double* v1, double* f1, const double* x2, const double* v2,
               double* f2) {
    sofac::joint_spring_forces(SPRINGS, x1, v1, f1, x2, v2, f2);
}
API void dforce(TABLE, const double* dx1, double* df1, const double* dx2, double* df2, double kfact) {
    sofac::joint_spring_dforces(SPRINGS, dx1, df1, dx2, df2, kfact);
}
API void assemble(TABLE, double* matrix, Index n, Index offset2, double kfact) {
    Dense dense{matrix, n};
    sofac::assemble_joint_springs(dense, SPRINGS, 0, offset2, kfact);
}
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    library = build_shim(tmp_path_factory, "joint_springs", SHIM)
    table = [I64, I64, D, D, I64, D, ctypes.c_int64]
    library.force.argtypes = [*table, D, D, D, D, D, D]
    library.dforce.argtypes = [*table, D, D, D, D, ctypes.c_double]
    library.assemble.argtypes = [*table, D, ctypes.c_int64, ctypes.c_int64, ctypes.c_double]
    return library


def qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product, (x y z w) as SOFA stores quaternions."""
    (x1, y1, z1, w1), (x2, y2, z2, w2) = p, q
    return np.array(
        [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 + y1 * w2 + z1 * x2 - x1 * z2,
            w1 * z2 + z1 * w2 + x1 * y2 - y1 * x2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ]
    )


def turn(w: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(w))
    if angle == 0.0:
        return np.array([0.0, 0.0, 0.0, 1.0])
    return np.array([*(np.sin(angle / 2) * w / angle), np.cos(angle / 2)])


def conj(q: np.ndarray) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


class Joint:
    """One spring between DOF 0 of body 1 and DOF 0 of body 2 (separate arrays), through the shim."""

    def __init__(self, lib: ctypes.CDLL, text: str, rest: np.ndarray | None = None) -> None:
        row = parse(text)[0]
        self.lib = lib
        self.a, self.b = np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)
        self.params = np.ascontiguousarray(row[2:20])
        self.rest = np.ascontiguousarray(row[20:27] if rest is None else rest, dtype=float)
        self.pending = np.array([int(row[27])], dtype=np.int64)
        self.memory = np.zeros(10)

    def _table(self) -> list[object]:
        return [_i(self.a), _i(self.b), _d(self.params), _d(self.rest), _i(self.pending), _d(self.memory), 1]

    def force(
        self, x1: np.ndarray, x2: np.ndarray, v1: np.ndarray | None = None, v2: np.ndarray | None = None
    ):  # type: ignore[no-untyped-def]
        f1, f2 = np.zeros(6), np.zeros(6)
        v1 = np.zeros(6) if v1 is None else v1
        v2 = np.zeros(6) if v2 is None else v2
        self.lib.force(*self._table(), _d(x1), _d(v1), _d(f1), _d(x2), _d(v2), _d(f2))
        return np.concatenate([f1, f2])

    def dforce(self, dx: np.ndarray, kfact: float = 1.0) -> np.ndarray:
        dx1, dx2 = np.ascontiguousarray(dx[:6]), np.ascontiguousarray(dx[6:])
        df1, df2 = np.zeros(6), np.zeros(6)
        self.lib.dforce(*self._table(), _d(dx1), _d(df1), _d(dx2), _d(df2), kfact)
        return np.concatenate([df1, df2])

    def matrix(self, kfact: float = 1.0) -> np.ndarray:
        dense = np.zeros((12, 12))
        self.lib.assemble(*self._table(), _d(dense), 12, 6, kfact)
        return dense


def perturbed(x1: np.ndarray, x2: np.ndarray, coordinate: int, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions moved by h along derivative coordinate 0..11 (rotations about world axes, as a
    rigid's velocity integrates: q' = turn(h e) q)."""
    x1, x2 = x1.copy(), x2.copy()
    body, c = (x1, coordinate) if coordinate < 6 else (x2, coordinate - 6)
    if c < 3:
        body[c] += h
    else:
        e = np.zeros(3)
        e[c - 3] = h
        body[3:] = qmul(turn(e), body[3:])
    return x1, x2


def fd_jacobian(joint: Joint, x1: np.ndarray, x2: np.ndarray, columns: range, h: float = 1e-6) -> np.ndarray:
    jacobian = np.zeros((12, 12))
    for c in columns:
        plus = joint.force(*perturbed(x1, x2, c, h))
        minus = joint.force(*perturbed(x1, x2, c, -h))
        jacobian[:, c] = (plus - minus) / (2 * h)
    joint.force(x1, x2)  # the memory of the configuration itself, for K dx
    return jacobian


def k_dx_matrix(joint: Joint) -> np.ndarray:
    return np.column_stack([joint.dforce(np.eye(12)[c]) for c in range(12)])


MIXED = "BEGIN_SPRING 0 0 FREE_AXIS 1 0 0 1 1 0 KS_T 5 300 KS_R 7 90 END_SPRING"
Q1 = turn(np.array([0.4, -0.9, 0.3]))
REST_T = np.array([0.3, -0.2, 0.5])
REST_R = turn(np.array([-0.2, 0.1, 0.7]))


def at_rest() -> tuple[np.ndarray, np.ndarray]:
    """Body 2 at its rest placement relative to body 1: d = c2 - c1 - initTrans = 0 and
    (q1^-1 q2) initRot = identity."""
    c1 = np.array([1.0, 2.0, -1.0])
    x1 = np.array([*c1, *Q1])
    x2 = np.array([*(c1 + REST_T), *qmul(Q1, conj(REST_R))])
    return x1, x2


def test_stiffness_is_the_force_derivative_at_rest(lib: ctypes.CDLL) -> None:
    """At the rest placement (general case: two free rotation axes, one free translation axis), SOFA's
    K dx, ref (K .* ref^-1 (dx2 - dx1)) per part, is the full 12 x 12 derivative of the force."""
    joint = Joint(lib, MIXED, rest=np.array([*REST_T, *REST_R]))
    x1, x2 = at_rest()
    assert np.abs(joint.force(x1, x2)).max() < 1e-9
    numeric = fd_jacobian(joint, x1, x2, range(12))
    stiffness = k_dx_matrix(joint)
    assert np.abs(stiffness - numeric).max() < 1e-6 * 300
    # the blocks: R diag(KT) R^T and R diag(KR) R^T, R body 1's rotation matrix
    x, y, z, w = Q1
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    translation = rotation @ np.diag([5.0, 300.0, 300.0]) @ rotation.T
    turning = rotation @ np.diag([7.0, 7.0, 90.0]) @ rotation.T
    assert stiffness[6:9, 0:3] == pytest.approx(translation, abs=1e-12)  # df2/dx1 = K
    assert stiffness[9:12, 3:6] == pytest.approx(turning, abs=1e-12)


def test_translation_stiffness_is_exact_anywhere(lib: ctypes.CDLL) -> None:
    """Away from rest (stretched, twisted, moving) the force is linear in the centres: the
    translation columns of K dx are the finite differences of the force to round-off."""
    joint = Joint(lib, MIXED)
    x1 = np.array([0.1, 0.2, 0.3, *Q1])
    x2 = np.array([0.9, -0.4, 0.6, *qmul(turn(np.array([0.3, 0.2, -0.4])), Q1)])
    numeric = fd_jacobian(joint, x1, x2, range(12))
    stiffness = k_dx_matrix(joint)
    for block in (slice(0, 3), slice(6, 9)):
        assert np.abs(stiffness[:, block] - numeric[:, block]).max() < 1e-6


def test_assembled_blocks_are_k_dx(lib: ctypes.CDLL) -> None:
    joint = Joint(lib, MIXED)
    x1 = np.array([0.1, 0.2, 0.3, *Q1])
    x2 = np.array([0.9, -0.4, 0.6, *qmul(turn(np.array([0.3, 0.2, -0.4])), Q1)])
    joint.force(x1, x2)
    assert np.abs(joint.matrix(0.25) - 0.25 * k_dx_matrix(joint)).max() < 1e-12


def test_torsion_spring_restoring_torque(lib: ctypes.CDLL) -> None:
    """Two frames at one point, body 2 turned by theta about an axis u in body 1's frame: torque
    k theta u (in world axes) on body 1 and its opposite on body 2, no force; damping kd (w2 - w1)."""
    joint = Joint(lib, "BEGIN_SPRING 0 0 KS_R 40 40 KD 0.5 END_SPRING")
    theta, u = 0.7, np.array([2.0, -1.0, 2.0]) / 3.0
    x1 = np.array([0.5, 0.5, 0.5, *Q1])
    x2 = np.array([0.5, 0.5, 0.5, *qmul(Q1, turn(theta * u))])
    w2 = np.array([0.0, 0.0, 0.0, 0.1, -0.3, 0.2])
    force = joint.force(x1, x2, np.zeros(6), w2)
    x, y, z, w = Q1
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    torque = 40 * theta * rotation @ u + 0.5 * w2[3:]
    assert force[:3] == pytest.approx(np.zeros(3), abs=1e-12)
    assert force[3:6] == pytest.approx(torque, abs=1e-12)
    assert force[6:] == pytest.approx(-force[:6], abs=0)


def test_angle_beyond_a_limit_is_held_by_the_bloc_stiffness(lib: ctypes.CDLL) -> None:
    """Free rotation about z limited to [-0.5, 0.5] (with x also free: SOFA's general case): at 0.8
    rad the torque is kBloc (0.8 - 0.5); inside the limits it is the soft stiffness's, and K dx uses
    kBloc on that axis."""
    text = "BEGIN_SPRING 0 0 FREE_AXIS 0 0 0 1 0 1 KS_R 2 1000 KS_B 50 R_LIM_Z -0.5 0.5 END_SPRING"
    joint = Joint(lib, text)
    x1 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    for angle, torque, kz in ((0.8, 50 * (0.8 - 0.5), 50.0), (0.3, 2 * 0.3, 2.0)):
        x2 = np.array([0.0, 0.0, 0.0, *turn(np.array([0.0, 0.0, angle]))])
        force = joint.force(x1, x2)
        assert force[3:6] == pytest.approx([0.0, 0.0, torque], abs=1e-12)
        assert joint.memory[7:10].tolist() == [2.0, 1000.0, kz]


def test_pivot_about_x_holds_the_swing(lib: ctypes.CDLL) -> None:
    """Only rotation about x free (limits -1 1): SOFA's pivot case. With M the relative rotation's
    matrix, theta = atan2(|(M10, M20)|, M00) the swing of the x axis; torque (KR_x torsion_x,
    -M20 theta KR_y, M10 theta KR_z) with KR = (soft, hard, hard), here in body 1's identity frame."""
    joint = Joint(lib, "BEGIN_SPRING 0 0 FREE_AXIS 0 0 0 1 0 0 KS_R 2 100 R_LIM_X -1 1 END_SPRING")
    x1 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    q = qmul(turn(np.array([0.5, 0.0, 0.0])), turn(np.array([0.0, 0.2, -0.1])))
    force = joint.force(x1, np.array([0.0, 0.0, 0.0, *q]))
    m = rotation_of(q)
    theta = np.arctan2(np.hypot(m[1, 0], m[2, 0]), m[0, 0])
    angle = 2 * np.arccos(q[3])
    torsion_x = q[0] / np.sin(angle / 2) * angle
    expected = [2 * torsion_x, -m[2, 0] * theta * 100, m[1, 0] * theta * 100]
    assert force[3:6] == pytest.approx(expected, rel=1e-12)
    assert joint.memory[7:10].tolist() == [2.0, 100.0, 100.0]


def test_rest_t_takes_the_initial_placement(lib: ctypes.CDLL) -> None:
    """REST_T given: SOFA's bwdInit overwrites it with c2 - c1 and the rest rotation with q2 q1^-1
    (that order: a body 1 turned by q1 at the start is then not at rest)."""
    joint = Joint(lib, "BEGIN_SPRING 0 0 KS_T 100 100 KS_R 40 40 REST_T 9 9 9 END_SPRING")
    x1 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    x2 = np.array([1.0, 2.0, 3.0, *turn(np.array([0.0, 0.0, 0.25]))])
    force = joint.force(x1, x2)
    assert joint.pending[0] == 0 and joint.rest.tolist() == pytest.approx([1, 2, 3, *x2[3:]], abs=0)
    # r = (q1^-1 q2) initRot = q2 q2: twice the angle
    assert force[:3] == pytest.approx(np.zeros(3), abs=1e-12)
    assert force[3:6] == pytest.approx([0.0, 0.0, 40 * 0.5], abs=1e-12)
    assert joint.force(x1 + np.eye(7)[0] * 0.5, x2)[:3] == pytest.approx([-50.0, 0.0, 0.0], abs=1e-12)


# ---- scenes -------------------------------------------------------------------------------------

THETA, K, DT = 0.4, 50.0, 0.01
SECOND = f"0 0 0 0 0 {float(np.sin(THETA / 2))!r} {float(np.cos(THETA / 2))!r}"


@pytest.mark.parametrize(
    ("solver", "angular_velocity"),
    [
        ('<EulerExplicitSolver symplectic="0"/>', -DT * K * THETA),
        (
            '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/><CGLinearSolver iterations="50" '
            'tolerance="1e-20" threshold="1e-30"/>',
            -DT * K * THETA / (1 + DT * DT * K),
        ),
        (
            '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>'
            '<SparseLDLSolver template="CompressedRowSparseMatrixd"/>',
            -DT * K * THETA / (1 + DT * DT * K),
        ),
    ],
    ids=["explicit", "implicit-cg", "implicit-ldl"],
)
def test_scene_torsion_spring(tmp_path: Path, solver: str, angular_velocity: float) -> None:
    """Body 1 fixed, body 2 at the same point turned by theta about z, unit inertia: after one step
    w_z = -dt k theta (explicit Euler) or -dt k theta / (1 + dt^2 k) (implicit Euler, v = 0)."""
    path = tmp_path / "torsion.scn"
    path.write_text(
        SCENE.format(solver=solver, second=SECOND, spring=f"BEGIN_SPRING 0 1 KS_R {K} {K} END_SPRING")
    )
    simulation = compile_scene(path).instantiate()
    simulation.step(1)
    velocity = simulation["dofs"].velocity
    assert velocity[0].tolist() == [0.0] * 6
    assert velocity[1, :5] == pytest.approx(np.zeros(5), abs=1e-15)
    assert velocity[1, 5] == pytest.approx(angular_velocity, rel=1e-12)


def test_infile_is_refused(tmp_path: Path) -> None:
    from sofac.diagnostics import SceneError

    path = tmp_path / "infile.scn"
    (tmp_path / "forces.txt").write_text("0 0 0 0 0 0\n")
    path.write_text(
        SCENE.format(
            solver="<EulerExplicitSolver/>", second=SECOND, spring="BEGIN_SPRING 0 1 END_SPRING"
        ).replace("<JointSpringForceField ", '<JointSpringForceField infile="forces.txt" ')
    )
    with pytest.raises(SceneError, match="constant joint forces read from infile are not compiled yet"):
        compile_scene(path)


# ---- RigidMapping Rigid3d -> Rigid3d (the frames JointSpringForceField.scn joins) ----------------

FRAMES = """\
<Node name="root" gravity="0 0 0" dt="0.01"><DefaultAnimationLoop/>
  <Node name="body">{solver}
    <MechanicalObject template="Rigid3d" name="parent" position="1 2 3 {q}" velocity="0.5 0 0 0.1 0.2 -0.3"/>
    <UniformMass vertexMass="1 1 [1 0 0,0 1 0,0 0 1]"/>
    <Node name="frames">
      <MechanicalObject template="Rigid3d" name="child" position="0.4 -0.2 0.1 {local}  0 0 0 0 0 0 1"/>
      <RigidMapping input="@../parent" output="@child"/>
      {extra}
    </Node>
  </Node>
</Node>
"""
QP = turn(np.array([0.3, -0.5, 0.2]))
QL = turn(np.array([-0.1, 0.4, 0.6]))


def frames_scene(tmp_path: Path, solver: str = '<EulerExplicitSolver symplectic="0"/>', extra: str = ""):  # type: ignore[no-untyped-def]
    path = tmp_path / "frames.scn"
    text = FRAMES.format(
        solver=solver,
        q=" ".join(repr(float(c)) for c in QP),
        local=" ".join(repr(float(c)) for c in QL),
        extra=extra,
    )
    path.write_text(text)
    return compile_scene(path).instantiate()


def rotation_of(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_rigid_to_rigid_mapping_places_and_moves_the_frames(tmp_path: Path) -> None:
    """x = (c + R p, q q_local), v = (v_c + w x R p, w) (SOFA's RigidMapping<Rigid3, Rigid3>)."""
    simulation = frames_scene(tmp_path)
    child = simulation["child"]
    r = rotation_of(QP) @ np.array([0.4, -0.2, 0.1])
    assert child.position[0, :3] == pytest.approx(np.array([1.0, 2.0, 3.0]) + r, abs=1e-14)
    assert child.position[0, 3:] == pytest.approx(qmul(QP, QL), abs=1e-15)
    assert child.position[1] == pytest.approx([1.0, 2.0, 3.0, *QP], abs=1e-15)
    w = np.array([0.1, 0.2, -0.3])
    assert child.velocity[0] == pytest.approx([*(np.array([0.5, 0, 0]) + np.cross(w, r)), *w], abs=1e-14)


def test_rigid_to_rigid_mapping_carries_forces_and_torques(tmp_path: Path) -> None:
    """applyJT with SOFA's Rigid3 updateOmega: f_c += f, tau_c += tau + r x f; one explicit step of a
    unit body from its velocity."""
    force = np.array([1.0, -2.0, 0.5, 0.3, 0.0, -0.7])
    simulation = frames_scene(
        tmp_path, extra=f'<ConstantForceField indices="0" forces="{" ".join(str(f) for f in force)}"/>'
    )
    simulation.step(1)
    r = rotation_of(QP) @ np.array([0.4, -0.2, 0.1])
    torque = force[3:] + np.cross(r, force[:3])
    velocity = simulation["parent"].velocity[0]
    assert velocity[:3] == pytest.approx(np.array([0.5, 0, 0]) + DT * force[:3], abs=1e-14)
    assert velocity[3:] == pytest.approx(np.array([0.1, 0.2, -0.3]) + DT * torque, abs=1e-14)


def test_joint_spring_on_mapped_frames_direct_and_cg_agree(tmp_path: Path) -> None:
    """A joint spring between the two mapped frames (one turned and offset from the other): the
    matrix-free CG and the assembled LDL solve (J^T K J through the mapping) give the same step."""
    spring = 'object1="@child" object2="@child" spring="BEGIN_SPRING 0 1 KS_T 50 80 KS_R 3 40 END_SPRING"'
    extra = f"<JointSpringForceField {spring}/>"
    results = []
    for solver in (
        '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>'
        '<CGLinearSolver iterations="200" tolerance="1e-30" threshold="1e-30"/>',
        '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>'
        '<SparseLDLSolver template="CompressedRowSparseMatrixd"/>',
    ):
        folder = tmp_path / str(len(results))
        folder.mkdir()
        simulation = frames_scene(folder, solver=solver, extra=extra)
        simulation.step(3)
        results.append(simulation["parent"].velocity.copy())
    assert np.abs(results[0]).max() > 0.1
    assert results[0] == pytest.approx(results[1], abs=1e-12)


def test_corpus_joint_spring_scene_runs(corpus_dir: Path) -> None:
    """Component/SolidMechanics/Spring/JointSpringForceField.scn: its rigidIndexPerPoint has 5 entries
    for 9 frames, so SOFA maps every attach from the fixed DOF 0: the springs hold nothing and the
    three free bodies fall, unturned."""
    simulation = compile_scene(
        corpus_dir / "Component/SolidMechanics/Spring/JointSpringForceField.scn"
    ).instantiate()
    simulation.step(10)
    bodies = simulation["DOFs"].position
    assert bodies[0].tolist() == [0, 0, 0, 0, 0, 0, 1]
    assert (bodies[1:, 1] < -0.04).all() and np.allclose(bodies[1:, 3:], [0, 0, 0, 1])
    centres = simulation["attaches"].position[:, :3]
    assert centres[:, 0].tolist() == [0, *[-1, 1] * 4] and not centres[:, 1:].any()
