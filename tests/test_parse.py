"""Tests for the parse stage: model building, locations, includes, macros, SOFA-tolerant XML."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest
from sofac.diagnostics import Diagnostics, SceneError
from sofac.front.model import Component, Node, Scene
from sofac.front.parse import (
    default_data_roots,
    find_data_file,
    parse_scene,
    parse_string,
    resolve_data_file,
)


@pytest.fixture(autouse=True)
def _no_env_data_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SOFAC_DATA_PATH", raising=False)


def _codes(diags: Diagnostics) -> list[str]:
    return [d.code for d in diags]


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def _parse_text(text: str, tmp_path: Path | None = None) -> tuple[Scene, Diagnostics]:
    diags = Diagnostics()
    scene = parse_string(text, diags, filename="t.scn", base_dir=tmp_path)
    return scene, diags


def _fails(text: str, tmp_path: Path | None = None) -> Diagnostics:
    diags = Diagnostics()
    with pytest.raises(SceneError):
        parse_string(text, diags, filename="t.scn", base_dir=tmp_path)
    return diags


# --- model and locations -------------------------------------------------------------------------

MULTILINE = """<?xml version="1.0"?>
<Node name="root"
      dt="0.01">
    <!-- a comment
         over two lines, with <Fake attr="x"/> inside -->
    <MechanicalObject
        name="dofs"
        position="0 0 0
                  1 1 1"
        template="Vec3d" />
    <Node name="child"><UniformMass
      totalMass="1"/></Node>
    <?some-pi data?>
    <OglModel name='single' color="1 0 0"/>
</Node>
"""


def test_element_and_attribute_lines() -> None:
    scene, diags = _parse_text(MULTILINE)
    assert list(diags) == []
    root = scene.root
    assert root.loc.line == 2 and root.loc.file == "t.scn"
    assert root.attributes["name"].loc.line == 2
    assert root.attributes["dt"].loc.line == 3
    assert root.attributes["dt"].loc.attribute == "dt"
    dofs = root.objects[0]
    assert dofs.type_name == "MechanicalObject"
    assert dofs.loc.line == 6
    assert [(a.name, a.loc.line) for a in dofs.attributes.values()] == [
        ("name", 7),
        ("position", 8),
        ("template", 10),
    ]
    child = root.child("child")
    assert child is not None and child.loc.line == 11
    mass = child.objects[0]
    assert mass.loc.line == 11
    assert mass.attributes["totalMass"].loc.line == 12
    assert root.objects[1].name == "single" and root.objects[1].loc.line == 14
    # Comments and processing instructions leave nothing behind.
    assert [o.type_name for o in root.objects] == ["MechanicalObject", "OglModel"]


def test_attribute_order_and_values_kept() -> None:
    scene, _ = _parse_text('<Node name="r" z="1" a="2" m="3"><X b="1" a="2"/></Node>')
    assert list(scene.root.attributes) == ["name", "z", "a", "m"]
    assert list(scene.root.objects[0].attributes) == ["b", "a"]
    assert scene.root.objects[0].get("a") == "2"


def test_file_name_as_given(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _write(tmp_path / "sub" / "s.scn", '<Node name="root">\n  <X/>\n</Node>\n')
    monkeypatch.chdir(tmp_path)
    diags = Diagnostics()
    scene = parse_scene(Path("sub") / "s.scn", diags)
    assert scene.root.loc.file == str(Path("sub") / "s.scn")
    assert scene.root.objects[0].loc == scene.root.objects[0].loc.__class__(str(Path("sub") / "s.scn"), 2)
    assert scene.file == Path("sub") / "s.scn"
    assert scene.sources == [(tmp_path / "sub" / "s.scn").resolve()]
    assert scene.data_roots[0] == (tmp_path / "sub").resolve()


def test_legacy_object_form() -> None:
    scene, diags = _parse_text(
        '<Node>\n<Object type="MechanicalObject" name="m" template="Rigid3d"/>\n</Node>'
    )
    assert list(diags) == []
    obj = scene.root.objects[0]
    assert isinstance(obj, Component)
    assert obj.type_name == "MechanicalObject"
    assert list(obj.attributes) == ["name", "template"]
    assert obj.loc.line == 2


def test_object_without_type_is_an_error() -> None:
    diags = _fails('<Node>\n<Object name="m"/>\n</Node>')
    assert _codes(diags) == ["E109"]
    assert next(iter(diags)).loc.line == 2


def test_attribute_data_elements() -> None:
    text = """<Node>
    <MechanicalObject template="Vec3" position="9 9 9">
        <Attribute type="name">
            <Data value="particleDOF" />
        </Attribute>
        <Attribute type="position">
            <Data
               value="0 0 0" />
        </Attribute>
        <Attribute type="velocity"><Data value="0 10 0"/></Attribute>
    </MechanicalObject>
