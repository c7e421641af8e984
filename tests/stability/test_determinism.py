"""Determinism: the same scene and binary give bit-identical trajectories run to run, across
instances (stepped side by side), across loads, and across processes."""

from __future__ import annotations

import hashlib
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import sofac

from .scenes import (
    DIRECT,
    EXACT_CG,
    GRAVITY,
    NO_GRAVITY,
    TWO_TETS,
    TWO_TETS_POINTS,
    Scenes,
    implicit,
    springs_body,
    tetra_body,
)

BLOCKS, PER_BLOCK = 10, 20


def fingerprint(sim: sofac.Simulation, blocks: int = BLOCKS, per_block: int = PER_BLOCK) -> str:
    """SHA-256 of every state's position and velocity bytes after each block of steps."""
    digest = hashlib.sha256()
    for _ in range(blocks):
        sim.step(per_block)
        for path in sim.objects():
            digest.update(sim[path].position.tobytes())
            digest.update(sim[path].velocity.tobytes())
    return digest.hexdigest()


def chain() -> str:
    rng = np.random.default_rng(7)
    points = np.cumsum(np.c_[np.ones(12), rng.normal(0, 0.2, 12), rng.normal(0, 0.2, 12)], axis=0)
    pairs = [(i, i + 1) for i in range(11)] + [(i, i + 2) for i in range(10)]
    return springs_body(implicit(), points, pairs, stiffness=500.0, damping=0.5, rest=1.2, fixed=[0])


def free_tets(solver: str) -> str:
    return tetra_body(solver, TWO_TETS_POINTS, TWO_TETS, "polar")


RIGID = (
    '<Node name="r"><RungeKutta4Solver/><MechanicalObject name="frame" template="Rigid3d" '
    'position="0 0 0 0 0 0 1" velocity="0.1 0 0 30 -50 80"/>'
    '<UniformMass vertexMass="2 1 [1 0 0, 0 2 0, 0 0 3]"/>'
    '<Node name="tip"><MechanicalObject name="point" position="0.5 0.2 0.1"/><RigidMapping/></Node></Node>'
)

CASES = {
    "springs-cg": (chain(), GRAVITY),
    "tets-cg": (free_tets(EXACT_CG), NO_GRAVITY),
    "tets-direct": (free_tets(DIRECT), NO_GRAVITY),
    "rigid-rk4": (RIGID, NO_GRAVITY),
}


@pytest.mark.parametrize("name", list(CASES))
def test_run_to_run_and_across_instances(scenes: Scenes, name: str) -> None:
    body, gravity = CASES[name]
    compiled = scenes.compiled(f"det-{name}", body, gravity=gravity)
    first, second = kicked(compiled.instantiate()), kicked(compiled.instantiate())
    for _ in range(BLOCKS):  # side by side: nothing shared between instances
        first.step(PER_BLOCK)
        second.step(PER_BLOCK)
        for path in first.objects():
            assert first[path].position.tobytes() == second[path].position.tobytes(), path
            assert first[path].velocity.tobytes() == second[path].velocity.tobytes(), path
    fresh = fingerprint(kicked(compiled.instantiate()))
    first.reset()  # run to run: reset() gives the same trajectory as a new instance
    assert fingerprint(kicked(first)) == fresh
    assert fingerprint(kicked(compiled.instantiate())) == fresh


def kicked(sim: sofac.Simulation) -> sofac.Simulation:
    """A deterministic initial velocity for every unmapped state that starts at rest."""
    for info in sim.states():
        state = sim[info.path]
        if not info.mapped and not state.velocity.any():
            state.velocity[:] = np.sin(np.arange(state.velocity.size)).reshape(state.velocity.shape)
    return sim


def test_separate_loads_of_the_liver_agree_bit_for_bit(corpus_dir: Path) -> None:
    liver = corpus_dir / "Demos" / "liver.scn"
    digests = {fingerprint(sofac.load(liver)) for _ in range(2)}
    assert len(digests) == 1


SCRIPT = textwrap.dedent(
    """
    import hashlib, sys
    import sofac

    sim = sofac.load(sys.argv[1])
    digest = hashlib.sha256()
    for _ in range({blocks}):
        sim.step({per_block})
        for path in sim.objects():
            digest.update(sim[path].position.tobytes())
            digest.update(sim[path].velocity.tobytes())
    print(digest.hexdigest())
    """
)


def test_across_processes(scenes: Scenes, corpus_dir: Path, tmp_path: Path) -> None:
    script = tmp_path / "fingerprint.py"
    script.write_text(SCRIPT.format(blocks=BLOCKS, per_block=PER_BLOCK))
    springs = scenes.write("det-process", chain(), gravity=GRAVITY)
    for path in (springs, corpus_dir / "Demos" / "liver.scn"):
        here = fingerprint(sofac.load(path))
        done = subprocess.run(
            [sys.executable, str(script), str(path)], capture_output=True, text=True, stdin=subprocess.DEVNULL
        )
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() == here, path.name
