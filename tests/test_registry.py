"""Tests for the component registry: coverage of the SOFA corpus, names, fields and defaults."""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from manifest_updates import IMPLEMENTED_SINCE_MANIFEST, SUPPORTED_SINCE_MANIFEST
from sofac import registry
from sofac.registry import Category, NameStatus
from sofac.registry.fields import FieldValueError, Link
from sofac.registry.spec import BASE_FIELDS, ComponentSpec


def _shared() -> Path | None:
    candidates = [Path(__file__).resolve().parents[2] / "shared"]
    if os.environ.get("SOFAC_SHARED"):
        candidates.append(Path(os.environ["SOFAC_SHARED"]))
    for candidate in candidates:
        if (candidate / "corpus" / "sofa").is_dir():
            return candidate
    return None


SHARED = _shared()
CORPUS = SHARED / "corpus" / "sofa" if SHARED else None
REGRESSION_LIST = SHARED / "reference" / "sofa-regression" / "scenes.regression-tests" if SHARED else None
needs_corpus = pytest.mark.skipif(CORPUS is None, reason="shared SOFA corpus not available")

# Element names that are not component classes.
STRUCTURAL_TAGS = frozenset({"Node", "include", "Attribute", "Data", "Object"})
# Attributes the XML reader handles itself (never Data of the component).
RESERVED_ATTRIBUTES = frozenset({"template", "src", "type"})

# Attributes written in supported corpus scenes that SOFA itself does not consume: it reports them as
# "Unused Attribute", so the registry deliberately leaves them out (sofac's checker warns the same way).
SOFA_IGNORED_ATTRIBUTES: dict[str, frozenset[str]] = {
    # d_maxIter / d_smallDenominatorThreshold are C++ member names; the Data are iterations/threshold.
    "CGLinearSolver": frozenset({"maxIter", "smallDenominatorThreshold"}),
    # TetrahedronFEMForceField has no index subset Data.
    "TetrahedronFEMForceField": frozenset({"indices"}),
    # FrictionContact.scn writes multi_grid, which SOFA's LCPConstraintSolver no longer declares.
    "LCPConstraintSolver": frozenset({"multi_grid"}),
}

_COMMENT = re.compile(r"<!--.*?-->", re.S)
_TAG = re.compile(r"<\s*([A-Za-z_][\w.:-]*)([^>]*?)/?>", re.S)
_ATTRIBUTE = re.compile(r"([A-Za-z_][\w.:-]*)\s*=\s*(\"[^\"]*\"|'[^']*')")


def _elements(path: Path) -> Iterator[tuple[str, dict[str, str]]]:
    """(class name, attributes) of every component element of a scene file (a simple tag scan)."""
    text = _COMMENT.sub("", path.read_text(errors="replace"))
    for match in _TAG.finditer(text):
        tag = match.group(1)
        attributes = {name: value[1:-1] for name, value in _ATTRIBUTE.findall(match.group(2))}
        if tag == "Object":
            tag = attributes.get("type", "Object")
        yield tag, attributes


def _macros() -> frozenset[str]:
    assert CORPUS is not None
    return frozenset(p.stem for p in (CORPUS / "Objects").glob("*.xml"))


def _scene_files() -> list[Path]:
    assert CORPUS is not None
    return sorted(p for p in CORPUS.rglob("*") if p.suffix in (".scn", ".xml") and p.is_file())


def _regression_scenes() -> list[Path]:
    assert CORPUS is not None and REGRESSION_LIST is not None
    scenes = []
    for line in REGRESSION_LIST.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith(("#", "$")):
            scenes.append(CORPUS / line.split()[0])
    return scenes


def _manifest() -> list[dict[str, Any]]:
    assert CORPUS is not None
    return json.loads((CORPUS / "manifest.json").read_text())["scenes"]


def _component_names(paths: list[Path]) -> set[str]:
    macros = _macros()
    return {
        tag
        for path in paths
        for tag, _ in _elements(path)
        if tag not in STRUCTURAL_TAGS and tag not in macros
    }


def _supported_scene_files() -> list[Path]:
    """Accepted corpus scenes plus the XML fragments they include."""
    assert CORPUS is not None
    files: set[Path] = set()
    for entry in _manifest():
        if entry["status"] != "supported":
            continue
        files.add(CORPUS / entry["scene"])
        files.update(CORPUS / f for f in entry["files"] if f.endswith(".xml"))
    return sorted(files)