</Node>"""
    scene, diags = _parse_text(text)
    assert list(diags) == []
    mo = scene.root.objects[0]
    assert mo.name == "particleDOF"
    # An existing attribute is replaced in place, a new one appended.
    assert list(mo.attributes) == ["template", "position", "name", "velocity"]
    assert mo.get("position") == "0 0 0"
    assert mo.attributes["position"].loc.line == 8
    assert mo.attributes["velocity"].loc.line == 10
    assert mo.attributes["name"].loc.line == 4


def test_attribute_without_type_and_ignored_children() -> None:
    diags = _fails("<Node><X><Attribute><Data value='1'/></Attribute></X></Node>")
    assert "E109" in _codes(diags)
    scene, diags = _parse_text("<Node>\n<X>\n<Y/>\n</X>\n<Data value='1'/>\n</Node>")
    assert _codes(diags) == ["W111", "W111"]
    assert [d.loc.line for d in diags] == [3, 5]
    assert [o.type_name for o in scene.root.objects] == ["X"]


def test_root_must_be_a_node() -> None:
    diags = _fails("<MechanicalObject/>")
    assert _codes(diags) == ["E112"]


def test_special_values_survive() -> None:
    text = '<Node name="a&lt;b&gt;&amp;&quot;&apos;&#10;&#x9;é漢"><X name="*/ --&gt; \\n"/></Node>'
    scene, diags = _parse_text(text)
    assert list(diags) == []
    assert scene.root.name == "a<b>&\"'\n\té漢"
    assert scene.root.objects[0].name == "*/ --> \\n"


def test_bytes_input_and_encodings() -> None:
    text = '<?xml version="1.0" encoding="ISO-8859-1"?>\n<Node name="caf\xe9"/>'
    diags = Diagnostics()
    scene = parse_string(text.encode("latin-1"), diags)
    assert scene.root.name == "café" and list(diags) == []
    scene = parse_string('<Node name="été"/>'.encode("utf-16"), diags)
    assert scene.root.name == "été"
    scene = parse_string(b'\xef\xbb\xbf<?xml version="1.0"?>\n<Node name="bom"/>', diags)
    assert scene.root.name == "bom" and scene.root.loc.line == 2


def test_large_inline_arrays_parse_fast() -> None:
    points = " ".join(f"{i * 0.001:.9f} {i * -0.002:.9f} {i * 0.003:.9f}" for i in range(10_000))
    springs = " ".join(f"{i} {i + 1} 1000.25 0.125 {1 + i * 1e-5:.9f}" for i in range(40_000))
    text = (
        '<Node name="root">\n'
        f'  <MechanicalObject name="dofs"\n     position="{points}" />\n'
        f'  <SpringForceField name="springs"\n     spring="{springs}" />\n'
        "</Node>\n"
    )
    assert len(text) > 1_800_000
    best = float("inf")
    for _ in range(3):
        diags = Diagnostics()
        start = time.perf_counter()
        scene = parse_string(text, diags)
        best = min(best, time.perf_counter() - start)
    assert best < 0.5, f"parsing {len(text)} bytes took {best:.3f} s"
    assert scene.root.objects[0].get("position") == points
    assert scene.root.objects[1].get("spring") == springs
    assert scene.root.objects[1].attributes["spring"].loc.line == 5


# --- lenient reading (what tinyxml2 accepts) ---------------------------------------------------------

NOT_WELL_FORMED = """<!-- leading comment: the declaration below is not at the start -->
<?xml version="1.0"?>
<Node name="root">
    <MergeVectors template="Data<int>" name="merge" />
    <MeshOBJLoader name="m" scale3d="10 10 10"filename="mesh/x.obj" />
    <CollisionResponse
        responseParams="mu=0.5&epsilon=10" />
    <Foo text="&unknown; &amp; &#65;"/>
