"""SofaPython3 scene scripts (``createScene(rootNode)``) and trees built in Python, compiled by sofac.

Each script here is written in SofaPython3's style (from its documentation and examples) next to
the ``.scn`` file a SOFA user would write for the same scene; the two must build the same tree and
run bit for bit the same. Controllers must give the trajectory that the same parameter changes
made through ``sim.param`` between ``step(1)`` calls give.
"""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.check.checker import check_file
from sofac.cli.main import main
from sofac.diagnostics import Diagnostics, SceneError
from sofac.front.parse import parse_scene
from sofac.front.writer import same_structure
from sofac.pyscene import script as pyscene
from sofac.pyscene import sofa_api as sofapython
from sofac.simulation.loader import ParameterNeedsReset

SCENES = Path(__file__).resolve().parents[1] / "scenes"


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(textwrap.dedent(text).lstrip("\n"))
    return path


def trajectory(sim: sofac.Simulation, steps: int, state: str) -> np.ndarray:
    frames = []
    for _ in range(steps):
        sim.step(1)
        frames.append(sim[state].position.copy())
    return np.array(frames)


# --- a beam whose tip a controller pulls ---------------------------------------------------------

BEAM_PLUGINS = """
    <RequiredPlugin pluginName="Sofa.Component.Constraint.Projective"/>
    <RequiredPlugin pluginName="Sofa.Component.Engine.Select"/>
    <RequiredPlugin pluginName="Sofa.Component.LinearSolver.Iterative"/>
    <RequiredPlugin pluginName="Sofa.Component.Mass"/>
    <RequiredPlugin pluginName="Sofa.Component.MechanicalLoad"/>
    <RequiredPlugin pluginName="Sofa.Component.ODESolver.Backward"/>
    <RequiredPlugin pluginName="Sofa.Component.SolidMechanics.FEM.Elastic"/>
    <RequiredPlugin pluginName="Sofa.Component.StateContainer"/>
    <RequiredPlugin pluginName="Sofa.Component.Topology.Container.Grid"/>
"""

BEAM_SCN = f"""
<?xml version="1.0"?>
<Node name="root" gravity="0 -9.81 0" dt="0.01">
{BEAM_PLUGINS}
    <DefaultAnimationLoop/>
    <Node name="beam">
        <EulerImplicitSolver name="odesolver" rayleighStiffness="0.1" rayleighMass="0.1"/>
        <CGLinearSolver name="linearsolver" iterations="100" tolerance="1e-9" threshold="1e-9"/>
        <RegularGridTopology name="grid" n="11 3 3" min="0 0 0" max="1 0.2 0.2"/>
        <MechanicalObject template="Vec3d" name="dofs"/>
        <UniformMass name="mass" totalMass="40"/>
        <BoxROI name="clamped" box="-0.01 -0.01 -0.01  0.01 0.21 0.21"/>
        <FixedProjectiveConstraint name="fixed" indices="@clamped.indices"/>
        <ConstantForceField name="pull" indices="98" forces="0 0 0"/>
        <HexahedronFEMForceField name="fem" youngModulus="1e6" poissonRatio="0.3" method="large"/>
    </Node>
</Node>
"""