def _unknown_attributes(paths: list[Path], only_supported: bool) -> list[str]:
    macros = _macros()
    problems = []
    for path in paths:
        for tag, attributes in _elements(path):
            if tag in STRUCTURAL_TAGS or tag in macros:
                continue
            resolution = registry.lookup(tag)
            assert resolution is not None, tag
            spec = resolution.spec
            if only_supported and not spec.supported:
                continue
            ignored = SOFA_IGNORED_ATTRIBUTES.get(spec.name, frozenset())
            for name in attributes:
                if name in RESERVED_ATTRIBUTES or name.startswith(("_", "NO")) or name in ignored:
                    continue
                if spec.field(name) is None:
                    problems.append(f"{path.relative_to(CORPUS)}: <{tag} {name}=...>")  # type: ignore[arg-type]
    return sorted(set(problems))


# --- coverage of the corpus ------------------------------------------------------------------


@needs_corpus
def test_every_corpus_component_resolves() -> None:
    names = _component_names(_scene_files())
    assert len(names) > 150
    missing = sorted(n for n in names if registry.lookup(n) is None)
    assert not missing, f"components used in the corpus but not registered: {missing}"


@needs_corpus
def test_every_regression_component_resolves() -> None:
    scenes = _regression_scenes()
    assert len(scenes) == 87 and all(p.is_file() for p in scenes)
    missing = sorted(n for n in _component_names(scenes) if registry.lookup(n) is None)
    assert not missing, f"components used in regression scenes but not registered: {missing}"


@needs_corpus
def test_macros_are_not_components() -> None:
    for macro in ("BoxConstraint", "CGImplicit", "CGImplicitSolver"):
        assert registry.lookup(macro) is None
    assert "BoxConstraint" in _macros()


@needs_corpus
def test_supported_flags_follow_the_manifest() -> None:
    manifest = _manifest()
    accepted = {c for e in manifest if e["status"] == "supported" for c in e["components"]}
    accepted.discard("macro:BoxConstraint")
    unsupported = sorted(n for n in accepted if not registry.lookup(n).spec.supported)  # type: ignore[union-attr]
    assert not unsupported, f"used by accepted scenes but marked unsupported: {unsupported}"
    # The negative scenes name their offending components in "expected"; those must be unsupported
    # (three scenes are rejected only because their XML is malformed).
    for entry in manifest:
        if entry["status"] != "negative" or any("not well-formed" in n for n in entry["notes"]):
            continue
        if entry["scene"] in IMPLEMENTED_SINCE_MANIFEST:
            assert registry.lookup(IMPLEMENTED_SINCE_MANIFEST[entry["scene"]]).spec.supported  # type: ignore[union-attr]
            continue
        offending = [c for c in entry["components"] if c not in accepted and not c.startswith("macro:")]
        assert offending, entry["scene"]
        for name in offending:
            spec = registry.lookup(name).spec  # type: ignore[union-attr]
            if spec.category is registry.Category.RENDERING:
                continue  # lights and cameras are accepted since the manifest (issue 19)
            if spec.name in SUPPORTED_SINCE_MANIFEST:
                continue
            assert not spec.supported, f"{name} ({entry['scene']}) should be unsupported"


@needs_corpus
def test_attributes_of_supported_scenes_are_known_fields() -> None:
    problems = _unknown_attributes(_supported_scene_files(), only_supported=False)
    assert not problems, "attributes with no field:\n" + "\n".join(problems)


@needs_corpus
def test_attributes_of_supported_components_in_regression_scenes_are_known() -> None:
    problems = _unknown_attributes(_regression_scenes(), only_supported=True)
    assert not problems, "attributes with no field:\n" + "\n".join(problems)


@needs_corpus
def test_templates_written_in_the_corpus_are_registered() -> None:
    from sofac.registry.components.common import MATRIX_TEMPLATE_ALIASES

    macros = _macros()
    problems = set()
    for path in _scene_files():
        for tag, attributes in _elements(path):
            text = attributes.get("template", "").strip()
            if not text or tag in STRUCTURAL_TAGS or tag in macros:
                continue
            spec = registry.lookup(tag).spec  # type: ignore[union-attr]
            parts = []
            for part in registry.split_template(text):
                canonical = registry.canonical_datatype(part)
                parts.append(canonical[0] if canonical else MATRIX_TEMPLATE_ALIASES.get(part, part))
            # As SOFA's factory: the full template, or (one-template forms) its first argument.
            if spec.templates and ",".join(parts) not in spec.templates and parts[0] not in spec.templates:
                problems.add(f"{path.relative_to(CORPUS)}: <{tag} template={text!r}>")  # type: ignore[arg-type]
    assert not problems, "templates not registered:\n" + "\n".join(sorted(problems))