</Node>
</Node>
junk
"""


def test_lenient_repairs_with_lines() -> None:
    scene, diags = _parse_text(NOT_WELL_FORMED)
    assert all(d.code == "W105" for d in diags)
    lines = [d.loc.line for d in diags]
    assert lines == [2, 4, 5, 7, 8, 10]
    messages = [d.message for d in diags]
    assert "declaration" in messages[0]
    assert "'<'" in messages[1] and "template" in messages[1]
    assert "whitespace" in messages[2] and "scale3d" in messages[2]
    assert "'&'" in messages[3] and "responseParams" in messages[3]
    assert "after the end of the root element" in messages[5] and "line 9" in messages[5]
    objs = scene.root.objects
    assert objs[0].get("template") == "Data<int>"
    assert objs[1].get("scale3d") == "10 10 10" and objs[1].get("filename") == "mesh/x.obj"
    assert objs[1].attributes["filename"].loc.line == 5
    assert objs[2].get("responseParams") == "mu=0.5&epsilon=10"
    assert objs[2].attributes["responseParams"].loc.line == 7
    # Unknown entities stay literal text, as in SOFA; known references are decoded.
    assert objs[3].get("text") == "&unknown; & A"


def test_well_formed_file_gets_no_repair_warnings() -> None:
    _, diags = _parse_text('<?xml version="1.0"?>\n<Node a="x &amp; y &lt; z"/>\n<!-- trailing -->\n')
    assert list(diags) == []


@pytest.mark.parametrize(
    ("text", "line"),
    [
        ("<Node>\n<X a='1' b>\n</Node>", 2),
        ("<Node>\n<X>\n</Node>", 3),
        ("<Node>\n\n<X a='1' a='2'/></Node>", 3),
        ("<Node><X a=1/></Node>", 1),
        ("", 1),
        ("<Node>\n<a:b/>\n</Node>", 2),
        ('<Node>\n<X"/></Node>', 2),
    ],
)
def test_unrepairable_xml_is_e101_with_line(text: str, line: int) -> None:
    diags = _fails(text)
    assert _codes(diags)[-1] == "E101"
    assert list(diags)[-1].loc.line == line


NOT_WELL_FORMED_CORPUS = {
    "Component/MechanicalLoad/EllipsoidForceField.scn": (38, "MergeVectors", "template", "Data<int>"),
    "Component/Visual/RecordedCamera.scn": (20, "MeshOBJLoader", "filename", "mesh/liver-smoothUV.obj"),
    "Demos/fallingBeamAugmentedLagrangianCollision.scn": (
        34,
        "CollisionResponse",
        "responseParams",
        "mu=0.5&epsilon=10",
    ),
}


def test_corpus_not_well_formed_scenes_load_with_w105(corpus_dir: Path) -> None:
    manifest = json.loads((corpus_dir / "manifest.json").read_text(encoding="utf-8"))
    flagged = {
        entry["scene"]
        for entry in manifest["scenes"]
        if any("not well-formed" in n for n in entry.get("notes", []))
    }
    assert flagged == set(NOT_WELL_FORMED_CORPUS)
    for rel, (line, type_name, attr, value) in NOT_WELL_FORMED_CORPUS.items():
        diags = Diagnostics()
        scene = parse_scene(corpus_dir / rel, diags)
        assert [(d.code, d.loc.line) for d in diags] == [("W105", line)], rel
        found = [c for c in scene.root.components() if c.type_name == type_name and attr in c.attributes]
        assert found and found[0].get(attr) == value, rel
        assert found[0].attributes[attr].loc.line == line


def test_every_corpus_file_parses(corpus_dir: Path) -> None:
    files = sorted(p for p in corpus_dir.rglob("*") if p.suffix in (".scn", ".xml") and p.is_file())
    assert len(files) > 150
    failures = []
    for path in files:
        diags = Diagnostics()
        try:
            parse_scene(path, diags)
        except SceneError as exc:
            failures.append(f"{path}: {exc}")
    assert failures == []


def test_corpus_components_match_manifest(corpus_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """After include/macro expansion, every scene has exactly the manifest's component types and
    pulls in exactly the manifest's .xml fragments."""
    monkeypatch.chdir(corpus_dir)
    manifest = json.loads(Path("manifest.json").read_text(encoding="utf-8"))
    for entry in manifest["scenes"]:
        scene = parse_scene(entry["scene"], Diagnostics())
        got = {c.type_name for c in scene.root.components()}
        want = {c for c in entry["components"] if not c.startswith("macro:")}
        assert got == want, entry["scene"]
        fragments = {str(p.relative_to(corpus_dir.resolve())) for p in scene.sources[1:]}
        assert fragments == {f for f in entry["files"] if f.endswith(".xml")}, entry["scene"]


