"""The plan is data: no C++ text and no callables anywhere in it, and it dumps as JSON
(``sofac inspect --plan-json``). Code generation alone spells calls out."""

from __future__ import annotations

import dataclasses
import enum
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sofac import pipeline
from sofac.check.checker import CheckedComponent
from sofac.cli.main import main
from sofac.codegen.cpp import statement
from sofac.front.model import Component, Node
from sofac.plan.ir import (
    CHILD,
    PARENT,
    Aggregate,
    Buffer,
    Count,
    Env,
    Offset,
    SpringDamping,
    SpringFlags,
    as_json,
    bind,
    buffers_of,
    call,
    kernel,
    recorded_once,
)
from sofac.registry.datatypes import DataType

REPO = Path(__file__).resolve().parents[1]
BUNDLED = sorted((REPO / "scenes").glob("*.scn"))
# Corpus scenes that between them lower mappings (rigid, barycentric, subset, distance, multi),
# projections of every kind, springs, FEM, masses, direct solvers and assembled systems.
CORPUS = [
    "Demos/mixedPendulum.scn",
    "Demos/simpleSphere.scn",
    "Demos/simpleBoundaryConditions.scn",
    "Benchmark/Analysis/Pendulum.scn",
    "Component/Mapping/NonLinear/DistanceMapping.scn",
    "Component/Mapping/NonLinear/DistanceMultiMapping.scn",
    "Component/Mapping/NonLinear/SquareDistanceMapping.scn",
    "Component/MechanicalLoad/InteractionEllipsoidForceField.scn",
    "Component/LinearSolver/Direct/FEMBAR_SparseLDLSolver.scn",
    "Component/LinearSystem/CompositeLinearSystem.scn",
    "Component/Mass/MeshMatrixMass.scn",
]

# What C++ looks like in a string: scopes, member access on the instance, statements, lambdas.
CPP = re.compile(r"sofac::|\bS\.\w|;|\bdata\(\)|\[&\]|->|\bIndex\(|\bA\.recording")


def _plans(corpus_dir: Path | None) -> list[tuple[str, Any]]:
    paths = list(BUNDLED)
    if corpus_dir is not None:
        paths += [corpus_dir / name for name in CORPUS if (corpus_dir / name).is_file()]
    return [(p.name, pipeline.plan_file(p)) for p in paths]


@pytest.fixture(scope="module")
def plans(request: pytest.FixtureRequest) -> list[tuple[str, Any]]:
    from conftest import find_shared

    shared = find_shared()
    return _plans(shared / "corpus" / "sofa" if shared else None)


def _walk(value: Any, seen: set[int], where: str) -> list[str]:
    """Paths of the callables and C++-looking strings inside a plan value."""
    scene = (Component, Node, CheckedComponent, DataType)  # references into the checked scene
    if id(value) in seen or isinstance(value, (*scene, np.ndarray, enum.Enum, type)):
        return []
    seen.add(id(value))
    if isinstance(value, str):
        return [f"{where}: {value!r}"] if CPP.search(value) else []
    if callable(value):
        return [f"{where}: callable {value!r}"]
    if dataclasses.is_dataclass(value):
        return [
            bad
            for f in dataclasses.fields(value)
            for bad in _walk(getattr(value, f.name), seen, f"{where}.{f.name}")
        ]
    if isinstance(value, dict):
        return [bad for k, v in value.items() for bad in _walk(v, seen, f"{where}[{k!r}]")]
    if isinstance(value, (list, tuple, set, frozenset)):
        return [bad for i, v in enumerate(value) for bad in _walk(v, seen, f"{where}[{i}]")]
    return []


def test_the_plan_holds_no_cpp_and_no_callables(plans: list[tuple[str, Any]]) -> None:
    assert len(plans) >= len(BUNDLED)
    for name, plan in plans:
        assert _walk(plan, set(), name) == []
        dump = json.dumps(as_json(plan))
        assert not CPP.search(dump), (name, CPP.search(dump))


def test_every_call_of_a_plan_generates(plans: list[tuple[str, Any]]) -> None:
    """Calls become statements naming their kernel; the C++ is all in code generation."""
    for name, plan in plans:
        calls = [
            c for g in plan.groups for phase in (g.forces, g.energy, g.init) for op in phase for c in op.calls
        ]
        assert calls, name
        for item in calls:
            text = statement(item)
            assert text.startswith(("sofac::", "kinetic += sofac::", "potential += sofac::")), text
            assert f"::{item.kernel}" in text and text.endswith(";")


def test_plan_json_from_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["inspect", str(REPO / "scenes" / "liver.scn"), "--plan-json"]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert plan["type"] == "Plan" and plan["dt"]["key"] == "/.dt"
    (group,) = plan["groups"]
    kernels = {c["kernel"] for op in group["forces"] for c in op["calls"]}
    assert {"tetra_fem_add_force", "mass_gravity"} <= kernels
    fem = next(op for op in group["forces"] if "TetrahedronFEMForceField" in op["origin"])
    (force,) = fem["calls"]
    assert force["args"][2] == {
        "buffer": group["states"][0]["x"]["buffer"],
        "key": "/Liver/dofs.position",
        "kind": "f64",
        "role": "state",
    }


