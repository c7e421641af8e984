"""One test per diagnostic code: a tiny scene that triggers exactly that code, at an exact line.

Every case writes its scene (and any included or referenced file) under ``tmp_path``, checks it with
:func:`sofac.check.checker.check_file` and compares the *whole* list of diagnostics with the one expected:
code, file, line and attribute. Most scenes start with :data:`HEAD` (lines 1-5: a root node with a
solver pair and a three-DOF Vec3d state), so their first line of interest is line 6.

:func:`test_every_code_is_covered` keeps this file in step with :data:`sofac.diagnostics.CODES`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from sofac.check.checker import check_file
from sofac.cli.main import main
from sofac.diagnostics import CODES, Diagnostic, Diagnostics, SceneError, Severity, SourceLoc
from sofac.front.parse import parse_scene

COMPILER = Path(__file__).resolve().parents[1] / "compiler"

# Lines 1-5 of most scenes below; the body starts at line 6.
HEAD = """\
<Node name="root" dt="0.01" gravity="0 -9.81 0">
    <DefaultAnimationLoop/>
    <EulerImplicitSolver/>
    <CGLinearSolver iterations="25" tolerance="1e-9" threshold="1e-9"/>
    <MechanicalObject name="dofs" position="0 0 0  1 0 0  2 0 0"/>
"""


def dyn(body: str) -> str:
    """A scene: :data:`HEAD`, then ``body`` from line 6, then the closing tag."""
    return HEAD + body + "</Node>\n"


@pytest.fixture(autouse=True)
def _no_env_data_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SOFAC_DATA_PATH", raising=False)


@dataclass(frozen=True)
class Case:
    id: str
    code: str
    scene: str
    line: int
    attribute: str | None = None
    files: Mapping[str, str] = field(default_factory=dict)  # more files, relative to the scene's folder
    file: str = "scene.scn"  # the file the diagnostic names
    hint: str = ""  # a fragment the hint must contain
    written: bool = True  # the attribute is written on the line (False: an implicit default)


PART = """\
<Node name="part">
    <MechanicalObject position="0 0 0"/>
</Node>
"""

# A node "body" (line 6) with two rigid frames (line 7), a mass (line 8) and mapped points (line 11).
RIGID_BODY = """\
    <Node name="body">
        <MechanicalObject template="Rigid3d" name="frame" position="0 0 0 0 0 0 1  1 0 0 0 0 0 1"/>
        <UniformMass {mass}/>
        <Node name="pts">
            <MechanicalObject position="{points}"/>
            <RigidMapping rigidIndexPerPoint="{per_point}"/>
        </Node>
    </Node>
"""
ANISOTROPIC = 'vertexMass="1 1 [1 0 0, 0 2 0, 0 0 3]"'

CASES = [
    # --- reading files
    Case("malformed", "E101", "<Node>\n    <A>\n    </B>\n</Node>\n", 3),
    Case(
        "malformed-include",
        "E101",
        dyn('    <include href="bad.xml"/>\n'),
        3,
        files={"bad.xml": "<Node>\n  <A>\n  </B>\n</Node>\n"},
        file="bad.xml",
    ),
    Case("doctype", "E102", '<?xml version="1.0"?>\n<!DOCTYPE Node [<!ENTITY x "y">]>\n<Node/>\n', 2),
    Case("too-deep", "E104", "\n".join(["<Node>"] * 201 + ["</Node>"] * 201), 201),
    Case("no-space-between-attributes", "W105", dyn('    <UniformMass name="m"totalMass="1"/>\n'), 6),
    Case("include-not-found", "E106", dyn('    <include href="nope.xml"/>\n'), 6, "href"),
    Case("include-itself", "E107", dyn('    <include href="scene.scn"/>\n'), 6, "href"),
    Case(
        "include-outside-roots",
        "E108",
        dyn('    <include href="../outside.xml"/>\n'),
        6,
        "href",
        files={"../outside.xml": '<Node name="outside"/>\n'},
    ),
    Case("include-without-href", "E109", dyn("    <include/>\n"), 6),
    Case("object-without-type", "E109", dyn("    <Object/>\n"), 6),
    Case(
        "override-matches-nothing",
        "W110",
        dyn('    <include href="part.xml" color="1 0 0"/>\n'),
        6,
        "color",
        files={"part.xml": PART},
    ),
    Case(
        "node-inside-component",
        "W111",
        dyn("""\
    <UniformMass totalMass="1">
        <Node name="x"/>
    </UniformMass>
