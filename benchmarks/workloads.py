"""The performance workloads of issue 6 (``shared/bench/workloads.md``), side by side in one run.

For each workload, in this one process:

- **sofac**: the workload as a generated ``.scn`` scene (``scenegen.py``), ``sofac.load``, warm-up
  steps, then ``--batches`` timed batches of ``sim.step(steps)``;
- **hand-written**: an independent C++ loop of the same algorithm (``handwritten/w1.cpp``,
  ``w2.cpp``, ``w3.cpp``), compiled with g++ and the flags sofac uses for large scenes
  (``sofac.build.compiler.LARGE_SCENE_FLAGS`` without the shared-library ones; W3 linked with CHOLMOD) and
  timed inside the C++ program, batch by batch, after the same warm-up;
- **NumPy / SciPy**: vectorised NumPy (W1); a ``scipy.sparse`` matrix with 25 CG iterations in
  NumPy (W2, W3) or SuperLU (``scipy.sparse.linalg.splu``, W3's direct variant ``w3ldl``), when
  SciPy is installed;
- **SOFA**: SOFA's measured figures from ``shared/reference/sofa/timings.md`` (not run here).

W3 (the corotational tetrahedral cantilever) is vectorised over the elements with ``np.einsum``
(``scipy_w3``: w3.cpp's formulas, K assembled as a ``scipy.sparse`` matrix each step); its SOFA
figure is that of SOFA's own beam scene (same counts). W3asm is W3 with CGLinearSolver on the assembled matrix
(``w3_beam_cg25_assembled.scn``), against the assembled hand-written loop, with sofac's
matrix-free W3 beside it. Its sparse direct variant (b) is timed with SOFA's SparseLDLSolver
(``w3ldl``, L D L^T) and SparseCholeskySolver (``w3chol``, L L^T), both against the hand-written
loop with CHOLMOD's defaults. ``Demos/liver.scn`` from the SOFA corpus is timed with sofac against
SOFA's figure.

W4 and W5 are penalty contact (issue 16) against hand-written loops that bin the static floor once
into a grid (``handwritten/w4.cpp``, ``w5.cpp``): W4 particles bouncing on a wavy floor, W5 damped
spheres dropped onto a flat floor at 100, 1024 and 10,000 spheres (``--w5-sides``), one row each,
whose final centres must also rest at the analytic height ks (contactDistance + r - h) = m g.

ms/step is the fastest batch, in CPU time by default (``--clock wall`` for the wall clock; the
machine is shared; the median is printed too). The final positions of sofac and the hand-written
loop after the same number of steps are compared (the same algorithm must give the same numbers to
rounding; W3's hand-written loop uses other, equivalent formulas: its tip displacement must agree
to 1e-6).

    python benchmarks/workloads.py                      # everything (a few minutes)
    python benchmarks/workloads.py --only w1 w2 liver   # some workloads
    python benchmarks/workloads.py --markdown table.md  # also write the table as Markdown
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

# Single-threaded like everything else compared here (and no idle BLAS threads spinning on the
# second core while the C++ loops run).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))

import scenegen  # noqa: E402
from machine import describe  # noqa: E402

HANDWRITTEN = HERE / "handwritten"
HANDWRITTEN_CHOLMOD = ("w3",)  # the loops linked with SuiteSparse's CHOLMOD
ALL = ("w1", "w2", "w3", "w3asm", "w3ldl", "w3chol", "w4", "w5", "beam", "liver")

# SOFA's measured ms/step (the minimum over runs) from shared/reference/sofa/timings.md.
SOFA_MS: dict[str, float] = {"w1": 4.02, "w2": 9.2, "beam": 27.99, "liver": 1.128}
# The targets: at least this many times faster than SOFA; at most this many times the
# hand-written loop.
SOFA_TARGET: dict[str, float] = {"w1": 20.0, "w2": 1.8, "beam": 1.8, "w3": 1.8, "liver": 10.0}
HAND_TARGET: dict[str, float] = {"w1": 1.2, "w2": 1.3, "w3": 1.3, "w3asm": 1.3, "w3ldl": 1.3, "w3chol": 1.3}
# The W3 beam is SOFA's e_beam_large_cg25 apart from its length (5 m here, 4 m there) and the
# tetrahedral split (Hexa2TetraTopologicalMapping here, the grid's own there): same counts.
SOFA_OF = {"w3": "beam"}
# W3's hand-written solvers (w3.cpp's SOLVER argument), implementation name and note: the first is
# the reference of the "x hand-written" column, the others are shown beside it.
W3_HANDWRITTEN: dict[str, tuple[tuple[str, str, str], ...]] = {
    "w3": (
        ("cg-assembled", "hand-written C++", "K assembled each step (3x3 blocks)"),
        ("cg", "hand-written C++ (matrix-free)", "element products, rotated shape gradients"),
    ),
    # W3 with CGLinearSolver on the assembled matrix (w3_beam_cg25_assembled.scn): the same reference
    "w3asm": (("cg-assembled", "hand-written C++", "K assembled each step (3x3 blocks)"),),
    # SparseLDLSolver is a simplicial L D L^T in SOFA and sofac: the same algorithm by hand is the
    # reference; CHOLMOD's default (a supernodal L L^T, another factorisation) is shown beside it.
    "w3ldl": (
        ("cholmod-simplicial", "hand-written C++", "CHOLMOD simplicial LDL^T, as sofac and SOFA"),
        ("cholmod", "hand-written C++ (supernodal LL^T)", "CHOLMOD's defaults"),
    ),
    "w3chol": (("cholmod", "hand-written C++", "CHOLMOD's defaults"),),
}
# W3 (b)'s scenes: SOFA's SparseLDLSolver (L D L^T) and SparseCholeskySolver (L L^T).
W3_DIRECT = {"w3ldl": "ldl", "w3chol": "cholesky"}


@dataclass
class Row:
    workload: str
    implementation: str
    ms: float  # fastest batch, ms per step
    median_ms: float
    note: str = ""
    final: np.ndarray | None = field(default=None, repr=False)


@dataclass
class Setup:
    n: int = 100
    w1_steps: int = 1000
    w2_steps: int = 100
    w3_steps: int = 100
    ldl_steps: int = 10
    liver_steps: int = 500
    w4_steps: int = 1000
    w4_size: tuple[int, int] = (64, 64)  # W4: particles per side, floor squares per side
    w5_steps: int = 500
    w5_sides: tuple[int, ...] = (10, 32, 100)  # W5: spheres per side, one workload row each
    batches: int = 3
    check_steps: int = 10  # the short run whose final positions must agree to rounding
    beam_grid: tuple[int, int, int] = (10, 10, 50)  # W3's grid points along x, y, z
    workdir: Path = field(default_factory=lambda: Path(tempfile.gettempdir()))


# ---- shared material --------------------------------------------------------------------------


def find_shared() -> Path | None:
    """``../shared`` beside the checkout, else ``$SOFAC_SHARED``."""
    candidates = [REPO.parent / "shared"]
    if os.environ.get("SOFAC_SHARED"):
        candidates.append(Path(os.environ["SOFAC_SHARED"]))
    return next((c for c in candidates if (c / "corpus" / "sofa").is_dir()), None)


# ---- sofac ------------------------------------------------------------------------------------


# The clock batches are timed with: the process's CPU time by default (on a shared machine, the
# time slices other processes take do not count; their effect on the caches still does), or the
# wall clock (--clock wall). The hand-written loops read SOFAC_BENCH_CLOCK (cloth_io.h's bench_ms).
CLOCKS: dict[str, Callable[[], float]] = {"cpu": time.process_time, "wall": time.perf_counter}
clock = CLOCKS["cpu"]


def time_sofac(scene: Path, warmup: int, steps: int, batches: int) -> tuple[list[float], np.ndarray, float]:
    """ms per step of each batch, the first state's final positions, and the load time in s."""
    import sofac

    started = time.perf_counter()
    sim = sofac.load(scene)
    loaded = time.perf_counter() - started
    if warmup:
        sim.step(warmup)
    times = []
    for _ in range(batches):
        t0 = clock()
        sim.step(steps)
        times.append((clock() - t0) * 1e3 / steps)
    state = sim[sim.objects()[0]]
    return times, np.array(state.position, dtype=float), loaded


