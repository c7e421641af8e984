"""The hybrid pendulum of "Introduction to SOFA" (section 6.1), built with sofac's Python API.

Builds the same scene as ``scenes/hybrid_pendulum.scn`` (see that file for where each number
comes from), writes it as ``.scn`` XML and, when the check stage is available, checks it.

Usage: ``python examples/hybrid_pendulum.py [OUTPUT.scn]`` (default ``hybrid_pendulum.scn``).
"""

from __future__ import annotations

import sys
from pathlib import Path

from sofac.diagnostics import Diagnostics
from sofac.front.model import Node, Scene
from sofac.front.writer import save_scene

# The document's parameters.
END_POS = 1.0  # x of the free end of the string
ATTACH = -1.0  # x of the attached particle in the rigid body's frame
SPRING_LENGTH = 1.0
STIFFNESS = 100.0
DAMPING = 1.0

PLUGINS = [
    "Sofa.Component.Constraint.Projective",
    "Sofa.Component.Mapping.NonLinear",
    "Sofa.Component.Mass",
    "Sofa.Component.ODESolver.Forward",
    "Sofa.Component.SolidMechanics.Spring",
    "Sofa.Component.StateContainer",
    "Sofa.Component.Visual",
]


def create_scene() -> Node:
    """The scene graph of the mixed pendulum; returns its root node."""
    root = Node("root")
    root.set("gravity", [0, -10, 0])
    root.set("dt", 0.01)
    for plugin in PLUGINS:
        root.addObject("RequiredPlugin", pluginName=plugin)
    root.addObject(
        "VisualStyle",
        displayFlags="showVisualModels showBehaviorModels showForceFields "
        "showInteractionForceFields showMechanicalMappings",
    )
    root.addObject("DefaultAnimationLoop")
    # One solver for all the graph.
    root.addObject("EulerExplicitSolver", name="S", symplectic=True)
    # The spring between the string's free end and the particle of the rigid body lives in their
    # common ancestor.
    root.addObject(
        "SpringForceField",
        template="Vec3d",
        name="F13",
        object1="@deformableBody/Dof1",
        object2="@rigidBody/rigidParticles/Dof3",
        spring=[1, 0, STIFFNESS, DAMPING, SPRING_LENGTH],
    )

    # The elastic string: particle 0 fixed, particle 1 free, one spring between them.
    deformable = root.addChild("deformableBody")
    deformable.addObject("MechanicalObject", template="Vec3d", name="Dof1", position=[0, 0, 0, END_POS, 0, 0])
    deformable.addObject("UniformMass", template="Vec3d", name="M1", vertexMass=1)
    deformable.addObject("FixedProjectiveConstraint", template="Vec3d", name="C", indices=0)
    deformable.addObject(
        "SpringForceField", template="Vec3d", name="F1", spring=[1, 0, STIFFNESS, DAMPING, SPRING_LENGTH]
    )

    # The rigid body: mass 0.3, volume 1, inertia matrix (per unit mass) 0.1 * identity.
    rigid = root.addChild("rigidBody")
    rigid.addObject(
        "MechanicalObject",
        template="Rigid3d",
        name="Dof2",
        position=[END_POS - ATTACH + SPRING_LENGTH, 0, 0, 0, 0, 0, 1],
    )
    inertia = [0.1, 0, 0, 0, 0.1, 0, 0, 0, 0.1]
    rigid.addObject("UniformMass", template="Rigid3d", name="M2", vertexMass=[0.3, 1, *inertia])

    # The particle attached to the rigid body, in the body's frame.
    particles = rigid.addChild("rigidParticles")
    particles.addObject("MechanicalObject", template="Vec3d", name="Dof3", position=[ATTACH, 0, 0])
    particles.addObject(
        "RigidMapping", template="Rigid3d,Vec3d", name="Map23", input="@../Dof2", output="@Dof3"
    )
    return root


def _check(root: Node) -> None:
    """Run the check stage if it exists yet and print what it says."""
    try:
        from sofac.check.checker import check_scene
    except ImportError:
        print("check stage not available")
        return
    diagnostics = Diagnostics()
    try:
        check_scene(Scene(root), diagnostics)
    except NotImplementedError:
        print("check stage not implemented yet")
        return
    if not len(diagnostics):
        print("check: no diagnostics")
    for diagnostic in diagnostics.sorted():
        print(diagnostic)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    output = Path(args[0]) if args else Path("hybrid_pendulum.scn")
    root = create_scene()
    save_scene(root, output)
    nodes = sum(1 for _ in root.walk())
    components = sum(1 for _ in root.components())
    print(f"wrote {output}: {nodes} nodes, {components} components")
    _check(root)
    return 0


if __name__ == "__main__":
    sys.exit(main())
