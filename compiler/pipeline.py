"""The one driver of the stages: parse → check → plan → generate → build → load.

Every tool (the command line, :func:`sofac.load`, accuracy, sweeps, regress, render) goes through
these functions, so a scene is checked, planned and compiled the same way whatever asks for it, and
a scene with errors always stops at the same place: a :class:`SceneError` carrying every diagnostic.
The stages themselves import nothing from here: data flows one way.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sofac.diagnostics import Diagnostic, Diagnostics, SceneError, SofacError

if TYPE_CHECKING:  # the front end is imported only when a scene is compiled (not for warm loads)
    from sofac.check.checker import CheckedScene
    from sofac.front.model import Scene
    from sofac.plan.ir import Plan
    from sofac.simulation.loader import Compiled, Simulation


def _stop_on_errors(checked: CheckedScene | None, diagnostics: Diagnostics) -> CheckedScene:
    if checked is None or diagnostics.has_errors():
        raise SceneError(diagnostics.sorted())
    return checked


def check_file(path: str | Path, *, data_roots: Sequence[Path] = ()) -> tuple[CheckedScene, Diagnostics]:
    """Parse and check a scene file; raises SceneError if it has errors."""
    from sofac.check.checker import check_file as check

    checked, diagnostics = check(path, data_roots=data_roots)
    return _stop_on_errors(checked, diagnostics), diagnostics


def check_model(scene: Scene) -> tuple[CheckedScene, Diagnostics]:
    """Check a scene model built or edited in Python; raises SceneError if it has errors."""
    from sofac.check.checker import check_scene

    diagnostics = Diagnostics()
    checked = check_scene(scene, diagnostics)
    return _stop_on_errors(checked, diagnostics), diagnostics


def plan_checked(
    checked: CheckedScene,
    diagnostics: Diagnostics | None = None,
    *,
    prune: bool = True,
    rigid_model: str = "sofa",
    threads: int = 1,
    interactive: bool = False,
) -> Plan:
    from sofac.plan.planner import plan_scene

    return plan_scene(
        checked, diagnostics, prune=prune, rigid_model=rigid_model, threads=threads, interactive=interactive
    )


def add_compile_refusals(checked: CheckedScene | None, diagnostics: Diagnostics) -> None:
    """What ``sofac run`` would refuse, reported by ``sofac check``: a scene that checks clean is
    planned (no code generated, no build) and the planner's refusals (E222...) join the check's
    diagnostics, with the code, file and line the compile would give. The rules stay in the
    planner alone. A scene with errors (or with unsupported components let through as warnings)
    is not planned: its own diagnostics already say why it will not compile."""
    if checked is None or diagnostics.has_errors() or any(d.code == "E222" for d in diagnostics):
        return
    with contextlib.suppress(SceneError):  # its diagnostics are in ``diagnostics`` already
        plan_checked(checked, diagnostics)


def plan_file(path: str | Path, *, data_roots: Sequence[Path] = (), threads: int = 1) -> Plan:
    """Check and plan a scene file, issuing its warnings (SceneWarning)."""
    from sofac import scene_warnings

    checked, diagnostics = check_file(path, data_roots=data_roots)
    scene_warnings.issue(diagnostics.sorted())
    return plan_checked(checked, diagnostics, threads=threads)


def generate(scene_plan: Plan) -> str:
    """The C++ source of a plan."""
    from sofac.codegen.cpp import generate_source

    return generate_source(scene_plan)


def compile_checked(
    checked: CheckedScene,
    diagnostics: Diagnostics | None = None,
    *,
    prune: bool = True,
    rigid_model: str = "sofa",
    threads: int = 1,
    interactive: bool = False,
) -> Compiled:
    """Plan, generate and build a checked scene (the build may come from the cache)."""
    from sofac import param_rules, scene_warnings
    from sofac.build import compiler as build
    from sofac.simulation.loader import Compiled
    from sofac.simulation.runspec import run_spec

    scene_plan = plan_checked(
        checked, diagnostics, prune=prune, rigid_model=rigid_model, threads=threads, interactive=interactive
    )
    spec = dataclasses.replace(run_spec(scene_plan), rules=param_rules.rules_of(checked, scene_plan.buffers))
    source = generate(scene_plan)
    direct = any(g.direct or g.preconditioned for g in scene_plan.groups)  # CHOLMOD / assembly
    numbers = sum(b.initial.size for b in scene_plan.buffers)  # picks -O2 or -O3 (build.scene_flags)
    built = build.build_scene(source, direct_solver=direct, numbers=numbers, openmp=scene_plan.threads > 1)
    found = scene_warnings.scene_warnings(diagnostics.sorted()) if diagnostics is not None else ()
    return Compiled(
        spec, built, scene_plan=scene_plan, source=source, checked=checked, rebuild=_rebuild, warnings=found
    )


def _rebuild(checked: CheckedScene, **options: Any) -> Compiled:
    return compile_checked(checked, **options)


def compile_scene(
    path: str | Path,
    *,
    data_roots: Sequence[Path] = (),
    prune: bool = True,
    rigid_model: str = "sofa",
    threads: int = 1,
    interactive: bool = False,
    strict: bool = False,
) -> Compiled:
    """Check, plan, generate and build a scene file (the build may come from the cache). The
    scene's warnings are issued as SceneWarning; ``strict``: they are errors (StrictSceneError)."""
    compiled = _compile_scene(
        path,
        data_roots=data_roots,
        prune=prune,
        rigid_model=rigid_model,
        threads=threads,
        interactive=interactive,
        strict=strict,
    )
    _issue(compiled.warnings, strict)
    return compiled