BEAM_PY = '''
import Sofa
import SofaRuntime

PLUGINS = ["Sofa.Component.Constraint.Projective", "Sofa.Component.Engine.Select",
           "Sofa.Component.LinearSolver.Iterative", "Sofa.Component.Mass",
           "Sofa.Component.MechanicalLoad", "Sofa.Component.ODESolver.Backward",
           "Sofa.Component.SolidMechanics.FEM.Elastic", "Sofa.Component.StateContainer",
           "Sofa.Component.Topology.Container.Grid"]


class TipPuller(Sofa.Core.Controller):
    """Pulls the beam's tip down a little more at the start of every step."""

    def __init__(self, *args, **kwargs):
        Sofa.Core.Controller.__init__(self, *args, **kwargs)
        self.pull = kwargs.get("pull")
        self.tip = kwargs.get("tip")
        self.count = 0
        self.ends = []

    def onAnimateBeginEvent(self, event):
        self.count += 1
        with self.pull.forces.writeableArray() as force:
            force[0] = [0.0, -0.5 * self.count, 0.25 * self.count]

    def onAnimateEndEvent(self, event):
        self.ends.append((event["type"], self.tip.position.value[98].copy()))


def createScene(rootNode):
    SofaRuntime.importPlugin("Sofa.Component.StateContainer")
    rootNode.gravity = [0, -9.81, 0]
    rootNode.dt = 0.01
    for plugin in PLUGINS:
        rootNode.addObject("RequiredPlugin", pluginName=plugin)
    rootNode.addObject("DefaultAnimationLoop")
    beam = rootNode.addChild("beam")
    beam.addObject("EulerImplicitSolver", name="odesolver", rayleighStiffness=0.1, rayleighMass=0.1)
    beam.addObject("CGLinearSolver", name="linearsolver", iterations=100, tolerance=1e-9, threshold=1e-9)
    beam.addObject("RegularGridTopology", name="grid", n=[11, 3, 3], min=[0, 0, 0], max=[1, 0.2, 0.2])
    dofs = beam.addObject("MechanicalObject", template="Vec3d", name="dofs")
    beam.addObject("UniformMass", name="mass", totalMass=40)
    beam.addObject("BoxROI", name="clamped", box=[-0.01, -0.01, -0.01, 0.01, 0.21, 0.21])
    beam.addObject("FixedProjectiveConstraint", name="fixed", indices="@clamped.indices")
    pull = beam.addObject("ConstantForceField", name="pull", indices=[98], forces=[0, 0, 0])
    beam.addObject("HexahedronFEMForceField", name="fem", youngModulus=1e6, poissonRatio=0.3, method="large")
    beam.addObject(TipPuller(name="puller", pull=pull, tip=dofs))
    return rootNode
'''

STEPS = 12


def test_beam_controller_matches_the_scn_driven_through_sim_param(tmp_path: Path) -> None:
    script = write(tmp_path, "beam.py", BEAM_PY)
    scn = write(tmp_path, "beam.scn", BEAM_SCN)
    assert (
        same_structure(parse_scene(script, Diagnostics()), parse_scene(scn, Diagnostics()), numeric=True)
        == []
    )

    controlled = sofac.load(script)
    assert isinstance(controlled, pyscene.ControlledSimulation)
    driven = sofac.load(scn)
    assert type(driven) is sofac.Simulation  # a scene without controllers is the plain simulation

    with_controller = trajectory(controlled, STEPS, "/beam/dofs")
    forces = driven.param("/beam/pull.forces")
    frames = []
    for count in range(1, STEPS + 1):
        forces[:] = [0.0, -0.5 * count, 0.25 * count]
        driven.step(1)
        frames.append(driven["/beam/dofs"].position.copy())
    assert np.array_equal(with_controller, np.array(frames))  # bit for bit
    # The pull did move the tip (against a beam that only sags under gravity).
    assert with_controller[-1, 98, 2] > 1e-4

    puller = controlled.controllers[0]
    assert puller.count == STEPS and puller.name.value == "puller" and puller.getPathName() == "/beam/puller"
    # onAnimateEndEvent saw the state after each step, as SOFA's AnimateEndEvent does.
    assert [kind for kind, _ in puller.ends] == ["AnimateEndEvent"] * STEPS
    assert np.array_equal(np.array([tip for _, tip in puller.ends]), with_controller[:, 98])


def test_controller_writes_to_an_init_only_parameter_say_so(tmp_path: Path) -> None:
    script = write(
        tmp_path,
        "soften.py",
        BEAM_PY.replace(
            "beam.addObject(TipPuller(",
            "beam.addObject(Softener(fem=beam.fem))\n    beam.addObject(TipPuller(",
        )
        + """

class Softener(Sofa.Core.Controller):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.fem = kwargs["fem"]

    def onAnimateEndEvent(self, event):
        self.fem.youngModulus.value = 5e5
""",
    )
    sim = sofac.load(script)
    sim.step(1)  # the end of step 1 changes youngModulus, which only init reads
    with pytest.raises(ParameterNeedsReset, match="youngModulus"):
        sim.step(1)


# --- a liver whose visual and collision nodes come from helper functions -------------------------

