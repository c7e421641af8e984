"""A SofaPython3 scene that sofac runs unchanged: a cantilever beam whose tip a controller pulls.

As a scene file (what SOFA's ``runSofa pulled_beam.py`` would load)::

    sofac check examples/pulled_beam.py      # runs createScene, reports problems at its lines
    sofac run examples/pulled_beam.py --steps 100

As a program, ``python examples/pulled_beam.py [OUTPUT.scn]`` shows the Python workflow:
``sofac.load`` of this file (its controller runs between the compiled steps), the same tree built
in Python with a stiffer material passed as an argument and compiled without a file, and that tree
saved as ``.scn`` (default ``pulled_beam.scn``) and driven through ``sim.param`` instead of the
controller, which gives the same trajectory bit for bit.
"""

from __future__ import annotations

import sys
from pathlib import Path

try:
    import Sofa  # sofac's API while sofac runs this file (or SOFA's own, under runSofa)
except ImportError:  # run as a plain program without SOFA: build with sofac's API
    from sofac.pyscene.sofa_api import Sofa

PULL_PER_STEP = 0.5  # N added to the downward pull on the tip at every step
TIP = 98  # the last grid point: x = 1, y = z = 0.2
PLUGINS = [
    "Sofa.Component.Constraint.Projective",
    "Sofa.Component.Engine.Select",
    "Sofa.Component.LinearSolver.Iterative",
    "Sofa.Component.Mass",
    "Sofa.Component.MechanicalLoad",
    "Sofa.Component.ODESolver.Backward",
    "Sofa.Component.SolidMechanics.FEM.Elastic",
    "Sofa.Component.StateContainer",
    "Sofa.Component.Topology.Container.Grid",
]


class TipPuller(Sofa.Core.Controller):
    """Before each step, pulls the tip down PULL_PER_STEP newtons harder than before."""

    def __init__(self, *args, **kwargs):
        Sofa.Core.Controller.__init__(self, *args, **kwargs)
        self.pull = kwargs["pull"]
        self.steps = 0

    def onAnimateBeginEvent(self, event):
        self.steps += 1
        with self.pull.forces.writeableArray() as force:
            force[0] = [0.0, -PULL_PER_STEP * self.steps, 0.0]


def add_beam(root, young_modulus=1e6, with_controller=True):
    """A 1 x 0.2 x 0.2 beam of hexahedra, clamped at x = 0 (see scenes/beam.scn)."""
    beam = root.addChild("beam")
    beam.addObject("EulerImplicitSolver", name="odesolver", rayleighStiffness=0.1, rayleighMass=0.1)
    beam.addObject("CGLinearSolver", name="linearsolver", iterations=100, tolerance=1e-9, threshold=1e-9)
    beam.addObject("RegularGridTopology", name="grid", n=[11, 3, 3], min=[0, 0, 0], max=[1, 0.2, 0.2])
    beam.addObject("MechanicalObject", template="Vec3d", name="dofs")
    beam.addObject("UniformMass", name="mass", totalMass=40)
    beam.addObject("BoxROI", name="clamped", box=[-0.01, -0.01, -0.01, 0.01, 0.21, 0.21])
    beam.addObject("FixedProjectiveConstraint", name="fixed", indices="@clamped.indices")
    pull = beam.addObject("ConstantForceField", name="pull", indices=[TIP], forces=[0, 0, 0])
    beam.addObject("HexahedronFEMForceField", name="fem", youngModulus=young_modulus, poissonRatio=0.3)
    if with_controller:
        beam.addObject(TipPuller(name="puller", pull=pull))
    return beam


def createScene(rootNode, young_modulus=1e6, with_controller=True):
    rootNode.gravity = [0, -9.81, 0]
    rootNode.dt = 0.01
    for plugin in PLUGINS:
        rootNode.addObject("RequiredPlugin", pluginName=plugin)
    rootNode.addObject("DefaultAnimationLoop")
    add_beam(rootNode, young_modulus, with_controller)
    return rootNode


def main(argv: list[str] | None = None) -> int:
    import numpy as np
    import sofac
    from sofac.pyscene.sofa_api import Sofa as SofacSofa

    args = sys.argv[1:] if argv is None else argv
    output = Path(args[0]) if args else Path("pulled_beam.scn")
    steps = 50

    # 1. This file, as sofac run would load it: the controller pulls between compiled steps.
    sim = sofac.load(__file__)
    sim.step(steps)
    tip = sim["/beam/dofs"].position[TIP]
    print(f"{__file__}: after {steps} steps (t={sim.time:g}) the tip is at {tip}")

    # 2. The tree built here, with a stiffer material, compiled without a file.
    stiff = SofacSofa.Core.Node("root")
    createScene(stiff, young_modulus=4e6)
    stiff_sim = sofac.load(stiff)
    stiff_sim.step(steps)
    print(f"E = 4e6 Pa: the tip is at {stiff_sim['/beam/dofs'].position[TIP]}")

    # 3. Saved as .scn (a .scn cannot hold a Python controller), the pull made through sim.param.
    plain = SofacSofa.Core.Node("root")
    createScene(plain, with_controller=False)
    sofac.save(plain, output)
    driven = sofac.load(output)
    forces = driven.param("/beam/pull.forces")
    for count in range(1, steps + 1):
        forces[:] = [0.0, -PULL_PER_STEP * count, 0.0]
        driven.step(1)
    difference = np.abs(driven["/beam/dofs"].position - sim["/beam/dofs"].position).max()
    print(f"wrote {output}; driven through sim.param, it ends {difference:g} away from the controller's run")
    return 0 if difference == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
