"""The registry knows every component SOFA registers, and the checker reads scenes as SOFA does.

SOFA's own list (``compiler/registry/sofa_catalog.json``, written by ``scripts/sofa_components.py``
from SOFA's source) turns a real SOFA component sofac does not compile into E222 naming its module,
leaving E200 for names SOFA does not know. The rest are the false errors of issue 19, each against
what SOFA's source does: every case checks a small scene and compares the whole list of errors and
warnings (code and line) with the expected one.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sofac import registry
from sofac.check.checker import CheckedScene, check_file
from sofac.diagnostics import Diagnostics
from sofac.registry import Category, NameStatus
from sofac.registry.fields import FieldValueError, Link, LinkList, SofaData, parse_ints, parse_reals

REPO = Path(__file__).resolve().parents[1]

# Lines 1-5; a scene's body starts at line 6.
HEAD = """\
<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <DefaultAnimationLoop/>
    <EulerImplicitSolver/>
    <CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/>
    <MechanicalObject name="dofs" position="0 0 0  1 0 0  2 0 0"/>
"""

# A unit square in the z=0 plane, as a Wavefront file.
SQUARE_OBJ = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"


@pytest.fixture(autouse=True)
def _no_env_data_path(monkeypatch: pytest.MonkeyPatch) -> None:
    for variable in ("SOFAC_DATA_PATH", "SOFA_DATA_PATH", "SOFA_ROOT"):
        monkeypatch.delenv(variable, raising=False)


def check(tmp_path: Path, text: str, files: dict[str, str] | None = None) -> tuple[CheckedScene, Diagnostics]:
    for name, content in (files or {}).items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(content)
    scene = tmp_path / "scene.scn"
    scene.write_text(text)
    checked, diagnostics = check_file(scene)
    assert checked is not None
    return checked, diagnostics


def codes(diagnostics: Diagnostics) -> list[tuple[str, int]]:
    return sorted((d.code, d.loc.line) for d in diagnostics)


def component(checked: CheckedScene, name: str):
    return next(c for c in checked if c.component.name == name)


# --- SOFA's list of components ---------------------------------------------------------------
def test_catalogue_knows_sofa_components_with_modules_templates_and_fields() -> None:
    from sofac.registry import catalogue

    assert catalogue.sofa_commit() == "2a278d891fe68ae5a835259bd62a2844df1670a1"
    names = set(catalogue.names())
    assert len(names) > 550
    assert {"VectorSpringForceField", "LCPForceFeedback", "Quad2TriangleTopologicalMapping"} <= names
    assert {"MeshSTLLoader", "OglShader", "MechanicalStateController"} <= names

    # SOFA's own description (the catalogue's), whether or not a hand-written spec compiles it.
    spec = catalogue.resolve("VectorSpringForceField")[0]
    assert registry.lookup("VectorSpringForceField").spec.supported  # compiled since issue 19
    assert spec.module == "Sofa.Component.SolidMechanics.Spring"
    assert spec.category is Category.INTERACTION_FORCEFIELD
    assert spec.templates == ("Vec3d",)
    assert not spec.supported and spec.from_sofa_source
    object1 = spec.field("object1")
    assert isinstance(object1.type, Link) and object1.type.target == "state" and object1.default == "@./"

    loader = catalogue.resolve("MeshSTLLoader")[0]
    assert loader.category is Category.LOADER
    scale = loader.field("scale3d")
    assert isinstance(scale.type, SofaData) and scale.type.cpp_type == "Vec3"
    assert scale.default == "Vec3(1.0, 1.0, 1.0)"
    assert loader.field("tetras") is loader.field("tetrahedra")  # a Data alias (addAlias)

    # SOFA's templates, default first; the hand-written spec keeps those sofac compiles.
    assert catalogue.templates("BarycentricMapping")[:2] == ("Vec3d,Vec3d", "Vec3d,Rigid3d")
    assert registry.lookup("BarycentricMapping").spec.templates == ("Vec3d,Vec3d",)
    # BaseMapping's isMechanical is an alias of three Data: it sets them all.
    mapping = registry.lookup("SubsetMultiMapping").spec
    assert set(mapping.field("isMechanical").sets) == {"mapForces", "mapConstraints", "mapMasses"}
    assert isinstance(mapping.field("input").type, LinkList)


def test_factory_alias_resolves_and_hand_written_names_win() -> None:
    alias = registry.lookup("PARDISOSolver")
    assert alias.spec.name == "SparsePARDISOSolver" and alias.status is NameStatus.ALIAS
    # SofaOpenCL still registers a class named FixedConstraint; the registry's rename wins.
    renamed = registry.lookup("FixedConstraint")
    assert renamed.spec.name == "FixedProjectiveConstraint" and renamed.status is NameStatus.RENAMED


def test_every_hand_written_component_is_one_sofa_registers() -> None:
    """The hand-written specs describe SOFA classes: by name or alias in SOFA's list, or from a
    plugin outside SOFA's repository (BeamAdapter, CSparseSolvers)."""
    from sofac.registry import _tables, catalogue

    sofa = set(catalogue.names())
    outside = {"Node", "AdaptiveBeamForceFieldAndMass", "BeamInterpolation", "SparseCholeskySolver"}
    outside |= {"SparseLUSolver"}
    missing = sorted(
        spec.name
        for spec in _tables()[0].values()
        if spec.name not in sofa and not set(spec.aliases) & sofa and spec.name not in outside
    )
    assert missing == []