"""),
        7,
    ),
    # Cut short after a final newline: libxml2 says line 3, which the file does not have.
    Case("truncated", "E101", '<Node name="root">\n    <MechanicalObject/>\n', 2),
    Case("root-not-node", "E112", "<Scene>\n</Scene>\n", 1),
    # --- names
    Case(
        "did-you-mean",
        "E200",
        dyn('    <UnifromMass totalMass="1"/>\n'),
        6,
        hint="did you mean UniformMass",
    ),
    Case(
        "former-name",
        "E201",
        dyn('    <UniformMass totalMass="1"/>\n    <TriangleModel/>\n'),
        7,
        hint="<TriangleCollisionModel>",
    ),
    Case("former-solver-name", "E201", dyn('    <CGSolver iterations="25"/>\n'), 6),
    Case("legacy-name", "W202", dyn('    <FixedConstraint indices="0"/>\n'), 6),
    Case(
        "unknown-attribute",
        "W203",
        dyn('    <UniformMass totalMas="1"/>\n'),
        6,
        "totalMas",
        hint="did you mean 'totalMass'",
    ),
    # --- values
    Case("not-a-number", "E204", dyn('    <UniformMass totalMass="abc"/>\n'), 6, "totalMass"),
    Case(
        "integer-too-large",
        "E204",
        dyn('    <FixedProjectiveConstraint indices="1 99999999999999999999999"/>\n'),
        6,
        "indices",
        hint="far smaller",
    ),
    Case(
        "positions-not-multiple-of-3",
        "W225",  # SOFA drops the incomplete last value
        dyn("""\
    <Node name="c">
        <MechanicalObject position="0 0 0  1 0"/>
    </Node>
"""),
        7,
        "position",
        hint="3 numbers per DOF",
    ),
    Case(
        "rigid-positions-not-multiple-of-7",
        "W225",  # SOFA drops the incomplete last value
        dyn("""\
    <Node name="r">
        <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0"/>
    </Node>
"""),
        7,
        "position",
        hint="7 numbers per DOF",
    ),
    Case(
        "vec2-positions",
        "W225",  # SOFA drops the incomplete last value
        """\
<Node name="root">
    <MechanicalObject template="Vec2d" position="0 0  1 1  2"/>
</Node>
""",
        2,
        "position",
    ),
    Case("spring-with-4-numbers", "E205", dyn('    <SpringForceField spring="0 1 10 0.1"/>\n'), 6, "spring"),
    Case("nan", "E206", dyn('    <UniformMass totalMass="nan"/>\n'), 6, "totalMass"),
    Case("inf", "E206", dyn('    <UniformMass totalMass="-inf"/>\n'), 6, "totalMass"),
    Case("overflow-1e400", "E206", dyn('    <UniformMass totalMass="1e400"/>\n'), 6, "totalMass"),
    Case(
        "nan-in-positions",
        "E206",
        dyn("""\
    <Node name="c">
        <MechanicalObject position="0 0 nan"/>
    </Node>
"""),
        7,
        "position",
    ),
    Case("mass-zero", "E207", dyn('    <UniformMass totalMass="0"/>\n'), 6, "totalMass"),
    Case("mass-negative", "E207", dyn('    <UniformMass totalMass="-1"/>\n'), 6, "totalMass"),
    Case("density-negative", "E207", dyn('    <MeshMatrixMass massDensity="-2"/>\n'), 6, "massDensity"),
    Case(
        "poisson-0.5",
        "E207",
        dyn('    <TetrahedronFEMForceField poissonRatio="0.5" youngModulus="1e3"/>\n'),
        6,
        "poissonRatio",
    ),
    Case(
        "poisson-minus-1",
        "E207",
        dyn('    <TetrahedronFEMForceField poissonRatio="-1" youngModulus="1e3"/>\n'),
        6,
        "poissonRatio",
    ),
    Case(
        "young-zero",
        "E207",
        dyn('    <TetrahedronFEMForceField poissonRatio="0.3" youngModulus="0"/>\n'),
        6,
        "youngModulus",
    ),
    Case("vertex-mass-zero", "E207", dyn('    <UniformMass vertexMass="0"/>\n'), 6, "vertexMass"),
    Case(
        "rigid-vertex-mass-negative",
        "E207",
        dyn("""\
    <Node name="r">
        <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1"/>
        <UniformMass vertexMass="-2 1 [1 0 0, 0 1 0, 0 0 1]"/>
    </Node>