# --- names ---------------------------------------------------------------------------------------


def test_registry_loads_without_duplicate_names() -> None:
    components = registry.all_components()
    assert "Node" in components and "MechanicalObject" in components
    assert len(components) > 160


@pytest.mark.parametrize(
    ("old", "new", "status"),
    [
        ("EulerSolver", "EulerExplicitSolver", NameStatus.FORMER),
        ("ExplicitEulerSolver", "EulerExplicitSolver", NameStatus.FORMER),
        ("MeshObjLoader", "MeshOBJLoader", NameStatus.FORMER),
        ("SphereModel", "SphereCollisionModel", NameStatus.FORMER),
        ("TriangleModel", "TriangleCollisionModel", NameStatus.FORMER),
        ("LineModel", "LineCollisionModel", NameStatus.FORMER),
        ("PointModel", "PointCollisionModel", NameStatus.FORMER),
        ("ImplicitEulerSolver", "EulerImplicitSolver", NameStatus.FORMER),
        ("CGSolver", "CGLinearSolver", NameStatus.FORMER),
        ("RungeKutta4", "RungeKutta4Solver", NameStatus.FORMER),
        ("DefaultPipeline", "CollisionPipeline", NameStatus.FORMER),
        ("DefaultContactManager", "CollisionResponse", NameStatus.FORMER),
        ("Mesh", "MeshTopology", NameStatus.FORMER),
        ("RegularGrid", "RegularGridTopology", NameStatus.FORMER),
        ("SurfaceIdentityMapping", "SubsetMapping", NameStatus.FORMER),
        ("Background", "BackgroundSetting", NameStatus.FORMER),
        ("RigidRigidMapping", "RigidMapping", NameStatus.FORMER),
        ("GenericConstraintSolver", "BlockGaussSeidelConstraintSolver", NameStatus.FORMER),
        ("FixedConstraint", "FixedProjectiveConstraint", NameStatus.RENAMED),
        ("PartialFixedConstraint", "PartialFixedProjectiveConstraint", NameStatus.RENAMED),
        ("StiffSpringForceField", "SpringForceField", NameStatus.RENAMED),
        ("ShewchukPCGLinearSolver", "PCGLinearSolver", NameStatus.RENAMED),
        ("ProjectToLineConstraint", "LineProjectiveConstraint", NameStatus.RENAMED),
        ("VisualModel", "VisualModelImpl", NameStatus.ALIAS),
    ],
)
def test_legacy_names(old: str, new: str, status: NameStatus) -> None:
    resolution = registry.lookup(old)
    assert resolution is not None, old
    assert resolution.spec.name == new
    assert resolution.status is status


def test_suggestions_skip_former_names() -> None:
    assert registry.suggest("MechanicalObjekt") == ["MechanicalObject"]
    assert "EulerSolver" not in registry.suggest("EulerSolve")


# --- specs are well formed -------------------------------------------------------------------------

SPECS = sorted(registry.all_components().values(), key=lambda s: s.name)
FIELDS = [(spec, field) for spec in SPECS for field in spec.fields]


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    return bool(a == b)


@pytest.mark.parametrize(("spec", "field"), FIELDS, ids=[f"{s.name}.{f.name}" for s, f in FIELDS])
def test_default_round_trips(spec: ComponentSpec, field: registry.FieldSpec) -> None:
    if field.default is None:
        return
    text = field.type.format(field.default)
    try:
        value = field.type.parse(text)
    except FieldValueError as error:
        pytest.fail(f"default {field.default!r} of {spec.name}.{field.name} does not parse: {error}")
    if isinstance(field.default, (str, int, float, bool)):
        assert value == field.default
    else:
        assert _same(value, field.default)
    if field.valid is not None and not isinstance(field.type, Link):
        predicate, phrase = field.valid
        numbers = np.atleast_1d(np.asarray(value, dtype=float))
        assert all(predicate(float(x)) for x in numbers), f"default of {spec.name}.{field.name} {phrase}"