def test_supported_by_sofa_is_e222_naming_the_module(tmp_path: Path) -> None:
    _, diagnostics = check(
        tmp_path,
        HEAD + '    <Node name="b"><MechanicalObject name="m" position="0 1 0"/></Node>\n'
        '    <PolynomialSpringsForceField object1="@dofs" object2="@b/m"/>\n</Node>\n',
    )
    assert codes(diagnostics) == [("E222", 7)]
    (error,) = diagnostics
    expected = "PolynomialSpringsForceField is supported by SOFA (module Sofa.Component.SolidMechanics"
    assert expected in error.message


def test_plugin_component_names_the_plugin(tmp_path: Path) -> None:
    _, diagnostics = check(tmp_path, HEAD + "    <ImageContainer/>\n</Node>\n")
    assert codes(diagnostics) == [("E222", 6)]
    assert "(plugin image)" in next(iter(diagnostics)).message


def test_e200_only_for_names_sofa_does_not_register(tmp_path: Path) -> None:
    _, diagnostics = check(tmp_path, HEAD + "    <VectorSpringForceFeld/>\n</Node>\n")
    assert codes(diagnostics) == [("E200", 6)]
    assert "VectorSpringForceField" in next(iter(diagnostics)).hint


def test_rendering_only_components_never_block(tmp_path: Path) -> None:
    _, diagnostics = check(
        tmp_path,
        HEAD + "    <LightManager/>\n    <SpotLight position='0 1 0'/>\n    <PositionalLight/>\n"
        '    <RecordedCamera/>\n    <OglShader fileVertexShaders="toon.vert"/>\n'
        '    <OglFloatVariable id="x" value="1"/>\n</Node>\n',
    )
    assert codes(diagnostics) == []


