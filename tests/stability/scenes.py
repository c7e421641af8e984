"""Small scene texts for the stability suite, and a session-wide compile cache keyed by scene text.

Compiling a scene costs 1-3 s, instantiating a compiled one a millisecond: tests build each
distinct text once (``Scenes.compiled``) and vary numbers through parameter and state views.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from sofac.pipeline import compile_scene
from sofac.simulation.loader import Compiled, Simulation

ROOT = '<Node name="root" gravity="{gravity}" dt="{dt}"><DefaultAnimationLoop/>{body}</Node>'
NO_GRAVITY = "0 0 0"
GRAVITY = "0 -9.81 0"


def nums(values: object) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def implicit(iterations: int = 25, tolerance: float = 1e-5, threshold: float = 1e-5) -> str:
    """EulerImplicitSolver (no Rayleigh damping) with a CGLinearSolver."""
    return (
        '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>'
        f'<CGLinearSolver iterations="{iterations}" tolerance="{tolerance!r}" threshold="{threshold!r}"/>'
    )


EXACT_CG = implicit(200, 1e-14, 1e-30)  # converged solves: the scheme's own behaviour, not CG's
DIRECT = '<EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/><SparseLDLSolver/>'


def springs_body(
    solver: str,
    positions: np.ndarray,
    pairs: Sequence[tuple[int, int]],
    *,
    stiffness: float = 100.0,
    damping: float = 1.0,
    rest: float | Sequence[float] = 1.0,
    mass: str = '<UniformMass name="mass" vertexMass="1"/>',
    fixed: Sequence[int] = (),
) -> str:
    """Node "s": one MechanicalObject "dofs" and a SpringForceField "springs" between ``pairs``.

    Damping and stiffness are written non-zero by default so that the compiled step keeps their
    code and tests can tune them through ``sim.param``."""
    lengths = [rest] * len(pairs) if isinstance(rest, float | int) else list(rest)
    springs = "  ".join(
        f"{a} {b} {stiffness!r} {damping!r} {float(length)!r}"
        for (a, b), length in zip(pairs, lengths, strict=True)
    )
    constraint = f'<FixedProjectiveConstraint indices="{" ".join(map(str, fixed))}"/>' if fixed else ""
    return (
        f'<Node name="s">{solver}<MechanicalObject name="dofs" position="{nums(positions)}"/>{mass}'
        f'{constraint}<SpringForceField name="springs" spring="{springs}"/></Node>'
    )


def chain_pairs(n: int) -> list[tuple[int, int]]:
    return [(i, i + 1) for i in range(n - 1)]


def line(n: int, spacing: float = 1.0, axis: int = 0) -> np.ndarray:
    points = np.zeros((n, 3))
    points[:, axis] = spacing * np.arange(n)
    return points


# Two tetrahedra sharing the face (1, 2, 3), both positively oriented.
TWO_TETS_POINTS = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
TWO_TETS = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
ONE_TET_POINTS = TWO_TETS_POINTS[:4]
ONE_TET = TWO_TETS[:1]


def tetra_body(
    solver: str,
    positions: np.ndarray,
    tetrahedra: np.ndarray,
    method: str,
    *,
    young: float = 1e4,
    poisson: float = 0.3,
    fixed: Sequence[int] = (),
    mass: str = '<UniformMass name="mass" vertexMass="1"/>',
) -> str:
    """Node "t": MeshTopology, MechanicalObject "dofs", a mass, TetrahedronFEMForceField "fem"."""
    constraint = f'<FixedProjectiveConstraint indices="{" ".join(map(str, fixed))}"/>' if fixed else ""
    cells = " ".join(str(int(i)) for i in np.ravel(tetrahedra))
    return (
        f'<Node name="t">{solver}<MeshTopology name="mesh" tetrahedra="{cells}"/>'
        f'<MechanicalObject name="dofs" position="{nums(positions)}"/>{mass}{constraint}'
        f'<TetrahedronFEMForceField name="fem" method="{method}" youngModulus="{young!r}" '
        f'poissonRatio="{poisson!r}"/></Node>'
    )


def beam(nx: int, size: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A bar of ``nx`` unit cubes along x, each cut into 6 tetrahedra around its main diagonal
    (positively oriented): points and tetrahedra."""
    points = np.array(
        [(i * size, j * size, k * size) for i in range(nx + 1) for j in range(2) for k in range(2)]
    )

    def index(i: int, j: int, k: int) -> int:
        return 4 * i + 2 * j + k

    cells = []
    for i in range(nx):
        c = [index(i + di, dj, dk) for di in range(2) for dj in range(2) for dk in range(2)]
        # corners c[dx*4 + dy*2 + dz]; the six paths from corner 0 to corner 7
        for a, b in ((4, 6), (4, 5), (2, 6), (2, 3), (1, 5), (1, 3)):
            cells.append([c[0], c[a], c[b], c[7]])
    tetrahedra = np.array(cells)
    signed = volumes(points, tetrahedra)
    flip = signed < 0
    tetrahedra[flip, 1], tetrahedra[flip, 2] = tetrahedra[flip, 2], tetrahedra[flip, 1].copy()
    return points, tetrahedra


def volumes(points: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    """Signed volumes of the tetrahedra."""
    a, b, c, d = (points[tetrahedra[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


class Scenes:
    """Writes scene texts into a folder and compiles each distinct text once per session."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self._compiled: dict[str, Compiled] = {}

    def write(self, name: str, body: str, *, dt: float = 0.01, gravity: str = NO_GRAVITY) -> Path:
        path = self.folder / f"{name}.scn"
        path.write_text(ROOT.format(gravity=gravity, dt=repr(dt), body=body))
        return path

    def compiled(self, name: str, body: str, *, dt: float = 0.01, gravity: str = NO_GRAVITY) -> Compiled:
        text = ROOT.format(gravity=gravity, dt=repr(dt), body=body)
        if text not in self._compiled:
            self._compiled[text] = compile_scene(self.write(name, body, dt=dt, gravity=gravity))
        return self._compiled[text]

    def sim(self, name: str, body: str, *, dt: float = 0.01, gravity: str = NO_GRAVITY) -> Simulation:
        """A fresh simulation of the scene (compiled once per session)."""
        return self.compiled(name, body, dt=dt, gravity=gravity).instantiate()


def finite(sim: Simulation) -> bool:
    return all(
        np.isfinite(sim[path].position).all() and np.isfinite(sim[path].velocity).all()
        for path in sim.objects()
    )