# ---- hand-written C++ -------------------------------------------------------------------------


def handwritten_flags() -> list[str]:
    """The flags sofac compiles the cloth scenes with (a large scene: ``-O3``), without those that
    make a shared library."""
    from sofac.build.compiler import LARGE_SCENE_FLAGS

    return [f for f in LARGE_SCENE_FLAGS if f not in ("-shared", "-fPIC", "-fvisibility=hidden", "-w")]


def build_handwritten(name: str, out: Path) -> Path:
    """Compile ``handwritten/NAME.cpp`` into ``out`` (W3 with CHOLMOD); returns the executable."""
    from sofac.build.compiler import SUITESPARSE_INCLUDE, compiler

    out.mkdir(parents=True, exist_ok=True)
    exe = out / name
    cholmod = ([f"-I{SUITESPARSE_INCLUDE}"], ["-lcholmod"]) if name in HANDWRITTEN_CHOLMOD else ([], [])
    command = [
        compiler(),
        *handwritten_flags(),
        *cholmod[0],
        str(HANDWRITTEN / f"{name}.cpp"),
        "-o",
        str(exe),
        *cholmod[1],
    ]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{done.stderr}")
    return exe


def write_cloth_input(path: Path, cloth: scenegen.Cloth) -> None:
    """The binary cloth file read by ``handwritten/cloth_io.h``."""
    a = np.array([s[0] for s in cloth.springs], dtype=np.int64)
    b = np.array([s[1] for s in cloth.springs], dtype=np.int64)
    rest = np.array([s[2] for s in cloth.springs], dtype=np.float64)
    header = np.array([len(cloth.positions), len(cloth.springs), len(cloth.fixed)], dtype=np.int64)
    with path.open("wb") as file:
        for array in (
            header,
            np.array(cloth.positions, dtype=np.float64).ravel(),
            a,
            b,
            rest,
            np.array(cloth.fixed, dtype=np.int64),
        ):
            file.write(array.tobytes())


def write_beam_input(path: Path, beam: scenegen.Beam) -> None:
    """The binary mesh file read by ``handwritten/w3.cpp``."""
    header = np.array([len(beam.positions), len(beam.tetrahedra), len(beam.fixed)], dtype=np.int64)
    with path.open("wb") as file:
        for array in (
            header,
            np.array(beam.positions, dtype=np.float64).ravel(),
            np.array(beam.tetrahedra, dtype=np.int64).ravel(),
            np.array(beam.fixed, dtype=np.int64),
        ):
            file.write(array.tobytes())


def run_handwritten(exe: Path, input_file: Path, args: Sequence[object]) -> tuple[dict[str, Any], np.ndarray]:
    """Run a hand-written loop: its JSON report and its final positions (points x 3)."""
    final = input_file.with_suffix(f".{exe.name}.out")
    done = subprocess.run(
        [str(exe), str(input_file), str(final), *(repr(a) if isinstance(a, float) else str(a) for a in args)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "SOFAC_BENCH_CLOCK": "wall" if clock is CLOCKS["wall"] else "cpu"},
    )
    report = json.loads(done.stdout)
    return report, np.fromfile(final, dtype=np.float64).reshape(-1, 3)


# ---- NumPy / SciPy ----------------------------------------------------------------------------