def test_sofa_visual_models_are_drawing_only(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Visual models sofac has no spec of (CylinderVisualModel, ClipPlane, DataDisplay) take no
    part in the step: the scene checks clean and plans (a mapping into one is a visual mapping)."""
    from sofac.cli.main import main

    scene = tmp_path / "scene.scn"
    scene.write_text(
        HEAD + '    <UniformMass totalMass="1"/>\n    <Node name="v">\n'
        '        <CylinderVisualModel name="c"/>\n'
        '        <IdentityMapping input="@../dofs" output="@c"/>\n        <ClipPlane/>\n'
        "        <DataDisplay/>\n    </Node>\n</Node>\n"
    )
    assert main(["check", "-q", str(scene)]) == 0
    assert capsys.readouterr().out == ""


def test_required_plugin_of_a_sofa_plugin_is_known(tmp_path: Path) -> None:
    _, diagnostics = check(
        tmp_path, HEAD + '    <RequiredPlugin pluginName="SofaCarving"/>\n'
        '    <RequiredPlugin pluginName="NoSuchPlugin"/>\n</Node>\n'
    )
    assert codes(diagnostics) == [("W224", 7)]


def test_catalogue_is_not_read_for_a_scene_of_hand_written_components(tmp_path: Path) -> None:
    code = (
        "from sofac.check.checker import check_file\n"
        f"_, found = check_file({str(REPO / 'scenes' / 'liver.scn')!r})\n"
        "from sofac.registry import catalogue\n"
        "print(len(list(found)), catalogue._load.cache_info().currsize)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.split() == ["0", "0"]  # liver checks clean without reading SOFA's list


def test_script_reads_a_sofa_tree(tmp_path: Path) -> None:
    """scripts/sofa_components.py on a two-file SOFA tree: registration, base class, Data, alias."""
    base = tmp_path / "sofa" / "Sofa" / "Component" / "Demo"
    (base / "src").mkdir(parents=True)
    (base / "CMakeLists.txt").write_text("project(Sofa.Component.Demo LANGUAGES CXX)\n")
    (base / "src" / "Pusher.h").write_text(
        "template<class DataTypes>\nclass Pusher : public core::behavior::ForceField<DataTypes>\n{\n"
        "    Data<Real> d_push; ///< how hard\n    Data<bool> d_on;\n};\n"
    )
    (base / "src" / "Pusher.cpp").write_text(
        "template<class DataTypes>\nPusher<DataTypes>::Pusher()\n"
        '    : d_push(initData(&d_push, (Real)2.5, "push", "how hard // not a comment"))\n'
        '    , d_on(initData(&d_on, "on", "switch"))\n{\n    addAlias(&d_push, "force");\n}\n'
        "void registerPusher(sofa::core::ObjectFactory* factory)\n{\n"
        '    factory->registerObjects(core::ObjectRegistrationData("Pushes. Hard.")\n'
        "        .add< Pusher<Vec3Types> >(true)\n        .add< Pusher<Rigid3Types> >()"
        '\n        .addAlias("Shover"));\n}\n'
    )
    output = tmp_path / "catalog.json"
    script = REPO / "scripts" / "sofa_components.py"
    run = [sys.executable, str(script), str(tmp_path / "sofa"), "--commit", "abc", "--output", str(output)]
    subprocess.run(run, check=True, capture_output=True)
    import json

    data = json.loads(output.read_text())
    assert data["sofa_commit"] == "abc"
    assert data["components"] == {
        "Pusher": [
            "Sofa.Component.Demo",
            "forcefield",
            "Pushes. Hard.",
            ["Vec3d", "Rigid3d"],
            ["Shover"],
            [["push", "Real", "(Real)2.5", "force"], ["on", "bool", None]],
        ]
    }
    assert subprocess.run([*run, "--check"], capture_output=True).returncode == 0


def test_committed_catalogue_is_what_the_script_writes_for_the_corpus_commit() -> None:
    """Refreshing needs a SOFA checkout; the committed file names the corpus commit and parses."""
    from sofac.registry import catalogue

    text = (REPO / "compiler" / "registry" / "sofa_catalog.json").read_text()
    assert '"generated_by": "scripts/sofa_components.py"' in text
    assert catalogue.spec("OglShader").supported  # a GL shader is rendering only


# --- values read as SOFA reads them -----------------------------------------------------------
def test_integer_ranges_as_sofa_vector_integral() -> None:
    assert parse_ints("0-5").tolist() == [0, 1, 2, 3, 4, 5]
    assert parse_ints("5-2").tolist() == [5, 4, 3, 2]
    assert parse_ints("0-10-3").tolist() == [0, 3, 6, 9]
    assert parse_ints("10-0-3").tolist() == [0, 3, 6, 9]  # a step against the direction swaps the ends
    assert parse_ints("0-3-0").tolist() == [0, 1, 2, 3]  # step 0 becomes 1
    assert parse_ints("1 7-8 2").tolist() == [1, 7, 8, 2]
    with pytest.raises(FieldValueError, match="not an integer or a range"):
        parse_ints("0-x")
    with pytest.raises(FieldValueError, match="range of"):
        parse_ints("0-999999999999")


def test_index_range_in_a_scene(tmp_path: Path) -> None:
    checked, diagnostics = check(
        tmp_path, HEAD + '    <FixedProjectiveConstraint name="fix" indices="0-1"/>\n</Node>\n'
    )
    assert codes(diagnostics) == []
    assert component(checked, "fix").fields["indices"].tolist() == [0, 1]
    _, diagnostics = check(tmp_path, HEAD + '    <FixedProjectiveConstraint indices="0-5"/>\n</Node>\n')
    assert codes(diagnostics) == [("E218", 6)]  # expanded: 3, 4, 5 are past the three DOFs


def test_reals_as_a_cpp_stream_reads_them(tmp_path: Path) -> None:
    assert parse_reals("0-0.707107 1e-3").tolist() == [0.0, -0.707107, 0.001]
    assert parse_reals("1.5.25").tolist() == [1.5, 0.25]
    with pytest.raises(FieldValueError, match="not a number"):
        parse_reals("1 abc")
    checked, diagnostics = check(
        tmp_path,
        HEAD + '    <Node name="n"><MechanicalObject name="m" template="Rigid3d" '
        'position="0 0 0 0 0-0.707107 0.707107"/></Node>\n</Node>\n',
    )
    assert codes(diagnostics) == []
    assert np.allclose(component(checked, "m").fields["position"], [0, 0, 0, 0, 0, -0.707107, 0.707107])


def test_src_at_alone_is_a_warning(tmp_path: Path) -> None:
    _, diagnostics = check(tmp_path, HEAD + '    <TriangleSetTopologyContainer src="@"/>\n</Node>\n')
    assert codes(diagnostics) == [("W225", 6)]
    assert "does nothing" in next(iter(diagnostics)).message


# --- links resolved as SOFA resolves them ----------------------------------------------------
def test_box_roi_takes_positions_through_src(tmp_path: Path) -> None:
    checked, diagnostics = check(
        tmp_path,
        '<Node name="root">\n    <MeshOBJLoader name="loader" filename="square.obj"/>\n'
        '    <BoxROI name="box" src="@loader" box="0.5 -1 -1  2 2 1"/>\n</Node>\n',
        {"square.obj": SQUARE_OBJ},
    )
    assert codes(diagnostics) == []
    assert checked.value(component(checked, "box").component, "indices").tolist() == [1, 2]


def test_no_e212_when_positions_come_from_an_unsupported_generator(tmp_path: Path) -> None:
    _, diagnostics = check(
        tmp_path,
        '<Node name="root">\n    <GridMeshCreator name="loader" resolution="5 5"/>\n'
        '    <MechanicalObject name="m" position="@loader.position"/>\n'
        '    <BoxROI box="0 0 0 1 1 1" position="@m.position"/>\n</Node>\n',
    )
    assert codes(diagnostics) == [("E222", 2)]


def test_topological_mapping_defaults_to_parent_and_own_node(tmp_path: Path) -> None:
    checked, diagnostics = check(
        tmp_path,
        '<Node name="root">\n    <RegularGridTopology name="grid" n="2 2 2" min="0 0 0" max="1 1 1"/>\n'
        '    <MechanicalObject name="dofs"/>\n    <Node name="tetra">\n'
        '        <TetrahedronSetTopologyContainer name="container"/>\n'
        '        <Hexa2TetraTopologicalMapping name="split"/>\n    </Node>\n</Node>\n',
    )
    assert codes(diagnostics) == []
    split = component(checked, "split")
    assert split.links["input"].name == "grid" and split.links["output"].name == "container"
    _, diagnostics = check(
        tmp_path,
        '<Node name="root">\n    <Node name="tetra">\n        <TetrahedronSetTopologyContainer/>\n'
        "        <Hexa2TetraTopologicalMapping/>\n    </Node>\n</Node>\n",
    )
    assert codes(diagnostics) == [("E226", 4)]
    assert "'@../' reaches none" in next(iter(diagnostics)).message


def test_template_sofa_registers_is_unsupported_not_unknown(tmp_path: Path) -> None:
    body = (
        '    <TetrahedronSetTopologyContainer name="t" position="0 0 0 1 0 0 0 1 0 0 0 1"'
        ' tetrahedra="0 1 2 3"/>\n'
        '    <MechanicalObject name="vol" position="@t.position"/>\n'
        '    <Node name="frame">\n'
        '        <MechanicalObject template="Rigid3d" position="0.1 0.1 0.1 0 0 0 1"/>\n'
        "        <BarycentricMapping/>\n    </Node>\n</Node>\n"
    )
    _, diagnostics = check(tmp_path, '<Node name="root">\n' + body)
    assert codes(diagnostics) == [("E222", 6)]  # BarycentricMapping Vec3d,Rigid3d exists in SOFA
    assert "BarycentricMapping Vec3d,Rigid3d is supported by SOFA" in next(iter(diagnostics)).message
    _, diagnostics = check(
        tmp_path,
        '<Node name="root">\n    <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1"/>\n'
        '    <Node name="points">\n        <MechanicalObject position="0 0 0"/>\n'
        "        <BarycentricMapping/>\n    </Node>\n</Node>\n",
    )
    assert codes(diagnostics) == [("E214", 5)]  # Rigid3d,Vec3d: SOFA has none either


# --- files -----------------------------------------------------------------------------------
def test_add_data_repository_adds_its_folder(tmp_path: Path) -> None:
    scene = (
        '<Node name="root">\n    <AddDataRepository path="./meshes"/>\n'
        '    <MeshOBJLoader name="loader" filename="square.obj"/>\n'
        '    <MechanicalObject name="m" src="@loader"/>\n</Node>\n'
    )
    checked, diagnostics = check(tmp_path, scene, {"meshes/square.obj": SQUARE_OBJ})
    assert codes(diagnostics) == []
    assert checked.positions(component(checked, "m").component).shape == (4, 3)
    _, diagnostics = check(tmp_path, scene.replace("./meshes", "./nowhere"))
    assert codes(diagnostics) == [("E219", 2), ("E219", 3)]
    outside = tmp_path / "scene"
    outside.mkdir()
    (outside / "scene.scn").write_text(scene.replace("./meshes", "../meshes"))
    _, diagnostics = check_file(outside / "scene.scn")
    assert codes(diagnostics) == [("E108", 2), ("E219", 3)]


def test_sofa_data_path_variables(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = tmp_path / "sofa"
    (root / "share" / "mesh").mkdir(parents=True)
    (root / "share" / "mesh" / "square.obj").write_text(SQUARE_OBJ)
    scene = (
        '<Node name="root">\n    <MeshOBJLoader name="l" filename="mesh/square.obj"/>\n'
        '    <MechanicalObject src="@l"/>\n</Node>\n'
    )
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "scene.scn").write_text(scene)
    _, diagnostics = check_file(tmp_path / "work" / "scene.scn")
    assert [d.code for d in diagnostics if d.code.startswith("E")] == ["E219"]
    monkeypatch.setenv("SOFA_ROOT", str(root))
    _, diagnostics = check_file(tmp_path / "work" / "scene.scn")
    assert [d.code for d in diagnostics if d.code.startswith("E")] == []
    monkeypatch.delenv("SOFA_ROOT")
    monkeypatch.setenv("SOFA_DATA_PATH", str(root / "share"))
    _, diagnostics = check_file(tmp_path / "work" / "scene.scn")
    assert [d.code for d in diagnostics if d.code.startswith("E")] == []


def test_examples_tree_searches_share_beside_it(tmp_path: Path) -> None:
    """A scene under SOFA's examples/ finds mesh/ in share/, as SOFA's default data path."""
    (tmp_path / "share" / "mesh").mkdir(parents=True)
    (tmp_path / "share" / "mesh" / "square.obj").write_text(SQUARE_OBJ)
    (tmp_path / "examples" / "mesh").mkdir(parents=True)
    (tmp_path / "examples" / "Demo").mkdir()
    scene = tmp_path / "examples" / "Demo" / "scene.scn"
    scene.write_text(
        '<Node name="root">\n    <MeshOBJLoader name="l" filename="mesh/square.obj"/>\n'
        '    <MechanicalObject src="@l"/>\n</Node>\n'
    )
    _, diagnostics = check_file(scene)
    assert codes(diagnostics) == []


def test_unreadable_mesh_is_a_diagnostic_not_an_exit(tmp_path: Path) -> None:
    """meshio ends the process on a POLYDATA .vtk (sys.exit): the checker reports it instead,
    and goes on with the next file."""
    polydata = "# vtk DataFile Version 3.0\nsurface\nBINARY\nDATASET POLYDATA\nPOINTS 1 float\n"
    scene = (
        '<Node name="root">\n    <MeshVTKLoader name="l" filename="s.vtk"/>\n'
        '    <MechanicalObject src="@l"/>\n</Node>\n'
    )
    _, diagnostics = check(tmp_path, scene, {"s.vtk": polydata})
    assert codes(diagnostics) == [("E219", 2)]
    assert "POLYDATA" in next(iter(diagnostics)).message


# --- one diagnostic at the cause -------------------------------------------------------------
def test_no_e221_next_to_an_unknown_or_unsupported_linear_solver(tmp_path: Path) -> None:
    scene = (
        '<Node name="root">\n    <EulerImplicitSolver/>\n    <{solver}/>\n'
        '    <MechanicalObject position="0 0 0"/>\n    <UniformMass totalMass="1"/>\n</Node>\n'
    )
    _, diagnostics = check(tmp_path, scene.format(solver="SparseTAUCSLLtSolver"))
    assert codes(diagnostics) == [("E200", 3)]
    _, diagnostics = check(tmp_path, scene.format(solver="SparsePARDISOSolver"))
    assert codes(diagnostics) == [("E222", 3)]


# --- check and compile agree -----------------------------------------------------------------
def test_check_reports_what_the_compile_refuses(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A RestShapeSpringsForceField pulling towards another state's positions checks as valid
    SOFA; the planner refuses it, and `sofac check` says so at its line, as `sofac run` would."""
    from sofac.cli.main import main

    scene = tmp_path / "scene.scn"
    scene.write_text(
        HEAD + '    <Node name="rest"><MechanicalObject name="target" position="0 1 0 1 1 0 2 1 0"/></Node>\n'
        '    <UniformMass totalMass="1"/>\n'
        '    <RestShapeSpringsForceField stiffness="10" external_rest_shape="@rest/target"/>\n</Node>\n'
    )
    _, diagnostics = check_file(scene)
    assert codes(diagnostics) == []  # the checker alone finds nothing wrong
    assert main(["check", "--format", "json", str(scene)]) == 1
    import json

    reported = [(d["code"], d["line"]) for d in json.loads(capsys.readouterr().out)]
    assert reported == [("E222", 8)]


def test_plugin_scene_in_a_sofa_tree_finds_share(tmp_path: Path) -> None:
    """applications/plugins/X/examples/scene.scn of a SOFA checkout: SOFA's share/ and examples/."""
    (tmp_path / "share" / "mesh").mkdir(parents=True)
    (tmp_path / "share" / "mesh" / "square.obj").write_text(SQUARE_OBJ)
    (tmp_path / "examples").mkdir()
    folder = tmp_path / "applications" / "plugins" / "X" / "examples"
    folder.mkdir(parents=True)
    (folder / "scene.scn").write_text(
        '<Node name="root">\n    <MeshOBJLoader name="l" filename="mesh/square.obj"/>\n'
        '    <MechanicalObject src="@l"/>\n</Node>\n'
    )
    _, diagnostics = check_file(folder / "scene.scn")
    assert codes(diagnostics) == []


def test_state_without_positions_has_sofa_s_one_default_coordinate(tmp_path: Path) -> None:
    """MechanicalObject's constructor resizes to one coordinate: a rigid frame at the origin."""
    scene = (
        '<Node name="root">\n    <EulerImplicitSolver/>\n    <CGLinearSolver/>\n'
        '    <MechanicalObject name="frame" template="Rigid3d"/>\n'
        '    <FixedProjectiveConstraint indices="{index}"/>\n    <Node name="child">\n'
        '        <MechanicalObject name="point" position="1 0 0"/>\n'
        '        <RigidMapping name="map" index="0"/>\n    </Node>\n</Node>\n'
    )
    checked, diagnostics = check(tmp_path, scene.format(index=0))
    assert codes(diagnostics) == []
    frame = component(checked, "frame").component
    assert checked.positions(frame).tolist() == [[0, 0, 0, 0, 0, 0, 1]]
    _, diagnostics = check(tmp_path, scene.format(index=1))
    assert codes(diagnostics) == [("E218", 5)]  # index 1 is past the one DOF


def test_state_beside_a_topology_takes_no_default_coordinate(tmp_path: Path) -> None:
    """Beside a topology whose points come from an engine sofac does not evaluate, the state's
    size is unknown (SOFA's init takes the topology's points): no E218 against one DOF."""
    _, diagnostics = check(
        tmp_path,
        '<Node name="root">\n    <GenerateCylinder name="cyl"/>\n'
        '    <TetrahedronSetTopologyContainer position="@cyl.output_position"/>\n'
        '    <MechanicalObject name="dofs"/>\n    <FixedProjectiveConstraint indices="15"/>\n</Node>\n',
    )
    assert codes(diagnostics) == [("E222", 2)]


def test_warm_load_reads_no_registry() -> None:
    """A scene loaded before comes from its warm record: neither the registry nor SOFA's list is
    imported (compiler/warm.py)."""
    scene = str(REPO / "scenes" / "hybrid_pendulum.scn")
    load = f"import sys, sofac\nsofac.load({scene!r})\n"
    subprocess.run([sys.executable, "-c", load], check=True, capture_output=True)  # compiles once
    probe = load + "print('sofac.registry' in sys.modules, 'sofac.registry.catalogue' in sys.modules)\n"
    result = subprocess.run([sys.executable, "-c", probe], check=True, capture_output=True, text=True)
    assert result.stdout.split() == ["False", "False"]


def test_vec2_and_rigid_states_take_their_topology_points(tmp_path: Path) -> None:
    """MechanicalObject::init copies its topology's points with DataTypes::set(x, px, py, pz):
    a Vec2 state keeps x and y, a rigid one the centre with identity orientation."""
    checked, diagnostics = check(
        tmp_path,
        '<Node name="root">\n    <Node name="flat">\n        <MechanicalObject name="m" template="Vec2d"/>\n'
        '        <RegularGridTopology n="3 2 1" min="0 0 0" max="2 1 0"/>\n    </Node>\n'
        '    <Node name="frames">\n        <MechanicalObject name="r" template="Rigid3d"/>\n'
        '        <MeshTopology position="1 2 3  4 5 6"/>\n    </Node>\n</Node>\n',
    )
    assert codes(diagnostics) == []
    flat = checked.positions(component(checked, "m").component)
    assert flat.tolist() == [[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]]
    frames = checked.positions(component(checked, "r").component)
    assert frames.tolist() == [[1, 2, 3, 0, 0, 0, 1], [4, 5, 6, 0, 0, 0, 1]]


def test_two_dimensional_grid_has_sofa_s_triangles_and_edges(tmp_path: Path, capsys) -> None:
    """GridTopology's update splits each quad (q0 q1 q2) (q0 q2 q3) and derives the edges from the
    triangles (createEdgeSetArray's order): a triangle container reading the grid through src= gets
    them, and TriangularFEMForceField compiles on it."""
    from sofac.cli.main import main

    text = (
        '<Node name="root" dt="0.01">\n    <EulerImplicitSolver/>\n    <CGLinearSolver iterations="25"'
        ' tolerance="1e-9" threshold="1e-9"/>\n'
        '    <RegularGridTopology name="grid" n="3 2 1" min="0 0 0" max="2 1 0"/>\n'
        '    <MechanicalObject src="@grid"/>\n    <TriangleSetTopologyContainer name="tri" src="@grid"/>\n'
        '    <DiagonalMass massDensity="1"/>\n    <FixedProjectiveConstraint indices="0 3"/>\n'
        '    <TriangularFEMForceField youngModulus="60" poissonRatio="0.3" method="large"/>\n</Node>\n'
    )
    checked, diagnostics = check(tmp_path, text)
    assert codes(diagnostics) == []
    grid = component(checked, "grid").component
    assert checked.value(grid, "quads").reshape(-1, 4).tolist() == [[0, 1, 4, 3], [1, 2, 5, 4]]
    triangles = [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]]
    assert checked.value(grid, "triangles").reshape(-1, 3).tolist() == triangles
    edges = [[1, 4], [4, 0], [0, 1], [4, 3], [3, 0], [2, 5], [5, 1], [1, 2], [5, 4]]
    assert checked.value(grid, "edges").reshape(-1, 2).tolist() == edges
    tri = component(checked, "tri").component
    assert checked.value(tri, "triangles").reshape(-1, 3).tolist() == triangles
    assert main(["check", "-q", str(tmp_path / "scene.scn")]) == 0  # and the planner accepts it
    assert capsys.readouterr().out == ""


def test_a_repeated_template_of_a_registered_type_is_unsupported_not_unknown(tmp_path: Path) -> None:
    """SofaCUDA's scenes write DiagonalMass template="CudaVec3f,CudaVec3f", SOFA registering it for
    CudaVec3f: its factory tries every creator when the written template has none, so the class is
    SOFA's (E222), not an unknown template (E208)."""
    _, diagnostics = check(
        tmp_path,
        '<Node name="root" dt="0.01">\n    <DefaultAnimationLoop/>\n'
        '    <MechanicalObject template="CudaVec3f" position="0 0 0"/>\n'
        '    <DiagonalMass template="CudaVec3f,CudaVec3f"/>\n</Node>\n',
    )
    assert [(d.code, d.loc.line) for d in diagnostics.errors] == [("E222", 3), ("E222", 4)]
    assert "DiagonalMass CudaVec3f,CudaVec3f is supported by SOFA" in diagnostics.errors[1].message