LIVER_SCN = """
<?xml version="1.0"?>
<Node name="root" gravity="0 -9.81 0" dt="0.02">
    <RequiredPlugin pluginName="Sofa.Component.Collision.Geometry"/>
    <RequiredPlugin pluginName="Sofa.Component.Constraint.Projective"/>
    <RequiredPlugin pluginName="Sofa.Component.IO.Mesh"/>
    <RequiredPlugin pluginName="Sofa.Component.LinearSolver.Iterative"/>
    <RequiredPlugin pluginName="Sofa.Component.Mapping.Linear"/>
    <RequiredPlugin pluginName="Sofa.Component.Mass"/>
    <RequiredPlugin pluginName="Sofa.Component.ODESolver.Backward"/>
    <RequiredPlugin pluginName="Sofa.Component.SolidMechanics.FEM.Elastic"/>
    <RequiredPlugin pluginName="Sofa.Component.StateContainer"/>
    <RequiredPlugin pluginName="Sofa.Component.Topology.Container.Dynamic"/>
    <RequiredPlugin pluginName="Sofa.GL.Component.Rendering3D"/>
    <DefaultAnimationLoop/>
    <MeshOBJLoader name="surfaceLoader" filename="liver-surface.obj"/>
    <Node name="Liver">
        <EulerImplicitSolver name="odesolver" rayleighStiffness="0.1" rayleighMass="0.1"/>
        <CGLinearSolver name="linearsolver" iterations="25" tolerance="1e-9" threshold="1e-9"/>
        <MeshGmshLoader name="meshLoader" filename="liver.msh"/>
        <TetrahedronSetTopologyContainer name="topo" src="@meshLoader"/>
        <MechanicalObject template="Vec3d" name="dofs" src="@meshLoader"/>
        <TetrahedronSetGeometryAlgorithms template="Vec3d" name="geomAlgo"/>
        <DiagonalMass name="mass" massDensity="1000"/>
        <TetrahedronFEMForceField template="Vec3d" name="FEM" method="large"
                                  youngModulus="1e4" poissonRatio="0.3"/>
        <FixedProjectiveConstraint name="ligaments" indices="35 91 167"/>
        <Node name="Visu">
            <OglModel name="visual" src="@/surfaceLoader" color="0.8 0.3 0.25 1"/>
            <BarycentricMapping name="visualMapping" input="@../dofs" output="@visual"/>
        </Node>
        <Node name="Surf">
            <TriangleSetTopologyContainer name="topo" src="@/surfaceLoader"/>
            <MechanicalObject name="points" src="@/surfaceLoader"/>
            <TriangleCollisionModel name="triangles"/>
            <BarycentricMapping name="collisionMapping" input="@../dofs" output="@points"/>
        </Node>
    </Node>
</Node>
"""

LIVER_PY = """
import Sofa

PLUGINS = ["Sofa.Component.Collision.Geometry", "Sofa.Component.Constraint.Projective",
           "Sofa.Component.IO.Mesh", "Sofa.Component.LinearSolver.Iterative",
           "Sofa.Component.Mapping.Linear", "Sofa.Component.Mass", "Sofa.Component.ODESolver.Backward",
           "Sofa.Component.SolidMechanics.FEM.Elastic", "Sofa.Component.StateContainer",
           "Sofa.Component.Topology.Container.Dynamic", "Sofa.GL.Component.Rendering3D"]


def add_visual(parent, surface):
    visu = parent.addChild("Visu")
    visu.addObject("OglModel", name="visual", src=surface.linkpath, color=[0.8, 0.3, 0.25, 1])
    visu.addObject("BarycentricMapping", name="visualMapping", input="@../dofs", output="@visual")
    return visu


def add_collision(parent, surface):
    surf = parent.addChild("Surf")
    surf.addObject("TriangleSetTopologyContainer", name="topo", src=surface.getLinkPath())
    surf.addObject("MechanicalObject", name="points", src=surface)
    surf.addObject("TriangleCollisionModel", name="triangles")
    surf.addObject("BarycentricMapping", name="collisionMapping", input="@../dofs", output="@points")
    return surf


def add_liver(root, surface, young=1e4):
    liver = root.addChild("Liver")
    liver.addObject("EulerImplicitSolver", name="odesolver", rayleighStiffness=0.1, rayleighMass=0.1)
    liver.addObject("CGLinearSolver", name="linearsolver", iterations=25, tolerance=1e-9, threshold=1e-9)
    liver.addObject("MeshGmshLoader", name="meshLoader", filename="liver.msh")
    liver.addObject("TetrahedronSetTopologyContainer", name="topo", src="@meshLoader")
    liver.addObject("MechanicalObject", template="Vec3d", name="dofs", src="@meshLoader")
    liver.addObject("TetrahedronSetGeometryAlgorithms", template="Vec3d", name="geomAlgo")
    liver.addObject("DiagonalMass", name="mass", massDensity=1000)
    liver.addObject("TetrahedronFEMForceField", template="Vec3d", name="FEM", method="large",
                    youngModulus=young, poissonRatio=0.3)
    liver.addObject("FixedProjectiveConstraint", name="ligaments", indices=[35, 91, 167])
    add_visual(liver, surface)
    add_collision(liver, surface)
    return liver


def createScene(rootNode):
    rootNode.gravity = [0, -9.81, 0]
    rootNode.dt = 0.02
    for plugin in PLUGINS:
        rootNode.addObject("RequiredPlugin", pluginName=plugin)
    rootNode.addObject("DefaultAnimationLoop")
    surface = rootNode.addObject("MeshOBJLoader", name="surfaceLoader", filename="liver-surface.obj")
    add_liver(rootNode, surface)
"""


