"""No heap allocation inside a step, checked with a counting allocator.

A small C library (tests/data/alloc/count_alloc.c) is preloaded into a fresh Python process
(LD_PRELOAD, glibc): it forwards malloc, calloc, realloc and the aligned allocators to glibc and
counts the calls a thread makes between sofac_alloc_count_start() and sofac_alloc_count_stop().
Every C++ ``new`` and every allocation by Eigen or CHOLMOD ends in one of these. The scenes are
stepped a few times first (the first steps may size workspaces: CHOLMOD's solve and the permuted
matrix of the factorisation are allocated once), then the native step (the compiled library, called
through the host module) is counted over 1 and 20 steps: both must allocate nothing."""

from __future__ import annotations

import importlib
import json
import os
import platform
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
BENCHMARKS = REPO / "benchmarks"
SHIM = Path(__file__).resolve().parent / "data" / "alloc" / "count_alloc.c"

PROBE = r"""
import ctypes, json, sys
import sofac

counter = ctypes.CDLL(None)
counter.sofac_alloc_count_stop.restype = ctypes.c_long


def counted(action):
    counter.sofac_alloc_count_start()
    action()
    return counter.sofac_alloc_count_stop()


results = {"control": counted(lambda: bytearray(1 << 20))}
for path in sys.argv[1:]:
    sim = sofac.load(path)
    native = sim._native  # the compiled step, without the Python wrapper's bookkeeping
    native.step(3)
    results[path] = [counted(lambda: native.step(1)), counted(lambda: native.step(20))]
print(json.dumps(results))
"""


@pytest.fixture(scope="module")
def shim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        pytest.skip("the counting allocator needs glibc")
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        pytest.skip("no C compiler")
    out = tmp_path_factory.mktemp("alloc") / "libcount_alloc.so"
    subprocess.run([compiler, "-O2", "-shared", "-fPIC", str(SHIM), "-o", str(out)], check=True)
    return out