def _buffer(ident: str) -> Buffer:
    return Buffer(ident, f"/x.{ident}", "f64", np.zeros(3))


def test_calls_are_spelled_out_only_by_codegen() -> None:
    x, y, table = _buffer("b1_x"), _buffer("b2_y"), _buffer("b3_t")
    springs = Aggregate("Springs", (table, Count(table, 2), 4))
    variant = (SpringDamping.DAMPED, SpringFlags.NONE)
    item = call(kernel("spring_forces", "Vec3d", "Rigid3d", *variant), springs, x, y, Env.NONE)
    assert buffers_of([item]) == {"b1_x", "b2_y", "b3_t"}
    assert statement(item) == (
        "sofac::spring_forces<sofac::Vec3d, sofac::Rigid3d, sofac::SpringDamping::Damped, "
        "sofac::SpringFlags::None>("
        "sofac::Springs{S.b3_t.data(), Index(S.b3_t.size() / 2), 4}, S.b1_x.data(), S.b2_y.data(), nullptr);"
    )
    energy = call("example_energy", x, np.float64(0.5), np.int64(3), into=Env.POTENTIAL)
    assert statement(energy) == "potential += sofac::example_energy(S.b1_x.data(), 0.5, 3);"
    # A number passed to a runtime kernel is labelled with the header's parameter name.
    weight = call(kernel("mass_gravity", "Vec3d"), x, 2, y, 0, table)
    assert statement(weight) == (
        "sofac::mass_gravity<sofac::Vec3d>(S.b1_x.data(), /*n=*/2, S.b2_y.data(), /*mass_stride=*/0, "
        "S.b3_t.data());"
    )
    mapping = call("rigid_apply_j", PARENT, CHILD, table, 7)
    with pytest.raises(TypeError, match="unbound"):
        statement(mapping)
    assert (
        statement(bind(mapping, {PARENT: x, CHILD: y}))
        == "sofac::rigid_apply_j(S.b1_x.data(), S.b2_y.data(), S.b3_t.data(), 7);"
    )
    rows = recorded_once(call("subset_jacobian", Env.ASSEMBLER, Offset(6, mapped=True), Offset(0), table))
    assert statement(rows) == (
        "if (A.recording()) sofac::subset_jacobian(A, sofac::Assembler::kMapped + 6, 0, S.b3_t.data());"
    )


def test_cpp_text_is_refused_as_an_argument() -> None:
    with pytest.raises(TypeError, match="not a plan argument"):
        call("mass_gravity", "S.b1_x.data()")


def test_a_rest_position_no_call_reads_is_not_allocated() -> None:
    from sofac.pipeline import plan_file

    oscillator = {b.key for b in plan_file(REPO / "scenes" / "oscillator.scn").buffers}
    assert "/oscillator/dofs.position" in oscillator
    assert "/oscillator/dofs.rest_position" not in oscillator  # springs and a mass: nobody reads it
    liver = {b.key for b in plan_file(REPO / "scenes" / "liver.scn").buffers}
    assert "/Liver/dofs.rest_position" in liver  # TetrahedronFEMForceField's init reads it


@pytest.mark.parametrize(
    ("force_field", "young", "poisson"),
    [("TetrahedronFEMForceField", 5000.0, 0.45), ("QuadBendingFEMForceField", 1000.0, 0.45)],
)
def test_an_empty_material_list_takes_the_registry_default(
    tmp_path: Path, force_field: str, young: float, poisson: float
) -> None:
    """SOFA's getVecRealInElement falls back on the Data's default; the plan fills it in, so no
    kernel carries a default of its own."""
    from sofac.pipeline import plan_file
    from sofac.registry import lookup

    found = lookup(force_field)
    assert found is not None and found.spec.field("youngModulus").default == (young,)
    cells = 'tetrahedra="0 1 2 3"' if force_field.startswith("Tetra") else 'quads="0 1 3 2"'
    scene = tmp_path / "material.scn"
    scene.write_text(
        f"""<Node name="root" dt="0.01"><DefaultAnimationLoop/>
  <EulerImplicitSolver/><CGLinearSolver iterations="10" tolerance="1e-9" threshold="1e-9"/>
  <MechanicalObject name="dofs" template="Vec3d" position="0 0 0  1 0 0  0 1 0  1 1 0.5"/>
  <MeshTopology {cells}/>
  <UniformMass totalMass="1"/>
  <{force_field} name="ff" youngModulus="" poissonRatio=""/>
</Node>
"""
    )
    values = {b.key: b.initial for b in plan_file(scene).buffers}
    assert values["/ff.youngModulus"].tolist() == [young]
    assert values["/ff.poissonRatio"].tolist() == [poisson]