def test_liver_built_in_helper_functions_matches_its_scn(tmp_path: Path) -> None:
    script = write(tmp_path, "liver.py", LIVER_PY)
    scn = write(tmp_path, "liver.scn", LIVER_SCN)
    roots = [SCENES]  # the meshes
    differences = same_structure(
        parse_scene(script, Diagnostics(), data_roots=roots),
        parse_scene(scn, Diagnostics(), data_roots=roots),
        numeric=True,
    )
    assert differences == []
    from_script = sofac.load(script, data_roots=roots)
    from_scn = sofac.load(scn, data_roots=roots)
    assert from_script.objects() == from_scn.objects() == ["/Liver/dofs", "/Liver/Surf/points"]
    start = from_scn["/Liver/dofs"].position.copy()
    from_script.step(10)
    from_scn.step(10)
    for path in from_scn.objects():
        assert np.array_equal(from_script[path].position, from_scn[path].position)
    # Under gravity the organ sags (its mean height drops), held by its ligaments.
    assert from_scn["/Liver/dofs"].position[:, 1].mean() < start[:, 1].mean() - 1e-4


# --- a scene whose parameters are function arguments ---------------------------------------------

CHAIN_PY = '''
import Sofa


def chain(root, count=4, stiffness=100.0, mass=0.5, dt=0.001):
    """A chain of `count` particles joined by springs, the first one fixed."""
    root.gravity = [0, -9.81, 0]
    root.dt = dt
    for plugin in ("Sofa.Component.Constraint.Projective", "Sofa.Component.Mass",
                   "Sofa.Component.ODESolver.Forward", "Sofa.Component.SolidMechanics.Spring",
                   "Sofa.Component.StateContainer"):
        root.addObject("RequiredPlugin", pluginName=plugin)
    root.addObject("DefaultAnimationLoop")
    node = root.addChild("chain")
    node.addObject("EulerExplicitSolver", name="odesolver", symplectic=True)
    node.addObject("MechanicalObject", name="dofs", template="Vec3d",
                   position=[[0.1 * i, 0, 0] for i in range(count)])
    node.addObject("UniformMass", name="mass", vertexMass=mass)
    node.addObject("FixedProjectiveConstraint", name="anchor", indices=0)
    springs = [[i, i + 1, stiffness, 0.1, 0.1] for i in range(count - 1)]
    node.addObject("SpringForceField", name="springs", spring=springs)
    return node


def createScene(rootNode):
    chain(rootNode)
    return rootNode
'''


def chain_scn(count: int, stiffness: str, mass: str, dt: str) -> str:
    positions = "  ".join(f"{0.1 * i!r} 0 0" if i else "0 0 0" for i in range(count))
    springs = "  ".join(f"{i} {i + 1} {stiffness} 0.1 0.1" for i in range(count - 1))
    return f"""<?xml version="1.0"?>
<Node name="root" gravity="0 -9.81 0" dt="{dt}">
    <RequiredPlugin pluginName="Sofa.Component.Constraint.Projective"/>
    <RequiredPlugin pluginName="Sofa.Component.Mass"/>
    <RequiredPlugin pluginName="Sofa.Component.ODESolver.Forward"/>
    <RequiredPlugin pluginName="Sofa.Component.SolidMechanics.Spring"/>
    <RequiredPlugin pluginName="Sofa.Component.StateContainer"/>
    <DefaultAnimationLoop/>
    <Node name="chain">
        <EulerExplicitSolver name="odesolver" symplectic="1"/>
        <MechanicalObject name="dofs" template="Vec3d" position="{positions}"/>
        <UniformMass name="mass" vertexMass="{mass}"/>
        <FixedProjectiveConstraint name="anchor" indices="0"/>
        <SpringForceField name="springs" spring="{springs}"/>
    </Node>
</Node>
"""