# --- includes ------------------------------------------------------------------------------------


def test_fembar_include_group_spliced(corpus_dir: Path) -> None:
    path = corpus_dir / "Component/LinearSolver/Iterative/FEMBAR_CGLinearSolver.scn"
    diags = Diagnostics()
    scene = parse_scene(path, diags)
    assert list(diags) == []
    root = scene.root
    assert [c.name for c in root.children] == ["plugins"]
    types = [o.type_name for o in root.objects]
    assert types == [
        "VisualStyle",
        "DefaultAnimationLoop",
        "DefaultVisualManagerLoop",
        "EulerImplicitSolver",
        "MechanicalObject",
        "UniformMass",
        "RegularGridTopology",
        "BoxROI",
        "FixedProjectiveConstraint",
        "CGLinearSolver",
        "HexahedronFEMForceField",
    ]
    common = (corpus_dir / "Component/LinearSolver/FEMBAR-common.xml").resolve()
    ode = root.objects[3]
    assert Path(ode.loc.file).resolve() == common and ode.loc.line == 24
    assert ode.parent is root
    cg = root.objects[9]
    assert cg.loc.file == str(path) and cg.loc.line == 5
    assert scene.sources == [path.resolve(), common]
    assert scene.data_roots == [path.parent.resolve(), corpus_dir.resolve()]