def _compile_scene(
    path: str | Path, *, data_roots: Sequence[Path] = (), strict: bool = False, **options: Any
) -> Compiled:
    """compile_scene() without issuing the warnings (a strict scene with warnings stops before
    it is built)."""
    _check_data_roots(data_roots)
    checked, diagnostics = check_file(path, data_roots=data_roots)
    if strict:
        from sofac import scene_warnings

        scene_warnings.issue(diagnostics, strict=True)
    return compile_checked(checked, diagnostics, **options)


def _issue(warnings: Sequence[Diagnostic], strict: bool) -> None:
    """Issue a scene's warnings as SceneWarning, attributed to the caller of load() or
    compile_scene(); the module is imported only when there are some (a warm load stays light)."""
    if warnings:
        from sofac import scene_warnings

        scene_warnings.issue(warnings, strict=strict, stacklevel=3)


def _check_data_roots(data_roots: Sequence[Path]) -> None:
    """The command line refuses a data root that is no folder (--data-path); so does the API."""
    if isinstance(data_roots, (str, Path)):
        shown = repr(str(data_roots))
        raise SofacError(f"data_roots={shown}: give a list of folders, such as [{shown}]")
    for root in data_roots:
        if not Path(root).is_dir():
            raise SofacError(f"data_roots: {root}: no such folder (each data root is a folder to search)")


def compile_model(scene: Scene, **options: Any) -> Compiled:
    """Check, plan, generate and build a scene model built or edited in Python."""
    checked, diagnostics = check_model(scene)
    return compile_checked(checked, diagnostics, **options)


def load(
    path: str | Path | Any,
    *,
    dt: float | None = None,
    data_roots: Sequence[Path] = (),
    prune: bool = True,
    rigid_model: str = "sofa",
    threads: int = 1,
    interactive: bool = False,
    strict: bool = False,
) -> Simulation:
    """Compile (or fetch from the cache) and instantiate a scene. ``threads`` > 1 runs the large
    element loops (FEM) on that many OpenMP threads, with the same numbers as one thread;
    ``interactive`` compiles a point force on each state that Python sets between steps
    (``<state path>.pointForceIndex`` / ``.pointForce`` parameters: how ``sofac view`` pulls).

    The scene's warnings (those ``sofac check`` prints) are issued as ``sofac.SceneWarning``
    Python warnings, on every load; ``strict=True`` raises StrictSceneError (a SceneError listing
    them) instead.

    A scene loaded before, whose files and sofac are unchanged, is instantiated from its warm
    record (simulation/warm.py) without being compiled again.

    ``path`` may also be a ``.py`` SofaPython3 scene script, or a root node built in Python
    (``sofac.front.model.Node``, ``Sofa.Core.Node``): see sofac.pyscene."""
    started = time.perf_counter()
    options: dict[str, Any] = {
        "data_roots": tuple(data_roots),
        "prune": prune,
        "rigid_model": rigid_model,
        "threads": threads,
        "interactive": interactive,
    }
    _check_data_roots(data_roots)
    if not isinstance(path, (str, os.PathLike)) or Path(path).suffix.lower() == ".py":
        sim = _load_python_scene(path, options)
    else:
        compiled = _warm_or_built(path, options, lambda: _compile_scene(path, strict=strict, **options))
        _issue(compiled.warnings, strict)
        sim = compiled.instantiate()
    sim.load_seconds = time.perf_counter() - started  # type: ignore[attr-defined]
    if dt is not None:
        sim.dt = dt
    return sim


def _load_python_scene(source: Any, options: dict[str, Any]) -> Simulation:
    """A SofaPython3 script (run once: its tree is compiled, or taken from its warm record keyed on
    the script and every file it read) or a tree built in Python, started with its controllers."""
    from sofac.pyscene import script

    compile_options = {key: options[key] for key in ("prune", "rigid_model", "threads", "interactive")}
    if not isinstance(source, (str, os.PathLike)):
        scene, controllers = script.tree_scene(source, options["data_roots"])
        return script.start(compile_model(scene, **compile_options), scene, controllers)
    scene = script.execute_script(source, Diagnostics(), data_roots=options["data_roots"])
    compiled = _warm_or_built(source, options, lambda: compile_model(scene, **compile_options))
    compiled.python_scene = scene  # later instantiate() calls run the script again
    return script.start(compiled, scene, scene.controllers)


def _warm_or_built(path: str | Path, options: dict[str, Any], build: Callable[[], Compiled]) -> Compiled:
    """The scene's warm record for these load options (the plan, source and checked scene are
    built again on first use, their warnings already in the record), else ``build()``, stored as
    the record the next load finds."""
    from sofac.simulation import warm
    from sofac.simulation.loader import Compiled

    record = warm.lookup(path, **options)
    if record is not None:

        def recompute() -> Compiled:
            from sofac import scene_warnings

            with scene_warnings.quiet():  # issued by load(), from the record
                return build()

        return Compiled(
            record.spec,
            record.built,
            recompute=recompute,
            rebuild=_rebuild,
            warnings=record.warnings,
            known_host=record.host,
        )
    compiled = build()
    warm.store(path, compiled.spec, compiled.built, compiled.checked, warnings=compiled.warnings, **options)
    return compiled