def load_module(path: Path) -> dict:
    namespace: dict = {"__name__": "chain_scene"}
    with sofapython.injected():
        exec(compile(path.read_text(), str(path), "exec"), namespace)
    return namespace


def test_scene_parameterised_by_function_arguments(tmp_path: Path) -> None:
    script = write(tmp_path, "chain.py", CHAIN_PY)
    # The defaults, through the script's createScene.
    scn = write(tmp_path, "chain.scn", chain_scn(4, "100", "0.5", "0.001"))
    defaults, reference = sofac.load(script), sofac.load(scn)
    assert type(defaults) is sofac.Simulation  # no controllers: the plain simulation, nothing in between
    assert np.array_equal(trajectory(defaults, 50, "/chain/dofs"), trajectory(reference, 50, "/chain/dofs"))

    # Other arguments, building the tree from Python and compiling it without a file.
    chain = load_module(script)["chain"]
    root = sofapython.Sofa.Core.Node("root")
    chain(root, count=6, stiffness=250.0, mass=0.25, dt=0.0005)
    scn6 = write(tmp_path, "chain6.scn", chain_scn(6, "250", "0.25", "0.0005"))
    built, reference6 = sofac.load(root), sofac.load(scn6)
    assert built[("/chain/dofs")].position.shape == (6, 3)
    assert np.array_equal(trajectory(built, 50, "/chain/dofs"), trajectory(reference6, 50, "/chain/dofs"))

    # The same tree saved as .scn reads back unchanged and runs the same.
    saved = sofac.save(root, tmp_path / "saved.scn")
    assert same_structure(parse_scene(saved, Diagnostics()), root._node) == []
    assert np.array_equal(
        trajectory(sofac.load(saved), 20, "/chain/dofs"), trajectory(sofac.load(scn6), 20, "/chain/dofs")
    )


def test_load_of_a_builder_tree_and_scn_round_trip_through_the_builder(tmp_path: Path) -> None:
    # A .scn parsed to the model, saved and parsed again: the same tree.
    scn = write(tmp_path, "chain.scn", chain_scn(3, "80", "1", "0.001"))
    tree = parse_scene(scn, Diagnostics())
    again = parse_scene(sofac.save(tree.root, tmp_path / "again.scn"), Diagnostics())
    assert same_structure(tree, again) == []
    # sofac.load takes the model's own Node (the builder API) as well.
    sim = sofac.load(tree.root)
    assert np.array_equal(trajectory(sim, 10, "/chain/dofs"), trajectory(sofac.load(scn), 10, "/chain/dofs"))


def test_simulation_functions_drive_the_compiled_tree(tmp_path: Path) -> None:
    """A SofaPython3 main(): Sofa.Simulation.init compiles, animate steps (controllers included)."""
    script = write(tmp_path, "chain.py", CHAIN_PY)
    namespace = load_module(script)
    Sofa = sofapython.Sofa
    root = Sofa.Core.Node("root")
    namespace["createScene"](root)
    Sofa.Simulation.init(root)
    assert root.isInitialized()
    dofs = root.chain.dofs
    for _ in range(5):
        Sofa.Simulation.animate(root, root.dt.value)
    position = dofs.position.value
    assert position.shape == (4, 3) and not position.flags.writeable  # .value is read-only, as in SofaPython3
    reference = sofac.load(script)
    reference.step(5)
    assert np.array_equal(position, reference["/chain/dofs"].position)
    # Data are views of the compiled scene: a write goes to the native parameter.
    sim = sofapython.bound_simulation(root._node)
    root.gravity.value = [0, 0, -1]
    assert np.array_equal(sim.param("/.gravity"), [0, 0, -1])
    assert root.dt.value == 0.001 and root.time.value == sim.time == pytest.approx(0.005)
    Sofa.Simulation.reset(root)
    assert sim.steps == 0
    assert np.array_equal(dofs.position.value, [[0.1 * i, 0, 0] for i in range(4)])
    with pytest.raises(sofapython.SofaAPIError, match="fixed when the scene was compiled"):
        root.chain.mass.name.value = "other"


