"""Penalty contact scenes: time per step split into detection, response and the rest (the solve,
with the contact forces in it), and what collision models that never meet cost.

    python benchmarks/contacts.py               # SOFA's contact scenes (corpus) + tests/data ones
    python benchmarks/contacts.py --steps 50 --repeat 3

Detection (trees, broad and narrow phase) and response (contact order, de-duplication, contact
points, the explicit forces of simulated pairs) are timed inside the compiled step and read from
``<pipeline>.contactReport``; the rest is the step's wall time minus both. The last lines time a
particle that never comes near a floor and the liver falling far above one, each with and without
its collision pipeline, in alternating blocks of one run: their ratio is what the collision models
that never meet cost.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import tempfile
import time
from pathlib import Path

import sofac

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
CORPUS = [
    "Component/SolidMechanics/Spring/MeshSpringForceField.scn",
    "Demos/chainHybrid.scn",
    "Demos/chainAll.scn",
    "Demos/collisionMultiple.scn",
    "Component/Collision/Detection/CompositeCollisionPipeline_none.scn",
]
LOCAL = ["tests/data/contact_particle_floor.scn", "tests/data/contact_two_particles.scn"]


def shared() -> Path | None:
    for candidate in (os.environ.get("SOFAC_SHARED"), REPO.parent / "shared"):
        if candidate and (Path(candidate) / "corpus" / "sofa").is_dir():
            return Path(candidate)
    return None


def split(path: Path, steps: int, repeat: int) -> tuple[float, float, float]:
    """Best of ``repeat`` runs: (total, detection, response) in ms per step."""
    sim = sofac.load(path)
    best = (float("inf"), 0.0, 0.0)
    for _ in range(repeat):
        sim.reset()
        started = time.perf_counter()
        sim.step(steps)
        total = (time.perf_counter() - started) / steps * 1e3
        reports = [sim.output(b.key) for b in sim.spec.buffers if b.key.endswith(".contactReport")]
        detection = sum(r[3] for r in reports) / steps * 1e3
        response = sum(r[4] for r in reports) / steps * 1e3
        best = min(best, (total, detection, response))
    return best


COLLISION = (
    "CollisionPipeline|BruteForceBroadPhase|BVHNarrowPhase|MinProximityIntersection|CollisionResponse|"
    "TriangleCollisionModel|PointCollisionModel"
)


def with_and_without(
    far: str, steps: int, repeat: int, data: Path | None = None
) -> tuple[float, float, float]:
    """ms per step of ``far`` (a scene whose collision models never meet) and of the same scene with
    its collision pipeline and models removed, stepped in alternating blocks (``repeat`` x 10 blocks
    of ``steps`` / 10 steps each, CPU time: the machine's load hits both alike), the median block of
    each; and the detection's ms per step in ``far`` (its contactReport, over all its steps)."""
    bare = re.sub(rf"<({COLLISION})\b[^>]*/>", "", far)
    block = max(steps // 10, 1)
    with tempfile.TemporaryDirectory() as folder:
        sims = []
        for name, scene in (("with", far), ("without", bare)):
            path = Path(folder) / f"{name}.scn"
            path.write_text(scene)
            sims.append(sofac.load(path, data_roots=(data,) if data else ()))
        times: list[list[float]] = [[], []]
        for _ in range(10 * repeat):
            for sim, measured in zip(sims, times, strict=True):
                started = time.process_time()
                sim.step(block)
                measured.append((time.process_time() - started) / block * 1e3)
        reports = [sims[0].output(b.key) for b in sims[0].spec.buffers if b.key.endswith(".contactReport")]
        detection = sum(r[3] for r in reports) / (10 * repeat * block) * 1e3
    return statistics.median(times[0]), statistics.median(times[1]), detection


def never_meeting(steps: int, repeat: int) -> tuple[float, float, float]:
    """ms per step of a particle far above a floor, with the collision pipeline and without it, and
    its detection's."""
    text = (REPO / LOCAL[0]).read_text()
    far = text.replace('position="0.1 0.4 -0.2"', 'position="0.1 100 -0.2"').replace(
        'gravity="0 -9.81 0"', 'gravity="0 0 0"'
    )
    return with_and_without(far, steps, repeat)


def never_meeting_liver(steps: int, repeat: int) -> tuple[float, float, float]:
    """ms per step of scenes/liver_on_floor.scn with its floor 10 km down (the liver falls, never
    reaching it), with the collision pipeline and models and without them (its collision points
    then are a mapped state nothing reads: mapped only when read)."""
    far = (REPO / "scenes" / "liver_on_floor.scn").read_text().replace(" -0.12 ", " -10000 ")
    return with_and_without(far, steps, repeat, REPO / "scenes")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    root = shared()
    scenes = [REPO / s for s in LOCAL]
    if root is not None:
        scenes = [root / "corpus" / "sofa" / s for s in CORPUS] + scenes
    print(f"{'scene':<58} {'ms/step':>9} {'detect':>8} {'respond':>8} {'rest':>8}")
    for path in scenes:
        total, detection, response = split(path, args.steps, args.repeat)
        rest = total - detection - response
        print(f"{path.name:<58} {total:9.3f} {detection:8.3f} {response:8.3f} {rest:8.3f}")
    print()
    for name, (with_models, without, detection) in (
        ("particle", never_meeting(20 * args.steps, args.repeat)),
        ("liver", never_meeting_liver(5 * args.steps, args.repeat)),
    ):
        print(
            f"models that never meet, {name}: {with_models * 1e3:.2f} us/step with the pipeline "
            f"(detection {detection * 1e3:.2f}), {without * 1e3:.2f} us/step without: "
            f"ratio {with_models / without:.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
