"""Pieces of the Lagrangian contact scenes the tests (and benchmarks/constraints.py) write: SOFA's
pipeline under FreeMotionAnimationLoop with LocalMinDistance and the FrictionContactConstraint
response, a static floor of two triangles, and particles with an uncoupled correction."""

from __future__ import annotations

import numpy as np

G = 9.81
DT = 0.01
CONTACT = 0.05  # LocalMinDistance's contactDistance: a particle rests this far above the floor


def contact_root(solver: str, mu: float = 0.0) -> str:
    """The scene's opening: the root node (DT, gravity -G along y), the loop, ``solver`` and the
    collision pipeline (alarm 0.2, contact CONTACT, friction ``mu``)."""
    return f"""<?xml version="1.0"?>
<Node name="root" dt="{DT}" gravity="0 -{G} 0">
    <FreeMotionAnimationLoop />
    {solver}
    <CollisionPipeline depth="6" />
    <BruteForceBroadPhase/>
    <BVHNarrowPhase/>
    <LocalMinDistance alarmDistance="0.2" contactDistance="{CONTACT}" />
    <CollisionResponse response="FrictionContactConstraint" responseParams="mu={mu}" />
"""


def static_floor(points: str) -> str:
    """Node /Floor: a static, non-simulated square of two triangles on the four ``points``."""
    return f"""    <Node name="Floor">
        <MechanicalObject name="dofs" position="{points}" />
        <MeshTopology triangles="0 2 1  0 3 2" />
        <TriangleCollisionModel simulated="0" moving="0" />
    </Node>
"""


def particles(name: str, points: np.ndarray, mass: float) -> str:
    """Node /``name``: the ``points``, of ``mass`` each, in one MechanicalObject (implicit Euler with
    CG), with UncoupledConstraintCorrection (compliance 1 / mass) and a point collision model."""
    position = "  ".join(" ".join(f"{c:.17g}" for c in p) for p in points)
    return f"""    <Node name="{name}">
        <EulerImplicitSolver rayleighStiffness="0" rayleighMass="0" />
        <CGLinearSolver iterations="25" tolerance="1e-12" threshold="1e-20" />
        <MechanicalObject name="dofs" position="{position}" />
        <UniformMass vertexMass="{mass!r}" />
        <UncoupledConstraintCorrection compliance="{1.0 / mass!r}" />
        <PointCollisionModel />
    </Node>
"""