# --- diagnostics, refusal, what is injected ----------------------------------------------------

BAD_PY = """
import Sofa


def createScene(root):
    root.addObject("DefaultAnimationLoop")
    node = root.addChild("n")
    node.addObject("MechanicalObject", name="dofs",
                   position=[0, 0, 0])
    node.addObject("UniformMass",
                   totalMass=-1)
"""


def test_diagnostics_point_to_the_script_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    script = write(tmp_path, "bad.py", BAD_PY)
    _, diagnostics = check_file(script)
    [error] = [d for d in diagnostics if d.code == "E207"]
    assert (error.loc.file, error.loc.line, error.loc.attribute) == (str(script), 9, "totalMass")
    assert main(["check", "--format", "json", str(script)]) == 1
    reported = json.loads(capsys.readouterr().out)
    assert [(d["code"], d["file"], d["line"]) for d in reported if d["code"] == "E207"] == [
        ("E207", str(script), 9)
    ]


@pytest.mark.parametrize(
    ("fmt", "expected"),
    [
        ("text", "{file}:9: error E207 [totalMass]"),
        ("github", "::error file={file},line=9,title=E207::"),
        ("junit", "{file}:9: error E207 [totalMass]"),
    ],
)
def test_every_format_names_the_script_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], fmt: str, expected: str
) -> None:
    script = write(tmp_path, "bad.py", BAD_PY)
    assert main(["check", "--format", fmt, str(script)]) == 1
    assert expected.format(file=script) in capsys.readouterr().out


@pytest.mark.parametrize(
    ("body", "line", "message"),
    [
        (
            "    root.addObject('DefaultAnimationLoop')\n    root.getMass()\n",
            5,
            "Sofa.Core.Node.getMass is not part",
        ),
        ("    import Sofa.Gui\n    Sofa.Gui.GUIManager.Init('x')\n", 5, "Sofa.Gui.GUIManager is not part"),
        (
            "    n = root.addChild('n')\n    n.nosuch.position\n",
            5,
            "node '/n' has no child, object or data named",
        ),
        ("    x = 1\n    raise ValueError('bad size')\n", 5, "raised ValueError: bad size"),
        ("    x = 1\n    y = (x,\n\n", 5, "raised SyntaxError: '(' was never closed"),
        ("    root.addObject('X', position=object())\n", 4, "a object cannot be a SOFA data value"),
    ],
)
def test_unsupported_api_and_script_errors_name_the_line(
    tmp_path: Path, body: str, line: int, message: str
) -> None:
    script = write(tmp_path, "api.py", "import Sofa\n\ndef createScene(root):\n" + body)
    _, diagnostics = check_file(script)
    [error] = list(diagnostics)
    assert (error.code, error.loc.file, error.loc.line) == ("E113", str(script), line)
    assert message in error.message


def test_script_without_create_scene(tmp_path: Path) -> None:
    script = write(tmp_path, "empty.py", "import Sofa\n")
    with pytest.raises(SceneError, match="defines no createScene"):
        sofac.load(script)


def test_no_exec_refuses_python_scenes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    marker = tmp_path / "ran"
    script = write(
        tmp_path, "side.py", f"open({str(marker)!r}, 'w').close()\ndef createScene(root):\n    pass\n"
    )
    assert main(["check", "--no-exec", "--format", "json", str(script)]) == 1
    [refusal] = json.loads(capsys.readouterr().out)
    assert (refusal["code"], refusal["file"]) == ("E114", str(script))
    assert not marker.exists()
    assert main(["check", "--no-exec", str(write(tmp_path, "c.scn", chain_scn(2, "1", "1", "0.01")))]) == 0
    main(["check", str(script)])  # without --no-exec the script runs, as SofaPython3 would run it
    assert marker.exists()


def test_sofa_modules_are_only_injected_while_a_script_runs(tmp_path: Path) -> None:
    before = {name: sys.modules.get(name) for name in ("Sofa", "Sofa.Core", "SofaRuntime", "Sofa.Gui")}
    script = write(
        tmp_path, "imports.py", "import Sofa.Gui\nimport SofaRuntime\ndef createScene(root):\n    pass\n"
    )
    parse_scene(script, Diagnostics())
    assert {name: sys.modules.get(name) for name in before} == before