"""),
        8,
        "vertexMass",
        hint="meaningful",
    ),
    Case("dt-zero", "E207", '<Node name="root"\n      dt="0">\n</Node>\n', 2, "dt"),
    Case("dt-negative", "E207", '<Node name="root" dt="-0.01">\n</Node>\n', 1, "dt"),
    # --- templates and states
    Case(
        "unknown-template",
        "E208",
        dyn('    <UniformMass template="Vec4d" totalMass="1"/>\n'),
        6,
        "template",
    ),
    Case(
        "float-template",
        "W209",
        dyn('    <UniformMass template="Vec3f" totalMass="1"/>\n'),
        6,
        "template",
    ),
    Case(
        "template-mismatch",
        "E210",
        dyn('    <UniformMass template="Rigid3d" totalMass="1"/>\n'),
        6,
        "template",
    ),
    Case(
        "inferred-template-not-accepted",
        "E210",
        dyn("""\
    <Node name="r">
        <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1"/>
        <TetrahedronFEMForceField youngModulus="1e3" poissonRatio="0.3"/>
    </Node>
"""),
        8,
    ),
    Case(
        "mapping-template-mismatch",
        "E210",
        dyn("""\
    <Node name="c">
        <MechanicalObject name="pts" position="0 0 0"/>
        <IdentityMapping template="Vec3d,Vec1d" input="@../dofs" output="@pts"/>
    </Node>
"""),
        8,
        "template",
    ),
    Case(
        "two-mechanical-objects",
        "E211",
        dyn('    <MechanicalObject name="second" position="0 0 0"/>\n'),
        6,
    ),
    Case("mass-without-state", "E212", '<Node name="root">\n    <UniformMass totalMass="1"/>\n</Node>\n', 2),
    # --- links and mappings
    Case(
        "broken-data-link",
        "W233",
        dyn('    <FixedProjectiveConstraint indices="@box.indices"/>\n'),
        6,
        "indices",
    ),
    Case(
        "broken-object-link",
        "E213",
        dyn('    <UniformMass mstate="@nowhere" totalMass="1"/>\n'),
        6,
        "mstate",
    ),
    Case(
        "broken-src",
        "E213",
        dyn("""\
    <Node name="c">
        <MechanicalObject src="@loader"/>
    </Node>
"""),
        7,
        "src",
    ),
    Case(
        "rigid-mapping-vec3-input",
        "E214",
        dyn("""\
    <Node name="c">
        <MechanicalObject name="pts" position="0 0 0"/>
        <RigidMapping input="@../dofs" output="@pts"/>
    </Node>
"""),
        8,
        hint="needs an input of type Rigid",
    ),
    Case(
        "input-unreachable",
        "E215",
        """\
<Node name="root">
    <MechanicalObject name="pts" position="0 0 0"/>
    <IdentityMapping output="@pts"/>
</Node>
""",
        3,
        "input",
        written=False,  # the default input "@../" of a mapping in the root node
    ),
    Case(
        "output-not-in-node",
        "E216",
        dyn("""\
    <Node name="c">
        <MechanicalObject name="pts" position="0 0 0  1 0 0  2 0 0"/>
    </Node>
    <Node name="d">
        <IdentityMapping input="@../dofs" output="@../c/pts"/>
    </Node>
"""),
        10,
        "output",
    ),
    Case(
        "mapping-cycle",
        "E217",
        dyn("""\
    <Node name="a">
        <MechanicalObject name="x" position="0 0 0"/>
        <IdentityMapping input="@../b/y" output="@x"/>
    </Node>
    <Node name="b">
        <MechanicalObject name="y" position="0 0 0"/>
        <IdentityMapping input="@../a/x" output="@y"/>
    </Node>