class ClothArrays:
    """The cloth as NumPy arrays."""

    def __init__(self, cloth: scenegen.Cloth) -> None:
        self.x0 = np.array(cloth.positions, dtype=float)
        self.a = np.array([s[0] for s in cloth.springs], dtype=np.int64)
        self.b = np.array([s[1] for s in cloth.springs], dtype=np.int64)
        self.rest = np.array([s[2] for s in cloth.springs], dtype=float)
        self.free = np.ones(len(self.x0), dtype=bool)
        self.free[list(cloth.fixed)] = False
        self.n = len(self.x0)

    def forces(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """f (n x 3) = m g + springs, and per spring the unit direction, length and intensity."""
        u = x[self.b] - x[self.a]
        d = np.sqrt(np.einsum("ij,ij->i", u, u))
        u /= d[:, None]
        intensity = scenegen.CLOTH_STIFFNESS * (d - self.rest)
        fs = u * intensity[:, None]
        f = np.empty_like(x)
        for c in range(3):
            f[:, c] = np.bincount(self.a, fs[:, c], self.n) - np.bincount(self.b, fs[:, c], self.n)
        f[:, 1] += scenegen.CLOTH_VERTEX_MASS * scenegen.GRAVITY[1]
        return f, u, d, intensity


def numpy_cg(A: Any, b: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, int]:
    """CGLinearSolver's rules at tolerance = threshold = 0 (handwritten/cg.h): from 0, at most
    CG_ITERATIONS iterations, stopping once r.r or p.Ap is exactly 0; every product projected by
    ``free`` (1 for a free DOF, 0 for a fixed one). Returns the solution and the iterations done."""
    dv = np.zeros_like(b)
    r, p = b.copy(), np.zeros_like(b)
    rho_previous = 1.0
    done = 0
    if r @ r != 0.0:
        for iteration in range(1, scenegen.CG_ITERATIONS + 1):
            rho = r @ r
            if iteration > 1 and rho == 0.0:
                break
            p = r + (rho / rho_previous) * p if iteration > 1 else r.copy()
            q = free * (A @ p)
            den = p @ q
            if den == 0.0:
                break
            alpha = rho / den
            dv += alpha * p
            r -= alpha * q
            rho_previous = rho
            done = iteration
    return dv, done


def numpy_w1(
    cloth: scenegen.Cloth, warmup: int, steps: int, batches: int, extra: int = 0
) -> tuple[list[float], np.ndarray]:
    """Vectorised symplectic Euler; ``extra`` untimed steps follow the batches."""
    arrays = ClothArrays(cloth)
    x, v = arrays.x0.copy(), np.zeros_like(arrays.x0)
    scale = np.where(arrays.free, scenegen.W1_DT / scenegen.CLOTH_VERTEX_MASS, 0.0)[:, None]

    def step() -> None:
        f = arrays.forces(x)[0]
        v[...] += scale * f
        x[...] += scenegen.W1_DT * v

    times = _timed(step, warmup, steps, batches)
    for _ in range(extra):
        step()
    return times, x


def scipy_w2(
    cloth: scenegen.Cloth, warmup: int, steps: int, batches: int, extra: int = 0
) -> tuple[list[float], np.ndarray, int]:
    """K assembled as a scipy.sparse matrix each step, b = h (f + h K v), then CG on the projected
    system P (M - h^2 K) P from 0, exactly as SOFA's CGLinearSolver with tolerance = threshold = 0
    (a NumPy loop around the sparse product: scipy.sparse.linalg.cg with rtol = 0 divides 0 by 0
    when a residual reaches exactly 0). ``extra`` untimed steps follow the batches. Also returns
    the fewest CG iterations any step ran."""
    import scipy.sparse as sp

    arrays = ClothArrays(cloth)
    h, m, k = scenegen.W2_DT, scenegen.CLOTH_VERTEX_MASS, scenegen.CLOTH_STIFFNESS
    x, v = arrays.x0.copy(), np.zeros_like(arrays.x0)
    size = 3 * arrays.n
    free = np.repeat(arrays.free, 3).astype(float)
    ia = 3 * arrays.a[:, None] + np.arange(3)  # springs x 3 DOF indices
    ib = 3 * arrays.b[:, None] + np.arange(3)
    # the four 3x3 blocks of each spring: (a,a) -J, (b,b) -J, (a,b) +J, (b,a) +J
    rows = np.concatenate([np.repeat(i, 3, axis=1).ravel() for i in (ia, ib, ia, ib)])
    cols = np.concatenate([np.tile(j, (1, 3)).ravel() for j in (ia, ib, ib, ia)])
    fewest = [scenegen.CG_ITERATIONS]

    def step() -> None:
        f, u, d, intensity = arrays.forces(x)
        t = intensity / d
        blocks = (k - t)[:, None, None] * u[:, :, None] * u[:, None, :] + t[:, None, None] * np.eye(3)
        flat = blocks.reshape(len(t), 9).ravel()
        K = sp.csr_matrix((np.concatenate([-flat, -flat, flat, flat]), (rows, cols)), shape=(size, size))
        A = m * sp.identity(size, format="csr") - (h * h) * K
        dv, done = numpy_cg(A, free * (h * (f.ravel() + h * (K @ v.ravel()))), free)
        fewest[0] = min(fewest[0], done)
        v[...] += dv.reshape(-1, 3)
        x[...] += h * v

    times = _timed(step, warmup, steps, batches)
    for _ in range(extra):
        step()
    return times, x, fewest[0]


class BeamArrays:
    """The W3 beam as NumPy arrays and its rest state, computed as w3.cpp does (independently of
    sofac): per tetrahedron the local rest edges r_1..r_3 in SOFA's "large" frame, the shape
    function gradients g_0..g_3 (rows of [r_1 r_2 r_3]^-1, g_0 = -(g_1 + g_2 + g_3)), V lambda and
    V mu; the 3x3 blocks' DOF indices for assembling K."""

    def __init__(self, beam: scenegen.Beam) -> None:
        self.x0 = np.array(beam.positions, dtype=float)
        self.tet = np.array(beam.tetrahedra, dtype=np.int64)
        self.n = len(self.x0)
        self.free = np.ones(self.n, dtype=bool)
        self.free[list(beam.fixed)] = False
        self.vertex_mass = scenegen.BEAM_TOTAL_MASS / self.n
        nu, young = scenegen.BEAM_POISSON, scenegen.BEAM_YOUNG
        frames = self.frames(self.x0)
        self.rest = self.local_edges(frames, self.x0)  # (e, k, i): local coordinate i of node k + 1
        inverse = np.linalg.inv(self.rest.transpose(0, 2, 1))  # the columns are r_1..r_3
        self.grad = np.concatenate([-inverse.sum(axis=1, keepdims=True), inverse], axis=1)  # (e, 4, 3)
        volume = np.abs(np.linalg.det(self.rest)) / 6.0
        self.vlambda = volume * young * nu / ((1 + nu) * (1 - 2 * nu))
        self.vmu = volume * young / (2 * (1 + nu))
        dofs = 3 * self.tet[:, :, None] + np.arange(3)  # (e, node a, i)
        # block (a, b) entry (i, j) of each element: row dof (a, i), column dof (b, j)
        self.rows = np.broadcast_to(dofs[:, :, None, :, None], (len(self.tet), 4, 4, 3, 3)).ravel()
        self.cols = np.broadcast_to(dofs[:, None, :, None, :], (len(self.tet), 4, 4, 3, 3)).ravel()

    def frames(self, x: np.ndarray) -> np.ndarray:
        """Each element's rotation (world -> local): rows x = edge 0->1, z = normal of (0->1, 0->2),
        y = z cross x."""
        p = x[self.tet[:, :3]]
        ex = p[:, 1] - p[:, 0]
        ex /= np.sqrt(np.einsum("ei,ei->e", ex, ex))[:, None]
        ez = np.cross(ex, p[:, 2] - p[:, 0])
        ez /= np.sqrt(np.einsum("ei,ei->e", ez, ez))[:, None]
        return np.stack([ex, np.cross(ez, ex), ez], axis=1)

    def local_edges(self, frames: np.ndarray, x: np.ndarray) -> np.ndarray:
        p = x[self.tet]
        return np.einsum("eij,ekj->eki", frames, p[:, 1:] - p[:, :1])

    def forces_and_stiffness(self, x: np.ndarray) -> tuple[np.ndarray, Any]:
        """f (3 n) = m g + elastic forces, and K (the positive stiffness, f = -K u) as a CSR matrix."""
        import scipy.sparse as sp

        frames = self.frames(x)
        d = self.local_edges(frames, x) - self.rest
        H = np.einsum("eki,ekj->eij", d, self.grad[:, 1:])  # local displacement gradient
        trace = np.einsum("eii->e", H)
        S = self.vmu[:, None, None] * (H + H.transpose(0, 2, 1)) + (self.vlambda * trace)[
            :, None, None
        ] * np.eye(3)
        local = -np.einsum("eij,eaj->eai", S, self.grad)
        world = np.einsum("eji,eaj->eai", frames, local)  # R^T f_local
        f = np.zeros(3 * self.n)
        f[1::3] = self.vertex_mass * scenegen.GRAVITY[1]
        f += np.bincount((3 * self.tet[:, :, None] + np.arange(3)).ravel(), world.ravel(), 3 * self.n)
        G = np.einsum("eji,eaj->eai", frames, self.grad)  # world gradients R^T g
        dots = np.einsum("eai,ebi->eab", G, G)
        blocks = (
            self.vlambda[:, None, None, None, None] * np.einsum("eai,ebj->eabij", G, G)
            + self.vmu[:, None, None, None, None] * np.einsum("ebi,eaj->eabij", G, G)
            + (self.vmu[:, None, None] * dots)[:, :, :, None, None] * np.eye(3)
        )
        size = 3 * self.n
        return f, sp.csr_matrix((blocks.ravel(), (self.rows, self.cols)), shape=(size, size))


def scipy_w3(
    beam: scenegen.Beam, direct: bool, warmup: int, steps: int, batches: int, extra: int = 0
) -> tuple[list[float], np.ndarray, int]:
    """W3 with SciPy, as w3.cpp and SOFA's EulerImplicitSolver do it: each step the element
    rotations, the forces and K assembled as a scipy.sparse matrix, b = h (f - rm M v - (h + rk) K v)
    on the free DOFs, then ((1 + h rm) M + h (h + rk) K) dv = b solved by 25 CG iterations in NumPy
    (SOFA's rules, as scipy_w2) or, ``direct``, by SuperLU (scipy.sparse.linalg.splu) on the free
    DOFs' matrix; v += dv, x += h v. ``extra`` untimed steps follow the batches. Also returns the
    fewest CG iterations any step ran (0 for the direct solve)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    arrays = BeamArrays(beam)
    h, m = scenegen.W3_DT, arrays.vertex_mass
    rk = rm = scenegen.BEAM_RAYLEIGH
    mfact, kfact = 1.0 + h * rm, h * (h + rk)
    size = 3 * arrays.n
    free_mask = np.repeat(arrays.free, 3)
    free = free_mask.astype(float)
    x, v = arrays.x0.ravel().copy(), np.zeros(size)
    identity = sp.identity(size, format="csr")
    fewest = [0 if direct else scenegen.CG_ITERATIONS]

    def step() -> None:
        f, K = arrays.forces_and_stiffness(x.reshape(-1, 3))
        b = free * (h * (f - rm * m * v - (h + rk) * (K @ v)))
        A = (mfact * m) * identity + kfact * K
        dv = np.zeros(size)
        if direct:
            reduced = A[free_mask][:, free_mask].tocsc()
            dv[free_mask] = spla.splu(reduced, permc_spec="MMD_AT_PLUS_A").solve(b[free_mask])
        else:
            dv, done = numpy_cg(A, b, free)
            fewest[0] = min(fewest[0], done)
        v[...] += dv
        x[...] += h * v

    times = _timed(step, warmup, steps, batches)
    for _ in range(extra):
        step()
    return times, x.reshape(-1, 3), fewest[0]


def _timed(step: Callable[[], None], warmup: int, steps: int, batches: int) -> list[float]:
    for _ in range(warmup):
        step()
    times = []
    for _ in range(batches):
        t0 = clock()
        for _ in range(steps):
            step()
        times.append((clock() - t0) * 1e3 / steps)
    return times


def have_scipy() -> bool:
    try:
        import scipy.sparse.linalg  # noqa: F401
    except ImportError:
        return False
    return True


# ---- the workloads ----------------------------------------------------------------------------


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    """max |a - b| over max |b| (positions)."""
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def row(
    workload: str, implementation: str, times: list[float], note: str = "", final: np.ndarray | None = None
) -> Row:
    return Row(workload, implementation, min(times), statistics.median(times), note, final)


def run_cloth(which: str, setup: Setup, log: Callable[[str], None]) -> tuple[list[Row], dict[str, float]]:
    """W1 or W2: sofac, hand-written, NumPy/SciPy. Also the relative differences of final positions."""
    implicit = which == "w2"
    folder = setup.workdir
    cloth = scenegen.cloth(setup.n)
    scene = folder / f"{which}_n{setup.n}.scn"
    scene.write_text(scenegen.cloth_scene(setup.n, implicit=implicit))
    cloth_file = folder / f"{which}_n{setup.n}.bin"
    write_cloth_input(cloth_file, cloth)
    steps = setup.w2_steps if implicit else setup.w1_steps
    warmup = max(1, steps // 10)
    batches = setup.batches
    label = f"{which.upper()} {setup.n}x{setup.n}"
    rows: list[Row] = []
    checks: dict[str, float] = {}

    log(f"{label}: sofac")
    times, sofac_final, loaded = time_sofac(scene, warmup, steps, batches)
    rows.append(row(which, "sofac", times, f"load {loaded:.1f} s", sofac_final))

    log(f"{label}: hand-written C++")
    exe = build_handwritten(which, folder / "bin")
    g = scenegen.GRAVITY[1]
    m, k = scenegen.CLOTH_VERTEX_MASS, scenegen.CLOTH_STIFFNESS
    if implicit:
        args: list[object] = [scenegen.W2_DT, m, k, g, scenegen.CG_ITERATIONS, warmup, steps, batches]
    else:
        args = [scenegen.W1_DT, m, k, g, warmup, steps, batches]
    report, hand_final = run_handwritten(exe, cloth_file, args)
    note = f"CG iterations per step >= {report['fewest_cg_iterations']}" if implicit else ""
    rows.append(row(which, "hand-written C++", report["ms_per_step"], note, hand_final))
    total = warmup + steps * batches
    checks[f"sofac vs hand-written, after {total} steps"] = relative_difference(sofac_final, hand_final)
    # The short run: W2's dynamics (25 CG iterations, far from converged, on a falling cloth) amplify
    # rounding differences exponentially (~1e-14 after 20 steps, 1e-8 after 40, O(0.1) after 80), so
    # the same-algorithm check compares a few steps, where both must agree to rounding.
    short = setup.check_steps
    _t, sofac_short, _l = time_sofac(scene, 0, short, 1)
    short_args = [*args[:-3], 0, short, 1]
    _r, hand_short = run_handwritten(exe, cloth_file, short_args)
    checks[f"sofac vs hand-written, after {short} steps"] = relative_difference(sofac_short, hand_short)

    if implicit and not have_scipy():
        log(f"{label}: SciPy not installed, skipped")
    else:
        log(f"{label}: {'SciPy' if implicit else 'NumPy'}")
        # slower: fewer timed steps per batch, then untimed steps up to the same step count
        np_steps = max(1, steps // 10)
        extra = (steps - np_steps) * batches
        if implicit:
            times, final, fewest = scipy_w2(cloth, warmup, np_steps, batches, extra)
            note = f"scipy.sparse K, CG in NumPy; CG iterations per step >= {fewest}"
        else:
            times, final = numpy_w1(cloth, warmup, np_steps, batches, extra)
            note = "vectorised NumPy (bincount scatter)"
        rows.append(row(which, "SciPy" if implicit else "NumPy", times, note, final))
        checks[f"NumPy/SciPy vs hand-written, after {total} steps"] = relative_difference(final, hand_final)
        short_final = scipy_w2(cloth, 0, short, 1)[1] if implicit else numpy_w1(cloth, 0, short, 1)[1]
        checks[f"NumPy/SciPy vs hand-written, after {short} steps"] = relative_difference(
            short_final, hand_short
        )
    return rows, checks


def run_beam(which: str, setup: Setup, log: Callable[[str], None]) -> tuple[list[Row], dict[str, float]]:
    """W3 (CG), W3 with CG on the assembled matrix (w3asm, with sofac's matrix-free CG beside it)
    or W3 with the sparse direct solver: sofac, the hand-written loops and (w3, w3ldl) SciPy; also the
    relative difference of the mean tip displacement (the z = L nodes) of each loop from sofac's,
    after all the steps run and, for CG, after ``check_steps`` (25 CG iterations on 15,000 DOFs
    amplify rounding differences exponentially from one step to the next, as in W2: ~6e-13 after
    20 steps, 2e-7 after 80, 1e-2 after 310; the direct solve does not)."""
    direct = which in W3_DIRECT
    nx, ny, nz = setup.beam_grid
    folder = setup.workdir
    scenes = scenegen.write_beam(folder, nx, ny, nz)
    scene = scenes[W3_DIRECT[which]] if direct else scenes["cg_assembled" if which == "w3asm" else "cg"]
    steps = setup.ldl_steps if direct else setup.w3_steps
    warmup = max(1, steps // 10)
    batches = setup.batches
    beam = scenegen.beam(nx, ny, nz)
    input_file = folder / f"w3_{nx}x{ny}x{nz}.bin"
    write_beam_input(input_file, beam)
    start = np.array(beam.positions, dtype=float)
    tip = start[:, 2] == start[:, 2].max()

    def tip_displacement(final: np.ndarray) -> np.ndarray:
        return np.asarray((final[tip] - start[tip]).mean(axis=0))

    label = f"{which.upper()} {nx}x{ny}x{nz}"
    log(f"{label}: sofac")
    times, sofac_final, loaded = time_sofac(scene, warmup, steps, batches)
    rows = [row(which, "sofac", times, f"{scene.name}, load {loaded:.1f} s", sofac_final)]
    if which == "w3asm":
        log(f"{label}: sofac, matrix-free CG")
        free_times, _free_final, free_loaded = time_sofac(scenes["cg"], warmup, steps, batches)
        note = f"{scenes['cg'].name} (as w3), load {free_loaded:.1f} s"
        rows.append(row(which, "sofac (matrix-free CG)", free_times, note))
    sofac_tip = tip_displacement(sofac_final)
    checks: dict[str, float] = {}
    exe = build_handwritten("w3", folder / "bin")
    total = warmup + steps * batches
    short = setup.check_steps
    sofac_short = tip_displacement(time_sofac(scene, 0, short, 1)[1]) if not direct else None
    for solver, implementation, note in W3_HANDWRITTEN[which]:
        log(f"{label}: {implementation}")
        args = [
            scenegen.W3_DT,
            scenegen.BEAM_TOTAL_MASS / len(beam.positions),
            scenegen.BEAM_YOUNG,
            scenegen.BEAM_POISSON,
            scenegen.GRAVITY[1],
            scenegen.BEAM_RAYLEIGH,
            scenegen.BEAM_RAYLEIGH,
            solver,
            scenegen.CG_ITERATIONS,
            warmup,
            steps,
            batches,
        ]
        report, final = run_handwritten(exe, input_file, args)
        if report.get("failed"):
            raise RuntimeError(f"w3 {solver}: CHOLMOD's factorisation failed")
        phases = report["phase_ms"]
        if direct:
            note += (
                f"; {report['factor']}, {report['flops'] / 1e9:.2f} GFlop, "
                f"factorisation {phases['factor']:.4g} ms/step"
            )
        else:
            note += f"; forces{' + K' if solver == 'cg-assembled' else ''} {phases['forces']:.3g} ms/step"
        rows.append(row(which, implementation, report["ms_per_step"], note, final))
        checks[f"tip displacement, sofac vs {implementation}, after {total} steps"] = relative_norm(
            tip_displacement(final) - sofac_tip, sofac_tip
        )
        if sofac_short is not None:
            final = run_handwritten(exe, input_file, [*args[:-3], 0, short, 1])[1]
            checks[f"tip displacement, sofac vs {implementation}, after {short} steps"] = relative_norm(
                tip_displacement(final) - sofac_short, sofac_short
            )
    if which in ("w3", "w3ldl") and not have_scipy():
        log(f"{label}: SciPy not installed, skipped")
    elif which in ("w3", "w3ldl"):
        log(f"{label}: SciPy")
        # CG is slower than the C++ loops: fewer timed steps per batch, then untimed steps up to
        # the same step count (the direct solve times as many steps as the others)
        np_steps = steps if direct else max(1, steps // 10)
        times, final, fewest = scipy_w3(beam, direct, warmup, np_steps, batches, (steps - np_steps) * batches)
        if direct:
            note = "scipy.sparse K; SuperLU (splu, MMD on A^T + A) on the free DOFs, not CHOLMOD"
        else:
            note = f"scipy.sparse K, CG in NumPy; CG iterations per step >= {fewest}"
        rows.append(row(which, "SciPy", times, note, final))
        checks[f"tip displacement, sofac vs SciPy, after {total} steps"] = relative_norm(
            tip_displacement(final) - sofac_tip, sofac_tip
        )
        if sofac_short is not None:
            final = scipy_w3(beam, direct, 0, short, 1)[1]
            checks[f"tip displacement, sofac vs SciPy, after {short} steps"] = relative_norm(
                tip_displacement(final) - sofac_short, sofac_short
            )
    return rows, checks


def write_particles_input(path: Path, scene: scenegen.Particles) -> None:
    """The binary file read by ``handwritten/w4.cpp``."""
    with path.open("wb") as out:
        header = [len(scene.positions), len(scene.floor), len(scene.triangles)]
        np.array(header, dtype=np.int64).tofile(out)
        np.array(scene.positions, dtype=np.float64).tofile(out)
        np.array(scene.floor, dtype=np.float64).tofile(out)
        np.array(scene.triangles, dtype=np.int64).tofile(out)


def run_contact(setup: Setup, log: Callable[[str], None]) -> tuple[list[Row], dict[str, float]]:
    """W4: sofac's compiled pipeline (trees, broad and narrow phase, SOFA's contact order) against a
    hand-written loop that bins the static floor once into a grid."""
    n, m = setup.w4_size
    folder = setup.workdir
    scene = folder / f"w4_n{n}_m{m}.scn"
    scene.write_text(scenegen.contact_scene(n, m))
    data = folder / f"w4_n{n}_m{m}.bin"
    write_particles_input(data, scenegen.particles(n, m))
    steps, batches = setup.w4_steps, setup.batches
    warmup = max(1, steps // 10)
    label = f"W4 {n}x{n} particles, {2 * m * m} floor triangles"

    log(f"{label}: sofac")
    times, sofac_final, loaded = time_sofac(scene, warmup, steps, batches)
    rows = [row("w4", "sofac", times, f"load {loaded:.1f} s", sofac_final)]
    log(f"{label}: hand-written C++")
    exe = build_handwritten("w4", folder / "bin")
    k = scenegen.W4_CONTACT_STIFFNESS
    args: list[object] = [scenegen.W4_DT, scenegen.W4_PARTICLE_MASS, k, k, scenegen.W4_ALARM]
    args += [scenegen.W4_CONTACT, scenegen.GRAVITY[1], warmup, steps, batches]
    report, hand_final = run_handwritten(exe, data, args)
    note = "floor binned once in a grid"
    rows.append(row("w4", "hand-written C++", report["ms_per_step"], note, hand_final))
    total = warmup + steps * batches
    # The contact points differ in their last bits (sofac maps them from barycentric weights, as SOFA
    # does; the loop keeps the projection), so the runs agree to rounding amplified by the bounces.
    return rows, {f"sofac vs hand-written, after {total} steps": relative_difference(sofac_final, hand_final)}


def run_spheres(setup: Setup, log: Callable[[str], None]) -> tuple[list[Row], dict[str, dict[str, float]]]:
    """W5 at each size of ``setup.w5_sides``: damped spheres dropped onto a flat floor, sofac's
    compiled pipeline against a hand-written loop that bins the floor once into a grid. Checks: the
    final positions agree, and both rest at the analytic height ks (contact + r - h) = m g."""
    folder = setup.workdir
    exe = build_handwritten("w5", folder / "bin")
    steps, batches = setup.w5_steps, setup.batches
    warmup = max(1, steps // 10)
    total = warmup + steps * batches
    rest = scenegen.w5_rest_height()
    rows: list[Row] = []
    checks: dict[str, dict[str, float]] = {}
    for n in setup.w5_sides:
        workload = f"w5-{n * n}"
        spheres = scenegen.spheres(n)
        scene = folder / f"w5_n{n}.scn"
        scene.write_text(scenegen.sphere_scene(n))
        data = folder / f"w5_n{n}.bin"
        write_particles_input(data, spheres)
        label = f"W5 {n}x{n} spheres, {len(spheres.triangles)} floor triangles"
        log(f"{label}: sofac")
        times, sofac_final, loaded = time_sofac(scene, warmup, steps, batches)
        rows.append(row(workload, "sofac", times, f"load {loaded:.1f} s", sofac_final))
        log(f"{label}: hand-written C++")
        args: list[object] = [scenegen.W5_DT, scenegen.W5_MASS, scenegen.W5_RADIUS]
        args += [scenegen.W5_FLOOR_STIFFNESS, scenegen.W5_SPHERE_STIFFNESS, scenegen.W5_ALARM]
        args += [scenegen.W5_CONTACT, scenegen.W5_DAMPING, scenegen.GRAVITY[1], warmup, steps, batches]
        report, hand_final = run_handwritten(exe, data, args)
        note = "floor binned once in a grid"
        rows.append(row(workload, "hand-written C++", report["ms_per_step"], note, hand_final))
        # sofac's contact point on the triangle is mapped back from barycentric weights (as SOFA does),
        # the loop keeps the projection: the same numbers to their last bits, damped out at rest.
        checks[workload] = {
            f"sofac vs hand-written, after {total} steps": relative_difference(sofac_final, hand_final),
            f"rest height, sofac, after {total} steps": float(np.max(np.abs(sofac_final[:, 1] - rest))),
            f"rest height, hand-written, after {total} steps": float(np.max(np.abs(hand_final[:, 1] - rest))),
        }
    return rows, checks


def relative_norm(difference: np.ndarray, reference: np.ndarray) -> float:
    return float(np.linalg.norm(difference) / max(float(np.linalg.norm(reference)), 1e-300))


def run_scene(workload: str, scene: Path, steps: int, setup: Setup, log: Callable[[str], None]) -> Row:
    log(f"{workload}: sofac {scene.name}")
    times, _final, loaded = time_sofac(scene, max(1, steps // 10), steps, setup.batches)
    return row(workload, "sofac", times, f"{scene.name}, load {loaded:.1f} s")


def run(
    workloads: Sequence[str], setup: Setup, log: Callable[[str], None]
) -> tuple[list[Row], dict[str, dict[str, float]]]:
    rows: list[Row] = []
    checks: dict[str, dict[str, float]] = {}
    shared = find_shared()
    for workload in workloads:
        if workload in ("w1", "w2"):
            found, check = run_cloth(workload, setup, log)
            rows += found
            checks[workload] = check
        elif workload in ("w3", "w3asm", *W3_DIRECT):
            found, check = run_beam(workload, setup, log)
            rows += found
            checks[workload] = check
        elif workload == "w4":
            found, check = run_contact(setup, log)
            rows += found
            checks[workload] = check
        elif workload == "w5":
            found, by_size = run_spheres(setup, log)
            rows += found
            checks.update(by_size)
        elif workload == "beam":
            scene = (
                shared / "reference" / "sofa" / "scenes" / "e_beam_large_cg25_noexport.scn"
                if shared
                else None
            )
            if scene is None or not scene.is_file():
                log("beam: shared/reference/sofa not found, skipped")
                continue
            rows.append(run_scene("beam", scene, setup.w3_steps, setup, log))
        elif workload == "liver":
            scene = shared / "corpus" / "sofa" / "Demos" / "liver.scn" if shared else None
            if scene is None or not scene.is_file():
                log("liver: shared/corpus/sofa not found, skipped")
                continue
            rows.append(run_scene("liver", scene, setup.liver_steps, setup, log))
        else:
            raise ValueError(f"unknown workload {workload!r}; known: {', '.join(ALL)}")
    return rows, checks


# ---- the table ----------------------------------------------------------------------------------


def table(rows: Sequence[Row], sofa: bool = True) -> list[list[str]]:
    """workload, implementation, ms/step (min), median, / hand-written, SOFA / this, target, met.

    ``sofa``: compare W1/W2 with SOFA's figures (only meaningful at N = 100)."""
    sofa_ms = SOFA_MS if sofa else {k: v for k, v in SOFA_MS.items() if k not in ("w1", "w2")}
    out = [
        [
            "workload",
            "implementation",
            "ms/step",
            "median",
            "x hand-written",
            "SOFA faster by",
            "target",
            "met",
            "note",
        ]
    ]
    hand = {r.workload: r.ms for r in rows if r.implementation == "hand-written C++"}
    for workload in dict.fromkeys(r.workload for r in rows):
        sofa_key = SOFA_OF.get(workload, workload)
        for r in (r for r in rows if r.workload == workload):
            to_hand = f"{r.ms / hand[workload]:.2f}" if workload in hand else "-"
            to_sofa = f"{sofa_ms[sofa_key] / r.ms:.2f}" if sofa_key in sofa_ms else "-"
            target, met = "", ""
            if r.implementation == "sofac":
                goals, results = [], []
                if sofa_key in sofa_ms and workload in SOFA_TARGET:
                    goals.append(f">= {SOFA_TARGET[workload]:g}x faster than SOFA")
                    results.append(sofa_ms[sofa_key] / r.ms >= SOFA_TARGET[workload])
                if workload in HAND_TARGET:
                    goals.append(f"<= {HAND_TARGET[workload]:g}x hand-written")
                    results.append(workload in hand and r.ms / hand[workload] <= HAND_TARGET[workload])
                target = "; ".join(goals)
                met = "; ".join(
                    ("met" if ok else "not met")
                    if (g.startswith(">=") or workload in hand)
                    else "no hand-written loop"
                    for g, ok in zip(goals, results, strict=True)
                )
            out.append(
                [
                    workload,
                    r.implementation,
                    f"{r.ms:.4g}",
                    f"{r.median_ms:.4g}",
                    to_hand,
                    to_sofa,
                    target,
                    met,
                    r.note,
                ]
            )
        if sofa_key in sofa_ms:
            ms = sofa_ms[sofa_key]
            to_hand = f"{ms / hand[workload]:.2f}" if workload in hand else "-"
            source = "timings.md" + (" (e_beam_large_cg25)" if sofa_key != workload else "")
            out.append([workload, "SOFA (reference)", f"{ms:.4g}", "", to_hand, "1.00", "", "", source])
    return out


def render(cells: list[list[str]], markdown: bool) -> str:
    if markdown:
        lines = ["| " + " | ".join(cells[0]) + " |", "|" + "---|" * len(cells[0])]
        lines += ["| " + " | ".join(c) + " |" for c in cells[1:]]
        return "\n".join(lines)
    widths = [max(len(r[i]) for r in cells) for i in range(len(cells[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in cells]
    lines.insert(1, "-" * len(lines[0]))
    return "\n".join(lines)


def checks_text(checks: dict[str, dict[str, float]]) -> str:
    lines = []
    for workload, found in checks.items():
        for what, value in found.items():
            if what.startswith("rest height"):
                rest = scenegen.w5_rest_height()
                lines.append(f"{workload.upper()} {what}: max |y - h| = {value:.3g} m (h = {rest:.6g} m)")
            elif what.startswith("tip displacement"):
                lines.append(f"{workload.upper()} {what}: |difference| / |sofac's| = {value:.3g}")
            else:
                lines.append(
                    f"{workload.upper()} final positions, {what}: max |difference| / max |x| = {value:.3g}"
                )
    return "\n".join(lines)


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--only", nargs="+", choices=ALL, default=list(ALL), help="workloads to run")
    parser.add_argument("--n", type=int, default=100, help="cloth size N for W1/W2 (default 100)")
    parser.add_argument("--w1-steps", type=int, default=1000, help="W1 steps per batch (default 1000)")
    parser.add_argument("--w2-steps", type=int, default=100, help="W2 steps per batch (default 100)")
    parser.add_argument(
        "--w3-steps", type=int, default=100, help="W3 CG / beam steps per batch (default 100)"
    )
    parser.add_argument(
        "--ldl-steps", type=int, default=10, help="W3 (b) sparse direct steps per batch (default 10)"
    )
    parser.add_argument("--liver-steps", type=int, default=500, help="liver steps per batch (default 500)")
    parser.add_argument("--w4-steps", type=int, default=1000, help="W4 steps per batch (default 1000)")
    parser.add_argument("--w5-steps", type=int, default=500, help="W5 steps per batch (default 500)")
    parser.add_argument(
        "--w5-sides",
        type=int,
        nargs="+",
        default=[10, 32, 100],
        help="W5 spheres per side, one row each (default 10 32 100: 100, 1024, 10000 spheres)",
    )
    parser.add_argument(
        "--batches", type=int, default=3, help="timed batches (default 3; the fastest is shown)"
    )
    parser.add_argument(
        "--check-steps", type=int, default=10, help="steps of the W1/W2/W3-CG agreement check (10)"
    )
    parser.add_argument("--markdown", type=Path, help="also write the table (Markdown) to this file")
    parser.add_argument("--json", type=Path, help="also write the rows and checks as JSON")
    parser.add_argument(
        "--clock",
        choices=sorted(CLOCKS),
        default="cpu",
        help="time batches by the process's CPU time (default) or the wall clock",
    )
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    global clock
    args = parse_args(argv)
    clock = CLOCKS[args.clock]
    if shutil.which(os.environ.get("CXX", "g++")) is None:
        print("workloads: no C++ compiler (g++ or $CXX)", file=sys.stderr)
        return 2
    started = datetime.datetime.now()
    before = describe()
    with tempfile.TemporaryDirectory(prefix="sofac-bench-") as tmp:
        setup = Setup(
            n=args.n,
            w1_steps=args.w1_steps,
            w2_steps=args.w2_steps,
            w3_steps=args.w3_steps,
            ldl_steps=args.ldl_steps,
            liver_steps=args.liver_steps,
            w4_steps=args.w4_steps,
            w5_steps=args.w5_steps,
            w5_sides=tuple(args.w5_sides),
            batches=args.batches,
            check_steps=args.check_steps,
            workdir=Path(tmp),
        )
        rows, checks = run(args.only, setup, lambda s: print(f"... {s}", file=sys.stderr, flush=True))
    cells = table(rows, sofa=args.n == 100)
    header = f"{started:%Y-%m-%d %H:%M}; {args.clock} clock; before: {before}; after: {describe()}"
    print(header)
    print(render(cells, markdown=False))
    print(checks_text(checks))
    if args.markdown:
        args.markdown.write_text(f"{header}\n\n{render(cells, markdown=True)}\n\n{checks_text(checks)}\n")
    if args.json:
        payload = {
            "header": header,
            "rows": [{k: v for k, v in r.__dict__.items() if k != "final"} for r in rows],
            "checks": checks,
        }
        args.json.write_text(json.dumps(payload, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
