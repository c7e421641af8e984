"""Attributes SOFA reads in a component's parse() with getAttributeAsFloat / getAttributeAsInt (strtof,
strtol): single-precision numbers; a text that is not one number is SOFA's default with a logged
message, so a warning (W225) here, not an error. Found by `sofac check` on SOFA's example tree
(Component/Mapping/Linear/CenterOfMassMapping.scn writes dx="0 0 0 ..." on MechanicalObjects and a
normal list in OglModel's normals; Component/MechanicalLoad/TaitSurfacePressureForceField.scn
scale="0.25 0.25 0.25" on a MeshOBJLoader)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sofac.check.checker import check_file

SCENE = """\
<Node name="root" gravity="0 0 0" dt="0.01"><DefaultAnimationLoop/>
  <MeshOBJLoader name="loader" filename="cube.obj" {loader}/>
  <Node name="body">
    <MechanicalObject name="dofs" position="0 0 0  1 0 0" {state}/>
    <Node name="visual"><OglModel name="skin" src="@../../loader" {visual}/></Node>
  </Node>
</Node>
"""
CUBE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n"


def check(tmp_path: Path, *, loader: str = "", state: str = "", visual: str = ""):  # type: ignore[no-untyped-def]
    (tmp_path / "cube.obj").write_text(CUBE)
    path = tmp_path / "scene.scn"
    path.write_text(SCENE.format(loader=loader, state=state, visual=visual))
    checked, diags = check_file(path)
    components = {c.label: c for c in checked.scene.root.components()} if checked else {}
    return checked, diags, components


def test_center_of_mass_mapping_attributes_check_clean(tmp_path: Path) -> None:
    """CenterOfMassMapping.scn's attributes: warnings on their lines, no error, SOFA's defaults."""
    checked, diags, components = check(
        tmp_path,
        state='dx="0 0 0 0 0 0 0 0 0 0 0 0"',
        visual='normals="-0.57735 -0.57735 -0.57735 0.333333 -0.666667 -0.666667"',
        loader='scale="0.25 0.25 0.25"',
    )
    assert diags.errors == []
    assert sorted((d.code, d.loc.line, d.loc.attribute) for d in diags.warnings) == [
        ("W225", 2, "scale"),
        ("W225", 4, "dx"),
        ("W225", 5, "normals"),
    ]
    assert "uses its default" in diags.warnings[0].message
    assert checked.positions(components["dofs"]).tolist() == [[0, 0, 0], [1, 0, 0]]  # no translation
    assert np.asarray(checked.value(components["loader"], "position")).max() == 1.0  # not scaled
    assert checked.value(components["skin"], "normals") is None  # useNormals keeps its default


def test_legacy_numbers_are_single_precision(tmp_path: Path) -> None:
    """MechanicalObject::parse: translation = (Real) getAttributeAsFloat("dx"): 0.1 is float's 0.1."""
    checked, diags, components = check(tmp_path, state='dx="0.1" dy="-2"')
    assert diags.errors == [] and diags.warnings == []
    points = checked.positions(components["dofs"])
    assert points[:, 0].tolist() == [float(np.float32(0.1)), 1.0 + float(np.float32(0.1))]
    assert points[:, 1].tolist() == [-2.0, -2.0]


@pytest.mark.parametrize(("text", "flag"), [("0", False), ("2", True), ("false", None)])
def test_normals_is_an_integer(tmp_path: Path, text: str, flag: bool | None) -> None:
    """VisualModelImpl::parse: setUseNormals(getAttributeAsInt("normals", 1) != 0): "false" is not an
    integer, so SOFA keeps useNormals true (a warning, and no value here)."""
    checked, diags, components = check(tmp_path, visual=f'normals="{text}"')
    assert diags.errors == []
    assert [d.code for d in diags.warnings] == ([] if text != "false" else ["W225"])
    assert checked.value(components["skin"], "normals") is flag


def test_incomplete_last_coordinate_is_dropped(tmp_path: Path) -> None:
    """vector<Coord>::read stops at an incomplete last value and drops it, the end of the text
    clearing the stream's error: SOFA reads 3 points from 10 numbers (Component/IO/Mesh/
    STLExporter.scn) and one rigid, quaternion 0 0 0 0, from "0 0 0 0 0 0 0 1"
    (Component/SolidMechanics/Spring/RestShapeSpringsForceField2.scn). A warning, not E205."""
    path = tmp_path / "short.scn"
    path.write_text(
        '<Node name="root"><DefaultAnimationLoop/>\n'
        '  <MechanicalObject name="points" position="0 1 2 3 4 5 6 7 8 9"/>\n'
        '  <Node name="r">\n'
        '    <MechanicalObject name="frame" template="Rigid3" position="0 0 0 0 0 0 0 1"/>\n'
        "  </Node>\n"
        "</Node>\n"
    )
    checked, diags = check_file(path)
    assert diags.errors == []
    assert [(d.code, d.loc.line, d.loc.attribute) for d in diags.warnings] == [
        ("W225", 2, "position"),
        ("W225", 4, "position"),
    ]
    assert "SOFA reads 3 Vec3d Coords and ignores the last 1 number" in diags.warnings[0].message
    components = {c.label: c for c in checked.scene.root.components()}
    assert checked.positions(components["points"]).tolist() == [[0, 1, 2], [3, 4, 5], [6, 7, 8]]
    assert checked.positions(components["frame"]).tolist() == [[0, 0, 0, 0, 0, 0, 0]]