"""),
        12,
    ),
    # --- indices, files, solvers, support
    Case("constraint-index", "E218", dyn('    <FixedProjectiveConstraint indices="0 5"/>\n'), 6, "indices"),
    Case("negative-index", "E218", dyn('    <FixedProjectiveConstraint indices="-1"/>\n'), 6, "indices"),
    Case("spring-end", "E218", dyn('    <SpringForceField spring="0 7 10 0.1 1"/>\n'), 6, "spring"),
    Case(
        "rigid-index-per-point",
        "E218",
        dyn(RIGID_BODY.format(mass='vertexMass="1"', points="0 0 0  1 0 0", per_point="0 2")),
        11,
        "rigidIndexPerPoint",
    ),
    Case(
        "boxroi-result",
        "E218",
        dyn("""\
    <BoxROI name="box" box="-1 -1 -1  10 1 1"/>
    <Node name="small">
        <MechanicalObject name="two" position="0 0 0  1 0 0"/>
        <FixedProjectiveConstraint indices="@../box.indices"/>
    </Node>
"""),
        9,
        "indices",
    ),
    Case(
        "missing-mesh",
        "E219",
        dyn("""\
    <MeshOBJLoader name="loader" filename="missing.obj"/>
    <Node name="v">
        <OglModel src="@../loader"/>
        <MechanicalObject src="@../loader"/>
    </Node>
"""),
        6,
        "filename",
    ),
    Case(
        "visual-only-loader-missing-file",
        "W231",
        dyn("""\
    <Node name="v">
        <MeshOBJLoader name="loader" filename="missing.obj"/>
        <OglModel name="visual" src="@loader"/>
        <BarycentricMapping input="@.." output="@visual"/>
    </Node>
"""),
        7,
        "filename",
    ),
    Case(
        "no-ode-solver",
        "W220",
        """\
<Node name="root">
    <MechanicalObject position="0 0 0"/>
    <UniformMass totalMass="1"/>
</Node>
""",
        2,
    ),
    Case(
        "implicit-without-linear-solver",
        "E221",
        """\
<Node name="root">
    <EulerImplicitSolver/>
    <MechanicalObject position="0 0 0"/>
</Node>
""",
        2,
    ),
    Case(
        "unsupported",
        "E222",
        dyn("    <TopologicalChangeProcessor/>\n"),
        6,
        hint="--allow-unsupported",
    ),
    Case("unknown-plugin", "W224", dyn('    <RequiredPlugin pluginName="NoSuchPlugin"/>\n'), 6),
    Case("child-node-dt", "W225", dyn('    <Node name="c" dt="0.5">\n    </Node>\n'), 6, "dt"),
    Case("loader-without-file", "E226", dyn('    <MeshOBJLoader name="loader"/>\n'), 6),
    Case(
        "unused-loader-missing-file",
        "W229",
        dyn('    <MeshOBJLoader name="loader" filename="missing.obj"/>\n'),
        6,
        "filename",
    ),
    Case(
        "anisotropic-inertia-spinning",
        "W230",
        dyn("""\
    <Node name="r">
        <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1" velocity="0 0 0 0 0 1"/>
        <UniformMass vertexMass="1 1 [1 0 0, 0 2 0, 0 0 3]"/>
    </Node>