def test_chain_hybrid_includes_with_overrides(corpus_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(corpus_dir)
    diags = Diagnostics()
    scene = parse_scene("Demos/chainHybrid.scn", diags)
    assert list(diags) == []
    chain = scene.root.child("Chain")
    assert chain is not None
    assert [c.name for c in chain.children] == ["Fixed", "FEM", "Spring", "FFD", "TorusRigid"]
    fem = chain.child("FEM")
    assert fem is not None
    # The include's name= renames the included root; the location is the include's attribute.
    assert fem.attributes["name"].loc.file == "Demos/chainHybrid.scn"
    assert fem.attributes["name"].loc.line == 38
    assert fem.loc.file == "Objects/TorusFEM.xml" and fem.loc.line == 1
    mo = fem.objects[4]
    assert mo.type_name == "MechanicalObject" and mo.loc.file == "Objects/TorusFEM.xml" and mo.loc.line == 6
    assert mo.get("dx") == "2.5"
    assert mo.attributes["dx"].loc.file == "Demos/chainHybrid.scn" and mo.attributes["dx"].loc.line == 38
    assert mo.get("dy") == "0" and mo.attributes["dy"].loc.file == "Objects/TorusFEM.xml"
    surf = fem.child("Surf2")
    assert surf is not None and surf.objects[2].get("dx") == "2.5"
    spring = chain.child("Spring")
    assert spring is not None
    assert [o.get("rx") for o in spring.objects if o.type_name == "MechanicalObject"] == ["90"]
    # Overrides only replace attributes already present: FFD's collision MechanicalObject has no dx.
    ffd = chain.child("FFD")
    assert ffd is not None and ffd.child("Surf2") is not None
    assert "dx" not in ffd.child("Surf2").objects[3].attributes  # type: ignore[union-attr]


def test_node_name_restricted_override(corpus_dir: Path) -> None:
    scene = parse_scene(corpus_dir / "Benchmark/Analysis/constantMomentum.scn", Diagnostics())
    springs = [c for c in scene.root.components() if c.type_name == "SpringForceField"]
    assert "InternalSprings1" in [s.name for s in springs]
    assert "InternalSprings" not in [s.name for s in springs]


def test_include_override_semantics(tmp_path: Path) -> None:
    _write(
        tmp_path / "part.xml",
        """<Node name="Part">
  <MechanicalObject name="a" dx="0" />
  <Node name="inner">
    <MechanicalObject name="b" dx="0" dy="0"/>
    <UniformMass name="b" totalMass="1"/>
  </Node>
</Node>""",
    )
    text = """<Node name="root">
  <include href="part.xml" name="P1" dx="5"
           b__dy="7" missing="1" b__nothere="2" c__dx="3"/>
</Node>"""
    scene, diags = _parse_text(text, tmp_path)
    p1 = scene.root.child("P1")
    assert p1 is not None
    assert p1.objects[0].get("dx") == "5"
    inner = p1.child("inner")
    assert inner is not None
    assert inner.objects[0].get("dx") == "5" and inner.objects[0].get("dy") == "7"
    assert inner.objects[0].attributes["dy"].loc == inner.objects[0].attributes["dy"].loc.__class__(
        "t.scn", 3, "dy"
    )
    assert "dx" not in inner.objects[1].attributes  # not added where absent
    w110 = [d for d in diags if d.code == "W110"]
    assert [(d.loc.line, d.loc.attribute) for d in w110] == [(3, "missing"), (3, "b__nothere"), (3, "c__dx")]
    assert _codes(diags) == ["W110", "W110", "W110"]


def test_include_group_merge_and_component_root(tmp_path: Path) -> None:
    _write(tmp_path / "group.xml", '<Node name="_Group_"><A name="a"/><Node name="n"/></Node>')
    _write(
        tmp_path / "merge.xml",
        '<Node name="_Merge_" dt="0.5"><Node name="body"><B name="x" k="2"/><C/></Node><D/></Node>',
    )
    _write(tmp_path / "comp.xml", '<MechanicalObject name="m" dx="1"/>')
    text = """<Node name="root" dt="0.1">
  <Node name="body"><B name="x" k="1" j="0"/></Node>
  <include href="group.xml"/>
  <include href="merge.xml"/>
  <include href="comp.xml" name="renamed" dx="3"/>
</Node>"""
    scene, diags = _parse_text(text, tmp_path)
    assert list(diags) == []
    root = scene.root
    assert root.get("dt") == "0.5"
    assert [c.name for c in root.children] == ["body", "n"]
    body = root.child("body")
    assert body is not None
    assert [(o.type_name, o.get("k"), o.get("j")) for o in body.objects] == [
        ("B", "2", "0"),
        ("C", None, None),
    ]
    assert [o.type_name for o in root.objects] == ["A", "D", "MechanicalObject"]
    assert root.objects[2].name == "renamed" and root.objects[2].get("dx") == "3"


def test_include_search_order_and_data_roots(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _write(tmp_path / "scenes" / "sub" / "a.xml", '<Node name="Group"><Local/></Node>')
    _write(tmp_path / "lib1" / "sub" / "a.xml", '<Node name="Group"><FromLib1/></Node>')
    _write(tmp_path / "lib1" / "b.xml", '<Node name="Group"><include href="c.xml"/></Node>')
    _write(tmp_path / "lib1" / "c.xml", '<Node name="Group"><NestedSibling/></Node>')
    _write(tmp_path / "lib2" / "d.xml", '<Node name="Group"><FromEnv/></Node>')
    scene_path = _write(
        tmp_path / "scenes" / "s.scn",
        '<Node><include href="sub/a.xml"/><include href="b.xml"/><include href="d.xml"/></Node>',
    )
    monkeypatch.setenv("SOFAC_DATA_PATH", str(tmp_path / "lib2"))
    diags = Diagnostics()
    scene = parse_scene(scene_path, diags, data_roots=[tmp_path / "lib1"])
    assert list(diags) == []
    assert [o.type_name for o in scene.root.objects] == ["Local", "NestedSibling", "FromEnv"]
    assert scene.data_roots[:3] == [(tmp_path / d).resolve() for d in ("scenes", "lib1", "lib2")]


def test_missing_include_names_href_and_dirs(tmp_path: Path) -> None:
    diags = _fails('<Node>\n  <include href="nope.xml"/>\n  <include/>\n</Node>', tmp_path)
    assert _codes(diags) == ["E106", "E109"]
    e106 = next(iter(diags))
    assert e106.loc.line == 2 and e106.loc.attribute == "href"
    assert "nope.xml" in e106.message and str(tmp_path.resolve()) in e106.message


def test_errors_in_included_file_are_located(tmp_path: Path) -> None:
    _write(tmp_path / "bad.xml", '<Node name="Group">\n\n  <X a="1" a="2"/>\n</Node>')
    _write(tmp_path / "repaired.xml", '<Node name="Group">\n  <X t="Data<int>"/>\n</Node>')
    diags = _fails('<Node>\n<include href="bad.xml"/>\n<include href="repaired.xml"/>\n</Node>', tmp_path)
    found = [(d.code, d.loc.file, d.loc.line) for d in diags]
    assert ("E101", "bad.xml", 3) in [(c, Path(f).name, n) for c, f, n in found]
    assert ("W105", "repaired.xml", 2) in [(c, Path(f).name, n) for c, f, n in found]


def test_diamond_include_is_not_a_cycle(tmp_path: Path) -> None:
    _write(tmp_path / "leaf.xml", '<Node name="Group"><Leaf/></Node>')
    _write(
        tmp_path / "mid.xml", '<Node name="Group"><include href="leaf.xml"/><include href="leaf.xml"/></Node>'
    )
    scene, diags = _parse_text('<Node><include href="mid.xml"/><include href="leaf.xml"/></Node>', tmp_path)
    assert list(diags) == []
    assert [o.type_name for o in scene.root.objects] == ["Leaf", "Leaf", "Leaf"]


# --- macros --------------------------------------------------------------------------------------


def test_box_constraint_macro(corpus_dir: Path) -> None:
    path = corpus_dir / "Component/Constraint/Projective/BoxConstraint.scn"
    diags = Diagnostics()
    scene = parse_scene(path, diags)
    assert list(diags) == []
    liver = scene.root.child("Liver")
    assert liver is not None
    types = [o.type_name for o in liver.objects]
    assert "BoxConstraint" not in types
    i = types.index("BoxROI")
    assert types[i + 1] == "FixedProjectiveConstraint"
    box, fixed = liver.objects[i], liver.objects[i + 1]
    macro_file = (corpus_dir / "Objects/BoxConstraint.xml").resolve()
    assert Path(box.loc.file).resolve() == macro_file and box.loc.line == 2
    assert box.get("box") == "-5 0 -1 -2 1 2"
    assert box.attributes["box"].loc.file == str(path) and box.attributes["box"].loc.line == 34
    assert box.get("drawBoxes") == "0"
    assert fixed.get("indices") == "@[-1].indices" and fixed.loc.line == 3
    assert macro_file in scene.sources


def test_macro_from_data_root_and_object_form(tmp_path: Path) -> None:
    _write(tmp_path / "lib" / "Objects" / "MyMacro.xml", '<Node name="Group"><Inner k="0"/><Other/></Node>')
    text = '<Node>\n<MyMacro k="4"/>\n<Object type="MyMacro" k="5"/>\n<NoSuchMacro k="1"/>\n</Node>'
    diags = Diagnostics()
    scene = parse_string(text, diags, base_dir=tmp_path, data_roots=[tmp_path / "lib"])
    assert list(diags) == []
    assert [(o.type_name, o.get("k")) for o in scene.root.objects] == [
        ("Inner", "4"),
        ("Other", None),
        ("Inner", "5"),
        ("Other", None),
        ("NoSuchMacro", "1"),
    ]


def test_known_component_is_never_a_macro(tmp_path: Path) -> None:
    _write(tmp_path / "Objects" / "MechanicalObject.xml", '<Node name="Group"><Hijacked/></Node>')
    scene, _ = _parse_text('<Node><MechanicalObject name="m"/></Node>', tmp_path)
    assert [o.type_name for o in scene.root.objects] == ["MechanicalObject"]


# --- data files ----------------------------------------------------------------------------------


def test_resolve_data_file(tmp_path: Path) -> None:
    _write(tmp_path / "scene" / "mesh" / "a.obj", "v 0 0 0\n")
    _write(tmp_path / "root" / "mesh" / "b.obj", "v 0 0 0\n")
    _write(tmp_path / "outside" / "secret.obj", "v 0 0 0\n")
    (tmp_path / "scene" / "link.obj").symlink_to(tmp_path / "outside" / "secret.obj")
    (tmp_path / "scene" / "inlink.obj").symlink_to(tmp_path / "scene" / "mesh" / "a.obj")
    roots = default_data_roots(tmp_path / "scene", [tmp_path / "root"])
    scene = Scene(Node("root"), data_roots=roots)
    base = tmp_path / "scene"
    assert resolve_data_file("mesh/a.obj", base, scene) == (base / "mesh" / "a.obj").resolve()
    assert resolve_data_file("mesh/b.obj", base, scene) == (tmp_path / "root" / "mesh" / "b.obj").resolve()
    assert resolve_data_file("inlink.obj", base, scene) == (base / "mesh" / "a.obj").resolve()
    assert resolve_data_file("mesh/none.obj", base, scene) is None
    for bad in ("../outside/secret.obj", str(tmp_path / "outside" / "secret.obj"), "link.obj", "/etc/passwd"):
        assert resolve_data_file(bad, base, scene) is None, bad
        assert find_data_file(bad, base, scene).refused, bad
    assert not find_data_file("mesh/none.obj", base, scene).refused
    assert resolve_data_file("", base, scene) is None
    assert resolve_data_file("a\0b", base, scene) is None


def test_auto_detected_data_root(tmp_path: Path) -> None:
    (tmp_path / "tree" / "mesh").mkdir(parents=True)
    (tmp_path / "tree" / "A" / "B").mkdir(parents=True)
    roots = default_data_roots(tmp_path / "tree" / "A" / "B")
    assert roots == [(tmp_path / "tree" / "A" / "B").resolve(), (tmp_path / "tree").resolve()]


def test_relative_paths_with_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SOFAC_DATA_PATH", os.pathsep.join(["", str(tmp_path / "missing"), str(tmp_path)]))
    roots = default_data_roots(tmp_path / "x")
    assert roots == [tmp_path.resolve()]


def test_cr_and_crlf_line_ends() -> None:
    for newline in ("\r", "\r\n"):
        text = newline.join(['<Node name="r"', '  dt="1">', "<X", ' a="1"/>', "</Node>"])
        scene, diags = _parse_text(text)
        assert list(diags) == []
        assert scene.root.attributes["dt"].loc.line == 2
        assert scene.root.objects[0].loc.line == 3
        assert scene.root.objects[0].attributes["a"].loc.line == 4


def test_symlinked_scene_resolves_from_its_given_folder(tmp_path: Path) -> None:
    _write(tmp_path / "real" / "s.scn", '<Node><include href="part.xml"/></Node>')
    _write(tmp_path / "work" / "part.xml", '<Node name="Group"><Here/></Node>')
    (tmp_path / "work" / "s.scn").symlink_to(tmp_path / "real" / "s.scn")
    scene = parse_scene(tmp_path / "work" / "s.scn", Diagnostics())
    assert [o.type_name for o in scene.root.objects] == ["Here"]