def test_warm_record_follows_the_files_the_script_reads(tmp_path: Path) -> None:
    settings = tmp_path / "settings.json"
    settings.write_text(json.dumps({"stiffness": 100.0}))
    script = write(
        tmp_path,
        "reads.py",
        CHAIN_PY.replace(
            "    chain(rootNode)",
            f"    import json\n    with open({str(settings)!r}) as f:\n"
            "        chain(rootNode, stiffness=json.load(f)['stiffness'])",
        ),
    )
    first = sofac.load(script)
    assert not first.compiled.warm
    assert sofac.load(script).compiled.warm  # nothing changed
    settings.write_text(json.dumps({"stiffness": 300.0}))
    changed = sofac.load(script)
    assert not changed.compiled.warm
    stiffer = sofac.load(write(tmp_path, "stiffer.scn", chain_scn(4, "300", "0.5", "0.001")))
    assert np.array_equal(trajectory(changed, 20, "/chain/dofs"), trajectory(stiffer, 20, "/chain/dofs"))


def test_every_instance_gets_controllers_of_its_own(tmp_path: Path) -> None:
    """Sweeps and accuracy studies instantiate a compiled scene many times (Compiled.instantiate)."""
    from sofac.pipeline import compile_scene

    script = write(tmp_path, "beam.py", BEAM_PY)
    compiled = compile_scene(script)
    sofac.load(script)
    warm_load = sofac.load(script)
    assert warm_load.compiled.warm
    first, second, third = compiled.instantiate(), compiled.instantiate(), warm_load.compiled.instantiate()
    for sim in (first, second, third):
        assert isinstance(sim, pyscene.ControlledSimulation)
    assert len({id(sim.controllers[0]) for sim in (first, second, third, warm_load)}) == 4
    expected = trajectory(first, 4, "/beam/dofs")
    assert np.array_equal(trajectory(second, 4, "/beam/dofs"), expected)
    assert np.array_equal(trajectory(third, 4, "/beam/dofs"), expected)
    assert [sim.controllers[0].count for sim in (first, second, third)] == [4, 4, 4]


def test_a_tree_with_controllers_drives_one_simulation(tmp_path: Path) -> None:
    namespace = load_module(write(tmp_path, "beam.py", BEAM_PY))
    root = sofapython.Sofa.Core.Node("root")
    namespace["createScene"](root)
    sofac.load(root)
    with pytest.raises(sofac.SofacError, match="already drives a simulation"):
        sofac.load(root)
    with pytest.raises(sofac.SofacError, match=r"a \.scn file cannot hold"):
        sofac.save(root, tmp_path / "beam.scn")