"""),
        8,
        "vertexMass",
        hint="isotropic",
    ),
    Case(
        "anisotropic-inertia-torque-from-mapped-point",
        "W230",
        dyn(RIGID_BODY.format(mass=ANISOTROPIC, points="0 0 0  1 0 0", per_point="0 1")),
        8,
        "vertexMass",
    ),
]

# Codes tested by the dedicated tests further down (they need another entry point than check_file),
# and the Python scene codes, tested in test_pyscene.py.
# W245 (a planner warning) and E246 (its scenes also carry E222 while constraint rows are not
# compiled) are tested in test_free_motion.py; W232 (a planner warning) in test_contacts.py; W247
# (a correction without compliance) in test_lagrangian_contact.py; W234 (a planner warning) in
# test_contact_guard.py.
SPECIAL_CODES = {"E100", "E103", "E002", "E113", "E114", "W245", "E246", "W232", "W247", "W234"}

# Codes listed in CODES that no stage emits yet: no source file of the package spells them (checked
# by test_unreachable_codes_are_never_emitted, which fails as soon as one of them is used).
UNREACHABLE = {
    "W223": "ambiguous link resolution is resolved silently as SOFA does; nothing reports it yet",
    "E227": "duplicate names are accepted (SOFA renames nothing at load); nothing reports them yet",
}


def _write(tmp_path: Path, case: Case) -> Path:
    scene = tmp_path / "scenes" / "scene.scn"
    scene.parent.mkdir(parents=True)
    scene.write_text(case.scene, encoding="utf-8")
    for name, text in case.files.items():
        path = scene.parent / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return scene


def _summary(diags: Diagnostics) -> list[tuple[str, str, int, str | None]]:
    return [(d.code, Path(d.loc.file).name, d.loc.line, d.loc.attribute) for d in diags]


@pytest.mark.parametrize("case", CASES, ids=[f"{c.code}-{c.id}" for c in CASES])
def test_code_and_line(case: Case, tmp_path: Path) -> None:
    scene = _write(tmp_path, case)
    _, diags = check_file(scene)
    assert _summary(diags) == [(case.code, case.file, case.line, case.attribute)]
    diag: Diagnostic = next(iter(diags))
    assert diag.severity is CODES[case.code].severity
    assert diag.message
    assert case.hint in diag.hint
    # The line really holds what the diagnostic is about.
    lines = (scene.parent / case.file).read_text(encoding="utf-8").splitlines()
    assert 1 <= diag.loc.line <= len(lines)
    if diag.loc.attribute and case.written:
        assert f"{diag.loc.attribute}=" in lines[diag.loc.line - 1]


# Scenes that once made the checker raise or report a false error; they must check clean.
CLEAN = {
    # src= finds its object as SOFA's Node::getObject does: '../' at the root stays at the root
    # (Demos/collisionMultiple.scn writes src="@../../../Loader-floor" two levels down).
    "src-above-root": dyn("""\
    <MeshOBJLoader name="loader" filename="m.obj"/>
    <Node name="a">
        <Node name="b">
            <OglModel src="@../../../loader"/>
        </Node>
    </Node>
"""),
    # SOFA uses rigidIndexPerPoint only with one entry per mapped point, else `index` for all of
    # them (corpus: Component/SolidMechanics/Spring/JointSpringForceField.scn:35): 2 is not checked.
    "rigid-index-per-point-ignored": dyn(
        RIGID_BODY.format(mass='vertexMass="1"', points="0 0 0  1 0 0", per_point="0 2 2")
    ),
    # A rigid mass: only the mass must be > 0; a zero volume, negative off-diagonal inertia terms.
    "rigid-inertia-off-diagonal": dyn("""\
    <Node name="r">
        <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1"/>
        <UniformMass vertexMass="2 0 [1 -0.2 0, -0.2 1 0, 0 0 1]"/>
    </Node>
"""),
    # W230 only where the body can rotate: an isotropic inertia spinning, an anisotropic one that
    # only falls (gravity gives no torque), one with every DOF fixed, a 2D body (scalar inertia).
    "isotropic-inertia-spinning": dyn("""\
    <Node name="r">
        <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1" velocity="0 0 0 1 2 3"/>
        <UniformMass vertexMass="1 1 [2 0 0, 0 2 0, 0 0 2]"/>
        <ConstantForceField forces="0 0 0 1 0 0"/>
    </Node>
"""),
    "anisotropic-inertia-falling": dyn("""\
    <Node name="r">
        <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1" velocity="1 0 0 0 0 0"/>
        <UniformMass vertexMass="1 1 [1 0 0, 0 2 0, 0 0 3]"/>
    </Node>
"""),
    "anisotropic-inertia-fixed": dyn("""\
    <Node name="r">
        <MechanicalObject template="Rigid3d" position="0 0 0 0 0 0 1" velocity="0 0 0 0 0 1"/>
        <UniformMass vertexMass="1 1 [1 0 0, 0 2 0, 0 0 3]"/>
        <FixedProjectiveConstraint fixAll="true"/>
    </Node>
"""),
    "rigid2d-spinning": dyn("""\
    <Node name="r">
        <MechanicalObject template="Rigid2d" position="0 0 0" velocity="0 0 1"/>
        <UniformMass vertexMass="1 1 0.3"/>
    </Node>
