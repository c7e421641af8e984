"""The pipeline's shape, as docs/architecture.md states it: each stage imports only earlier stages
and shared code (data flows one way), no stage imports the pipeline driver or a tool, and no two
modules import each other, even through others."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "compiler"
# The stages in pipeline order; shared code any stage may use; tools that drive the stages.
STAGES = ("front", "check", "plan", "codegen", "build", "simulation")
SHARED = {
    "diagnostics",
    "resources",
    "progress",
    "registry",
    "geometry",
    "limits",
    "paths",
    "param_rules",
    "scene_warnings",
    "cache_errors",
    "__init__",
}
TOOLS = {"pipeline", "cli", "accuracy", "render", "sweeps", "regress", "viewer", "pyscene", "__main__"}
# Calls from a stage into a tool, each on purpose: ``sim.render()``, a shortcut for
# ``sofac.render.render(sim)``; a ``.py`` scene handed by the parser to the Python front end, which
# runs the user's script; a Python scene's controllers, started with each instance; and a
# script's own ``Sofa.Simulation.init(root)``, which compiles its tree. These callbacks are left
# out of the cycle test: the rest of the graph has no cycle.
ALLOWED = {
    ("simulation.loader", "render.picture"),
    ("front.parse", "pyscene.script"),
    ("simulation.loader", "pyscene.script"),
    ("pyscene.sofa_api", "pipeline"),
}


def _module(path: Path) -> str:
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    return ".".join(p for p in parts if p != "__init__") or "__init__"


def _type_checking_only(tree: ast.Module) -> set[int]:
    """The import statements under ``if TYPE_CHECKING:`` (annotations only, never run)."""
    return {
        id(statement)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING"
        for statement in node.body
    }


def _imports(path: Path) -> set[str]:
    """The sofac modules a file imports when it runs, anywhere in it (lazy imports count)."""
    found: set[str] = set()
    tree = ast.parse(path.read_text())
    skipped = _type_checking_only(tree)
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("sofac"):
            base = node.module.removeprefix("sofac").lstrip(".")
            for alias in node.names:
                found.add(f"{base}.{alias.name}" if base else alias.name)
                if base:
                    found.add(base)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("sofac."):
                    found.add(alias.name.removeprefix("sofac."))
    return found


def _graph() -> dict[str, set[str]]:
    modules = {_module(p): p for p in PACKAGE.rglob("*.py")}
    return {name: {m for m in _imports(path) if m in modules and m != name} for name, path in modules.items()}


def _top(module: str) -> str:
    return module.split(".")[0]


def test_stages_import_only_earlier_stages_and_shared_code() -> None:
    wrong = []
    for module, imported in _graph().items():
        if _top(module) not in STAGES:
            continue
        rank = STAGES.index(_top(module))
        for other in imported:
            top = _top(other)
            if top in SHARED or (top in STAGES and STAGES.index(top) <= rank) or (module, other) in ALLOWED:
                continue
            wrong.append(f"{module} imports {other}")
    assert wrong == []


def test_no_import_cycles() -> None:
    graph = _graph()
    for module, callback in ALLOWED:
        graph[module].discard(callback)
    # Packages stand for their __init__; a module importing its own package's names is no cycle.
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for other in sorted(graph.get(node, ())):
            if other == _top(node) and "." in node:
                continue
            if state.get(other) == 1:
                cycles.append([*trail[trail.index(other) :], other] if other in trail else [node, other])
            elif other not in state:
                visit(other, [*trail, other])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert cycles == []


def test_the_graph_is_read() -> None:
    graph = _graph()
    assert "plan.ir" in graph["codegen.cpp"] and "front.parse" in graph["check.checker"]
    assert {"front", "check", "plan", "codegen", "build", "simulation"} <= {_top(m) for m in graph}


def test_every_name_imported_from_sofac_exists() -> None:
    """Each ``from sofac... import name`` anywhere in the package (lazy imports inside functions
    included, which only run on some paths) names something its module defines."""
    import importlib

    missing = []
    for path in sorted(PACKAGE.rglob("*.py")):
        package = ".".join(("sofac", *path.relative_to(PACKAGE).parent.parts))
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:  # relative: from its own package up
                base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                target = f"{base}.{node.module}" if node.module else base
            elif node.module is not None and node.module.split(".")[0] == "sofac":
                target = node.module
            else:
                continue
            module = importlib.import_module(target)
            for alias in node.names:
                if alias.name == "*" or hasattr(module, alias.name):
                    continue
                try:  # a submodule of a package
                    importlib.import_module(f"{target}.{alias.name}")
                except ImportError:
                    missing.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: {target}.{alias.name}")
    assert missing == []