def test_integer_data_reads_the_leading_integer(tmp_path: Path) -> None:
    """Data<int>::read is `istream >> int`: iterations="1e4" is 1 iteration in SOFA, silently
    (Component/Mapping/NonLinear/SquareMapping.scn): a warning naming SOFA's value, which is used."""
    path = tmp_path / "cg.scn"
    path.write_text(
        '<Node name="root"><DefaultAnimationLoop/>\n'
        '  <EulerImplicitSolver/>\n  <CGLinearSolver name="cg" iterations="1e4"/>\n'
        '  <MechanicalObject position="0 0 0"/>\n  <UniformMass totalMass="1"/>\n'
        "</Node>\n"
    )
    checked, diags = check_file(path)
    assert diags.errors == []
    assert [(d.code, d.loc.line, d.loc.attribute) for d in diags.warnings] == [("W225", 3, "iterations")]
    assert "SOFA's value here: 1" in diags.warnings[0].hint
    cg = next(c for c in checked.scene.root.components() if c.label == "cg")
    assert checked.value(cg, "iterations") == 1


def test_rigid_mass_reads_its_first_eleven_numbers(tmp_path: Path) -> None:
    """`istream >> RigidMass` reads mass, volume and the 3x3 inertia and leaves the rest unread
    (Component/Constraint/Lagrangian/BilateralLagrangianConstraint_Rigid.scn gives 12 numbers)."""
    path = tmp_path / "mass.scn"
    path.write_text(
        '<Node name="root"><DefaultAnimationLoop/><EulerExplicitSolver/>\n'
        '  <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1"/>\n'
        '  <UniformMass name="mass" vertexMass="1 1 0.1 0 0 0 0.1 0 0 0 0.1 0"/>\n'
        "</Node>\n"
    )
    checked, diags = check_file(path)
    assert diags.errors == []
    assert [(d.code, d.loc.line, d.loc.attribute) for d in diags.warnings] == [("W225", 3, "vertexMass")]
    mass = next(c for c in checked.scene.root.components() if c.label == "mass")
    assert np.asarray(checked.value(mass, "vertexMass")).tolist() == [1, 1, 0.1, 0, 0, 0, 0.1, 0, 0, 0, 0.1]


def test_empty_fixed_size_value_keeps_the_default(tmp_path: Path) -> None:
    """Data<T>::read("") only resizes the value to 0 elements, which a number or a Vec3 cannot be,
    and Base::parseField says nothing about an empty text: SOFA keeps the default
    (examples/Objects/BoxConstantForceField.xml writes showArrowSize=""). A warning,
    not E204/E205; an empty list stays an empty list."""
    path = tmp_path / "empty.scn"
    path.write_text(
        '<Node name="root"><DefaultAnimationLoop/><EulerExplicitSolver/>\n'
        '  <MechanicalObject name="dofs" position="0 0 0  1 0 0"\n      translation=""/>\n'
        '  <UniformMass totalMass="1"/>\n'
        '  <ConstantForceField name="push" indices="0" forces="1 2 3" showArrowSize=""/>\n'
        '  <FixedProjectiveConstraint name="fix" indices=""/>\n'
        "</Node>\n"
    )
    checked, diags = check_file(path)
    assert diags.errors == []
    assert [(d.code, d.loc.line, d.loc.attribute) for d in diags.warnings] == [
        ("W225", 3, "translation"),
        ("W225", 5, "showArrowSize"),
    ]
    assert "is empty: SOFA keeps its default" in diags.warnings[0].message
    components = {c.label: c for c in checked.scene.root.components()}
    assert checked.value(components["push"], "showArrowSize") == 0.0
    assert checked.positions(components["dofs"]).tolist() == [[0, 0, 0], [1, 0, 0]]
    assert np.asarray(checked.value(components["fix"], "indices")).size == 0


@pytest.mark.parametrize("src", ["", "loader"])
def test_src_that_is_not_a_link_is_sofa_s_error(tmp_path: Path, src: str) -> None:
    """BaseComponent::parse: a src not starting with '@' is an error in SOFA ("'src' attribute value
    should be a link using '@'"; examples/Objects/DynamicSparseGridTopology.xml writes src="")."""
    _, diags, _ = check(tmp_path, state=f'src="{src}"')
    assert [(d.code, d.loc.line, d.loc.attribute) for d in diags.errors] == [("E213", 4, "src")]
    assert "is not a link: SOFA reports that it should start with '@'" in diags.errors[0].message


def test_optional_link_to_nothing_is_a_warning(tmp_path: Path) -> None:
    """RestShapeSpringsForceField::init: an external_rest_shape that finds nothing is SOFA's warning
    ("external_rest_shape ... not found") and the springs pull to the state's own rest positions
    (Xitact's XitactGrasping*.scn write external_rest_shape="@toto"); a broken object1 stays E213."""
    path = tmp_path / "rest.scn"
    path.write_text(
        '<Node name="root"><DefaultAnimationLoop/><EulerImplicitSolver/><CGLinearSolver/>\n'
        '  <MechanicalObject name="dofs" position="0 0 0  1 0 0"/>\n  <UniformMass totalMass="1"/>\n'
        '  <RestShapeSpringsForceField name="springs" stiffness="10" external_rest_shape="@toto"/>\n'
        '  <SpringForceField object1="@nothing" object2="@dofs"/>\n'
        "</Node>\n"
    )
    checked, diags = check_file(path)
    assert [(d.code, d.loc.line, d.loc.attribute) for d in diags.warnings] == [
        ("W233", 4, "external_rest_shape")
    ]
    assert "SOFA warns and goes on as if external_rest_shape were not written" in diags.warnings[0].message
    assert [(d.code, d.loc.line, d.loc.attribute) for d in diags.errors] == [("E213", 5, "object1")]
    springs = next(c for c in checked.scene.root.components() if c.label == "springs")
    assert "external_rest_shape" not in checked.of(springs).links