"""),
    # A BoxROI without a box: nothing to evaluate, no crash.
    "boxroi-without-box": dyn(
        '    <BoxROI name="box"/>\n    <FixedProjectiveConstraint indices="@box.indices"/>\n'
    ),
}


@pytest.mark.parametrize("name", sorted(CLEAN))
def test_clean_scene(name: str, tmp_path: Path) -> None:
    scene = _write(tmp_path, Case(name, "", CLEAN[name], 0, files={"m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\n"}))
    _, diags = check_file(scene)
    assert _summary(diags) == []


def test_missing_file_is_e100_for_the_whole_file(tmp_path: Path) -> None:
    _, diags = check_file(tmp_path / "nope.scn")
    # Line 0 stands for the file as a whole: there is no line to point at.
    assert _summary(diags) == [("E100", "nope.scn", 0, None)]
    assert str(tmp_path / "nope.scn") in next(iter(diags)).message


def test_included_file_too_large_is_e103_at_the_include(tmp_path: Path) -> None:
    big = '<Node name="big">' + " " * 5000 + "</Node>\n"
    case = Case("big-include", "E103", dyn('    <include href="big.xml"/>\n'), 6, "href", {"big.xml": big})
    scene = _write(tmp_path, case)
    diags = Diagnostics()
    with pytest.raises(SceneError):
        parse_scene(scene, diags, max_bytes=2000)
    assert _summary(diags) == [("E103", "scene.scn", 6, "href")]


@pytest.mark.parametrize(
    "args",
    [
        ["check", "{tmp}/nope.scn"],  # a path that does not exist
        ["check", "{tmp}"],  # a folder with no scene in it
        ["check", "--format", "sarif", "{tmp}"],  # a bad option value
        ["check"],  # no path at all
        ["inspect"],  # no scene
        ["frobnicate"],  # no such command
    ],
)
def test_usage_error_is_e002(args: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([a.replace("{tmp}", str(tmp_path)) for a in args]) == 2
    out, err = capsys.readouterr()
    assert re.search(r"^sofac: error E002: ", err, re.MULTILINE), err
    assert out == ""


def test_allow_unsupported_turns_e222_into_a_warning(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    case = next(c for c in CASES if c.code == "E222")
    scene = _write(tmp_path, case)
    _, diags = check_file(scene, allow_unsupported=True)
    assert [(d.code, d.loc.line, d.severity) for d in diags] == [("E222", 6, Severity.WARNING)]
    assert not diags.has_errors()
    # The same through the command line: exit 1 without the option, 0 with it.
    assert main(["check", str(scene)]) == 1
    assert "error E222" in capsys.readouterr().out
    assert main(["check", "--allow-unsupported", str(scene)]) == 0
    assert "warning E222" in capsys.readouterr().out


def test_a_diagnostic_found_twice_is_reported_once() -> None:
    diagnostics = Diagnostics()
    for _ in range(3):  # one refusal reached from three places
        diagnostics.add("E222", SourceLoc("a.scn", 4), "unsupported component X at line 4: why")
    diagnostics.add("E222", SourceLoc("a.scn", 5), "unsupported component X at line 4: why")
    assert [d.loc.line for d in diagnostics] == [4, 5]


def test_every_code_is_covered() -> None:
    covered = {case.code for case in CASES} | SPECIAL_CODES
    assert covered == set(CODES) - set(UNREACHABLE)
    assert not covered & set(UNREACHABLE)


@pytest.mark.parametrize("code", sorted(UNREACHABLE))
def test_unreachable_codes_are_never_emitted(code: str) -> None:
    users = [
        str(path.relative_to(COMPILER))
        for path in COMPILER.rglob("*.py")
        if path.name != "diagnostics.py" and code in path.read_text(encoding="utf-8")
    ]
    assert users == [], f"{code} is emitted now: add a case for it to CASES and drop it from UNREACHABLE"


def test_topological_mapping_from_an_unknown_component_gives_diagnostics(tmp_path: Path) -> None:
    # A misspelled grid feeding Hexa2Tetra (found by tests/test_mutations.py): the evaluator must not
    # ask a component of unknown type for its values.
    scene = tmp_path / "misspelled.scn"
    scene.write_text(
        '<Node name="root">\n  <Node name="beam">\n    <eRgularGridTopology name="grid" n="3 3 3"/>\n'
        '    <TetrahedronSetTopologyContainer name="volume"/>\n'
        '    <Hexa2TetraTopologicalMapping input="@grid" output="@volume"/>\n  </Node>\n</Node>\n'
    )
    _, diags = check_file(scene)
    assert [(d.code, d.loc.line) for d in diags] == [("E200", 3)]