@pytest.mark.parametrize("spec", SPECS, ids=[s.name for s in SPECS])
def test_spec_is_consistent(spec: ComponentSpec) -> None:
    names = [key for field in spec.fields for key in (field.name, *field.aliases)]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    assert not duplicates, f"{spec.name}: attribute names claimed twice: {duplicates}"
    base = {key for field in BASE_FIELDS for key in (field.name, *field.aliases)}
    assert not base & set(names), f"{spec.name} redefines base Data {sorted(base & set(names))}"
    known = set(spec.field_names)
    for field in spec.fields:
        assert set(field.sets) <= known, f"{spec.name}.{field.name} sets unknown fields {field.sets}"
        assert field.indexes in (None, "state", "input", "output", "object1", "object2")
    if spec.name != "Node":
        assert spec.module, f"{spec.name} has no module"
    if spec.templates:
        assert spec.default_template in spec.templates, spec.name
    else:
        assert spec.default_template is None, spec.name
    if not spec.supported:
        assert spec.unsupported_reason, f"{spec.name} is unsupported without a reason"
    if spec.needs_linear_solver:
        assert spec.category is Category.ODE_SOLVER
    if spec.compute:
        from sofac.check import evaluate

        assert spec.compute in evaluate.EVALUATORS, f"{spec.name}: no evaluator {spec.compute!r}"


def test_physical_checks() -> None:
    def check(component: str, field: str, text: str) -> bool:
        spec = registry.lookup(component).spec  # type: ignore[union-attr]
        field_spec = spec.field(field)
        assert field_spec is not None and field_spec.valid is not None
        predicate, _ = field_spec.valid
        return all(predicate(float(x)) for x in np.atleast_1d(field_spec.type.parse(text)))

    assert check("TetrahedronFEMForceField", "poissonRatio", "0.3")
    assert not check("TetrahedronFEMForceField", "poissonRatio", "0.5")
    assert not check("TetrahedronFEMForceField", "poissonRatio", "-1")
    assert not check("TetrahedronFEMForceField", "youngModulus", "0")
    assert not check("UniformMass", "totalMass", "-2")
    assert not check("RegularGridTopology", "n", "0 2 2")
    assert check("CGLinearSolver", "iterations", "1")


def test_core_defaults_match_sofa() -> None:
    def default(component: str, field: str) -> Any:
        spec = registry.lookup(component).spec  # type: ignore[union-attr]
        field_spec = spec.field(field)
        assert field_spec is not None, f"{component}.{field}"
        return field_spec.default

    assert default("EulerImplicitSolver", "rayleighStiffness") == 0.0
    assert default("EulerImplicitSolver", "rayleighMass") == 0.0
    assert default("EulerExplicitSolver", "symplectic") is True
    assert default("CGLinearSolver", "iterations") == 25
    assert default("CGLinearSolver", "tolerance") == 1e-5
    assert default("TetrahedronFEMForceField", "method") == "large"
    assert default("TetrahedronFEMForceField", "youngModulus") == (5000.0,)
    assert default("TetrahedronFEMForceField", "poissonRatio") == (0.45,)
    assert default("SpringForceField", "stiffness") == (100.0,)
    assert default("RegularGridTopology", "n") == (2, 2, 2)
    assert default("PlaneForceField", "stiffness") == 500.0
    assert default("SphereCollisionModel", "contactStiffness") == 10.0
    assert default("MinProximityIntersection", "alarmDistance") == 1.0
    assert default("NewmarkImplicitSolver", "beta") == 0.25
    assert default("Gravity", "gravity") == (0.0, 0.0, 0.0)
    assert default("UniformMass", "vertexMass") is None  # one of vertexMass/totalMass is required


def test_umbrella_attributes() -> None:
    spec = registry.lookup("MeshSpringForceField").spec  # type: ignore[union-attr]
    stiffness = spec.field("stiffness")
    assert stiffness is not None
    assert set(stiffness.sets) == {
        f"{k}Stiffness" for k in ("lines", "triangles", "quads", "tetrahedra", "cubes")
    }
    assert spec.field("tetrasStiffness") is spec.field("tetrahedraStiffness")
    mapping = registry.lookup("BarycentricMapping").spec  # type: ignore[union-attr]
    assert mapping.field("isMechanical").sets == ("mapForces", "mapConstraints", "mapMasses")  # type: ignore[union-attr]


def test_implicit_solvers_need_a_linear_solver() -> None:
    implicit = {s.name for s in SPECS if s.needs_linear_solver}
    assert {
        "EulerImplicitSolver",
        "NewmarkImplicitSolver",
        "StaticSolver",
        "VariationalSymplecticSolver",
    } <= implicit
    assert not {"EulerExplicitSolver", "RungeKutta2Solver", "RungeKutta4Solver"} & implicit