def allocations(shim: Path, scenes: list[Path]) -> dict[str, list[int]]:
    env = {**os.environ, "LD_PRELOAD": str(shim), "OPENBLAS_NUM_THREADS": "1"}
    result = subprocess.run(
        [sys.executable, "-c", PROBE, *map(str, scenes)],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    counts = json.loads(result.stdout.strip().splitlines()[-1])
    assert counts.pop("control") >= 1  # the counter sees allocations made in the window
    return counts


def test_bundled_scenes_do_not_allocate_in_a_step(shim: Path) -> None:
    # explicit rigid + mapping, explicit springs, implicit CG springs, implicit CG FEM
    names = ["hybrid_pendulum.scn", "oscillator.scn", "cloth.scn", "beam.scn"]
    counts = allocations(shim, [REPO / "scenes" / name for name in names])
    assert counts == {str(REPO / "scenes" / name): [0, 0] for name in names}


def test_corpus_scenes_do_not_allocate_in_a_step(shim: Path, shared_dir: Path) -> None:
    preconditioners = shared_dir / "corpus/sofa/Component/LinearSolver/Preconditioner"
    scenes = [
        shared_dir / "corpus/sofa/Demos/liver.scn",  # CG, tetrahedral FEM, barycentric mapping
        shared_dir / "reference/sofa/scenes/c2_beam_tetfem_ldl.scn",  # SparseLDLSolver: factorised each step
        shared_dir / "corpus/sofa/Component/LinearSolver/Direct/FEMBAR_PrecomputedLinearSolver.scn",
        # L L^T (runtime/sofac/direct.h's supernodal kernel)
        shared_dir / "corpus/sofa/Component/LinearSolver/Direct/FEMBAR_EigenSimplicialLLT.scn",
        preconditioners / "FEMBAR_PCG_JacobiPreconditioner.scn",
        preconditioners / "FEMBAR_PCG_PrecomputedWarpPreconditioner.scn",  # no PCG iteration
        # CG on the assembled matrix (CompressedRowSparseMatrixMat3x3): values refilled each step
        shared_dir / "corpus/sofa/Component/LinearSolver/Iterative/FEMBAR_CGLinearSolver_assembled.scn",
        # SparseLDLSolver through RigidMapping: J refilled and J^T K J assembled every step
        shared_dir / "corpus/sofa/Component/LinearSystem/CompositeLinearSystem.scn",
    ]
    counts = allocations(shim, scenes)
    assert counts == {str(path): [0, 0] for path in scenes}


def test_variational_symplectic_solver_does_not_allocate_in_a_step(shim: Path, tmp_path: Path) -> None:
    # Newton iterations, the Hamiltonian's extra solve, CG and a factorised direct solver.
    scene = (REPO / "scenes" / "oscillator.scn").read_text()
    paths = []
    for name, linear in (
        ("cg", '<CGLinearSolver iterations="50" tolerance="1e-12"/>'),
        ("ldl", "<SparseLDLSolver/>"),
    ):
        path = tmp_path / f"vss_{name}.scn"
        path.write_text(
            scene.replace(
                '<EulerExplicitSolver name="odesolver" symplectic="1"/>',
                f'<VariationalSymplecticSolver steps="3" newtonError="0"/>{linear}',
            )
        )
        paths.append(path)
    counts = allocations(shim, paths)
    assert counts == {str(path): [0, 0] for path in paths}


def test_fast_tetrahedral_corotational_does_not_allocate_in_a_step(shim: Path, tmp_path: Path) -> None:
    # SOFA's example (four methods, EigenSimplicialLDLT: assembled) and a matrix-free CG (K dx on edges)
    example = Path(
        "/work/sofa-tree/examples/Component/SolidMechanics/FEM/FastTetrahedralCorotationalForceField.scn"
    )
    if not example.is_file():
        pytest.skip("SOFA's examples tree is not extracted at /work/sofa-tree")
    matrix_free = tmp_path / "fast_tetra_cg.scn"
    matrix_free.write_text(
        example.read_text().replace(
            '<EigenSimplicialLDLT template="CompressedRowSparseMatrixMat3x3"/>',
            '<CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/>',
        )
    )
    assert "CGLinearSolver" in matrix_free.read_text()
    counts = allocations(shim, [example, matrix_free])
    assert counts == {str(example): [0, 0], str(matrix_free): [0, 0]}


def test_supernodal_cholesky_does_not_allocate_in_a_step(shim: Path, tmp_path: Path) -> None:
    # W3's SparseCholeskySolver beam at 8x8x20 nodes (1.2e8 flops per factorisation): many
    # supernodes, each updated by its descendants, in runtime/sofac/direct.h's SupernodalCholesky
    # (CHOLMOD's cholmod_super_numeric allocated 2,753 times per step here).
    sys.path.insert(0, str(BENCHMARKS))
    try:
        scenegen = importlib.import_module("scenegen")
    finally:
        sys.path.remove(str(BENCHMARKS))
    path = tmp_path / "w3_beam_cholesky_8x8x20.scn"
    path.write_text(scenegen.beam_scene("cholesky", 8, 8, 20))
    assert allocations(shim, [path]) == {str(path): [0, 0]}


def test_contact_scenes_do_not_allocate_in_a_step(shim: Path, shared_dir: Path, tmp_path: Path) -> None:
    # Penalty contact (runtime/sofac/penalty.h): trees refitted, broad and narrow phase, the stable
    # maps' nodes from their pool, contact points and forces in buffers reserved at init.
    data = REPO / "tests" / "data"
    touching = tmp_path / "two_particles_touching.scn"  # in contact from the first step
    touching.write_text(
        (data / "contact_two_particles.scn")
        .read_text()
        .replace('"-0.5 0 0"', '"-0.2 0 0"')
        .replace('"0.5 0.01 0"', '"0.2 0.01 0"')
    )
    far = tmp_path / "liver_far_floor.scn"
    far.write_text((REPO / "scenes" / "liver_on_floor.scn").read_text().replace(" -0.12 ", " -10000 "))
    for mesh in ("liver.msh", "liver-surface.obj"):
        shutil.copy(REPO / "scenes" / mesh, tmp_path / mesh)
    scenes = [
        data / "contact_particle_floor.scn",  # a static partner: in the particle's group (CG)
        touching,  # two simulated models: explicit, at the step's start
        data / "contact_sphere_floor.scn",
        # a chain of tori held by contacts: NewProximity triangle-triangle, barycentric contact points
        shared_dir / "corpus/sofa/Component/SolidMechanics/Spring/MeshSpringForceField.scn",
        REPO / "scenes" / "liver_on_floor.scn",  # collision points mapped when near; lands at step 20
        far,  # its floor 10 km down: detections that leave the points unmapped
    ]
    counts = allocations(shim, scenes)
    assert counts == {str(path): [0, 0] for path in scenes}


def test_lagrangian_contact_scenes_do_not_allocate_in_a_step(
    shim: Path, shared_dir: Path, tmp_path: Path
) -> None:
    # FrictionContactConstraint under FreeMotionAnimationLoop (runtime/sofac/lagrangian_contact.h):
    # the detection's buffers, every pair's traversal stack (reserved at the first detection), the
    # contacts, their rows and Jacobians in buffers reserved at init; a particle resting on a floor
    # (BGS) and a torus and a cube in a box whose contacts come and go (LCP, 3 to 30 a step); 425
    # particles landing, more contacts than the rows reserved: the first step grows them (doubled,
    # once), the steps after it allocate nothing.
    sys.path.insert(0, str(REPO / "tests"))
    from stability.test_lagrangian_stability import grids_scene
    from test_lagrangian_contact import FLAT, scene

    scenes = [
        scene(tmp_path, FLAT, (0.3, 0.06, 0.2)),
        shared_dir / "corpus/sofa/Component/Collision/Response/FrictionContact.scn",
        grids_scene(tmp_path / "grids.scn"),
    ]
    counts = allocations(shim, scenes)
    assert counts == {str(path): [0, 0] for path in scenes}


def test_linear_solver_correction_contacts_do_not_allocate_in_a_step(shim: Path, tmp_path: Path) -> None:
    # LinearSolverConstraintCorrection (runtime/sofac/linear_correction.h): W += dt J A^-1 J^T and the
    # correction through the direct solver's own right-hand side and solution, CHOLMOD's solve
    # workspaces kept; a particle in contact with a floor from the first step.
    sys.path.insert(0, str(REPO / "tests"))
    from test_linear_solver_correction import particle_scene

    path = particle_scene(tmp_path, "<LinearSolverConstraintCorrection/>")
    assert allocations(shim, [path]) == {str(path): [0, 0]}


def test_barycentric_contacts_do_not_allocate_in_a_step(shim: Path, shared_dir: Path, tmp_path: Path) -> None:
    # contact rows carried through a BarycentricMapping (lagrangian_contact.h barycentric_rows): the
    # blocks before their sort reserved at init for the widest rows; a stiff FEM cube whose mapped
    # points come within the alarm distance of the floor during the counted steps (about the
    # 15th), under either correction, and SOFA's chain of
    # tori (a barycentric-mapped FEM torus between a fixed and a rigid one, in contact throughout)
    sys.path.insert(0, str(REPO / "tests"))
    from test_barycentric_contact import CORRECTIONS, cube_scene

    corners = np.array([[x, 0.0, z] for z in (-0.4, 0.4) for x in (-0.45, 0.45)])
    scenes = [cube_scene(tmp_path, corners, correction=c, lift=0.3, mu=0.5) for c in CORRECTIONS]
    scenes.append(shared_dir / "corpus/sofa/Component/AnimationLoop/FreeMotionAnimationLoop.scn")
    counts = allocations(shim, scenes)
    assert counts == {str(path): [0, 0] for path in scenes}


def test_self_collision_and_rigid_sphere_contacts_do_not_allocate_in_a_step(
    shim: Path, tmp_path: Path
) -> None:
    # Self-collision (pairs of one node, SOFA's element filters) explicit and in the group of the
    # solver integrating the pipeline's node (contact_group_add_force / _dforce); spheres on
    # Rigid3d frames (rigid contact points), with CG, with SparseLDLSolver (their 6 x 6 blocks)
    # and two of them in one solver's group.
    sys.path.insert(0, str(REPO / "tests"))
    from test_rigid_sphere_contacts import IMPLICIT, RIGHT_RIGID, TWO_BALLS, rigid_scene
    from test_self_collision import folded_cloth

    scenes = []
    for name, root in (("explicit", False), ("grouped", True)):
        path = tmp_path / f"cloth_{name}.scn"  # the upper half 4 cm above: in contact within 3 steps
        path.write_text(folded_cloth(height=0.04, solver_at_root=root, stiffness=10.0 if root else 1.0))
        scenes.append(path)
    scenes.append(rigid_scene(tmp_path, "rigid_floor.scn"))
    ldl = (REPO / "tests" / "data" / "contact_sphere_floor.scn").read_text()
    scenes.append(rigid_scene(tmp_path, "rigid_ldl.scn", ldl.replace(
        '<CGLinearSolver iterations="50" tolerance="1e-12" threshold="1e-20"/>', "<SparseLDLSolver/>"
    )))  # fmt: skip
    balls = tmp_path / "balls.scn"
    touching = TWO_BALLS.format(root=IMPLICIT, solver="", right=RIGHT_RIGID)
    balls.write_text(
        touching.replace('"-0.5 0 0 0 0 0 1"', '"-0.1 0 0 0 0 0 1"').replace('"0.5 0.08 0', '"0.1 0.08 0')
    )
    scenes.append(balls)
    counts = allocations(shim, scenes)
    assert counts == {str(path): [0, 0] for path in scenes}