def test_a_real_sofa_module_is_put_back(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import types

    real = types.ModuleType("Sofa")  # stands for a SOFA installation imported before
    monkeypatch.setitem(sys.modules, "Sofa", real)
    seen = tmp_path / "seen.txt"
    script = write(
        tmp_path,
        "which.py",
        f"import Sofa\nopen({str(seen)!r}, 'w').write(Sofa.__doc__)\ndef createScene(root):\n    pass\n",
    )
    parse_scene(script, Diagnostics())
    assert "sofac" in seen.read_text()  # the script saw sofac's API...
    assert sys.modules["Sofa"] is real  # ...and the installation's module is back


def test_data_before_the_tree_is_compiled_read_and_write_the_model() -> None:
    Sofa = sofapython.Sofa
    root = Sofa.Core.Node("root")
    root.dt = 0.02
    assert root.findData("dt").value == 0.02 and root.dt.value == 0.02
    assert root.name.value == "root" and root.getName() == "root" and root.findData("nosuch") is None
    dofs = root.addChild("body").addObject("MechanicalObject", name="dofs", position=[[0, 0, 0], [1, 2, 3]])
    assert root.body.dofs is dofs and root["body.dofs"] is dofs and root.body.objects["dofs"] is dofs
    assert np.array_equal(dofs.position.value, [0, 0, 0, 1, 2, 3])
    with dofs.position.writeableArray() as position:
        position[3] = 5
    assert dofs._element.get("position") == "0 0 0 5 2 3"  # written back to the model's text
    spring = root.body.addObject("SpringForceField", name="s", spring=[[0, 1, 10, 0.5, 1.0]])
    assert spring.getLinkPath() == "@/body/s" and dofs.position.getLinkPath() == "@/body/dofs.position"
    assert root.body.getObject("missing") is None and not hasattr(root.body, "missing")
    typo = r"has no data named 'stifness' \(did you mean 'stiffness'\?\)"
    with pytest.raises(sofapython.SofaAPIError, match=typo):
        _ = spring.stifness


def test_a_failing_controller_names_its_line_and_step(tmp_path: Path) -> None:
    script = write(
        tmp_path,
        "failing.py",
        BEAM_PY.replace(
            "        self.count += 1\n",
            "        self.count += 1\n"
            "        if self.count == 3:\n"
            "            raise RuntimeError('cable snapped')\n",
        ),
    )
    sim = sofac.load(script)
    line = next(i for i, text in enumerate(script.read_text().splitlines(), 1) if "cable snapped" in text)
    with pytest.raises(
        pyscene.ControllerError, match=rf"failing.py:{line}: controller 'puller'.*cable snapped.*step 3"
    ):
        sim.step(5)
    assert sim.steps == 2
    with pytest.raises(sofapython.SofaAPIError, match="the scene is compiled"):
        sim.controllers[0].getContext().addChild("late")


def test_a_dropped_python_scene_frees_its_simulation(tmp_path: Path) -> None:
    """Sweeps make a simulation (and a tree) per run: nothing may keep the old ones alive."""
    import gc
    import weakref

    sim = sofac.load(write(tmp_path, "chain.py", CHAIN_PY))
    tree = weakref.ref(sim.compiled.python_scene.root)
    gone = weakref.ref(sim)
    del sim
    gc.collect()
    assert gone() is None and tree() is None


def test_an_edited_helper_module_is_a_miss_and_is_imported_afresh(tmp_path: Path) -> None:
    helpers = write(tmp_path, "chain_helpers.py", CHAIN_PY.replace("def createScene", "def _unused"))
    script = write(
        tmp_path,
        "uses_helpers.py",
        "from chain_helpers import chain\n\n\ndef createScene(root):\n    chain(root, stiffness=100.0)\n",
    )
    assert not sofac.load(script).compiled.warm
    assert sofac.load(script).compiled.warm
    assert "chain_helpers" not in sys.modules  # the script's own modules are not left behind
    helpers.write_text(helpers.read_text().replace("vertexMass=mass", "vertexMass=2 * mass"))
    edited = sofac.load(script)
    assert not edited.compiled.warm
    heavier = sofac.load(write(tmp_path, "heavier.scn", chain_scn(4, "100", "1", "0.001")))
    assert np.array_equal(trajectory(edited, 20, "/chain/dofs"), trajectory(heavier, 20, "/chain/dofs"))


def test_the_example_runs_and_its_scn_gives_the_same_trajectory(tmp_path: Path) -> None:
    example = Path(__file__).resolve().parents[1] / "examples" / "pulled_beam.py"
    import subprocess

    done = subprocess.run(
        [sys.executable, str(example), str(tmp_path / "pulled_beam.scn")], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr  # 0: the .scn driven through sim.param ends bit for bit equal
    assert "it ends 0 away from the controller's run" in done.stdout
    assert (tmp_path / "pulled_beam.scn").is_file()


def test_a_write_to_a_compiled_out_effect_says_how_to_keep_it(tmp_path: Path) -> None:
    from sofac.simulation.loader import PrunedEffectError

    Sofa = sofapython.Sofa
    root = Sofa.Core.Node("root")
    load_module(write(tmp_path, "chain.py", CHAIN_PY))["chain"](root)
    root.gravity = [0, 0, 0]  # no gravity: the compiled step has no code for it
    Sofa.Simulation.init(root)
    with pytest.raises(PrunedEffectError, match="recompile=True"):
        root.gravity.value = [0, -9.81, 0]
    with pytest.raises(PrunedEffectError, match="recompile=True"), root.gravity.writeableArray():
        pass
    assert np.array_equal(root.gravity.value, [0, 0, 0])  # reading it is fine
    velocity = Sofa.Core.Node("other").addObject("MechanicalObject").velocity
    with pytest.raises(sofapython.SofaAPIError, match="has no value yet"), velocity.writeableArray():
        pass
