"""Python scene files (SofaPython3's ``createScene(rootNode)``) and trees built in Python.

A ``.py`` scene is executed with sofac's SofaPython3-compatible API (sofapython.py): its
``createScene(rootNode)`` builds sofac's own model tree, which then goes through the same
check -> plan -> compile pipeline as a ``.scn`` file. Loading a ``.py`` scene runs the user's code,
as SofaPython3 does; ``sofac check --no-exec`` refuses such files instead.

What the compiled result depends on, for the warm records (warm.py): the script's content and
every file it opened or imported while it ran (recorded with an audit hook), except the Python
installation's own files.

Controllers (``Sofa.Core.Controller`` subclasses added with ``addObject``) run between compiled
steps, in the order SOFA's event visitor reaches them (depth first, in each node in the order they
were added): ``onAnimateBeginEvent`` before each step, ``onAnimateEndEvent`` after it. A scene
without controllers gets the plain :class:`~sofac.loader.Simulation`, so it pays nothing for them.
"""

from __future__ import annotations

import builtins
import contextlib
import os
import site
import sys
import sysconfig
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType, TracebackType
from typing import Any

from sofac.diagnostics import Diagnostics, SceneError, SofacError, SourceLoc
from sofac.front import model
from sofac.front.datafiles import default_data_roots, real_path
from sofac.pyscene import sofa_api as sofapython
from sofac.simulation.loader import Compiled, Simulation

__all__ = [
    "ControlledSimulation",
    "ControllerError",
    "PythonScene",
    "execute_script",
    "refused",
    "save",
]


@dataclass
class PythonScene(model.Scene):
    """A scene built by Python code, with the controllers it added (in event order)."""

    controllers: list[sofapython.Controller] = field(default_factory=list)
    # Whether a simulation runs with these controllers: another one needs its own (a new run).
    started: bool = False


class ControllerError(SofacError):
    """A controller's callback raised an exception while the simulation ran."""


# --- what a script reads -----------------------------------------------------------------------

_reads: list[str] | None = None
_hook_installed = False


def _audit(event: str, args: tuple[Any, ...]) -> None:
    # Runs for every audited event of the process: do nothing unless a script is being executed.
    if _reads is None or event != "open":
        return
    try:
        path, mode, flags = args
        if isinstance(path, int):
            return
        writes = (
            any(c in mode for c in "wax+") if isinstance(mode, str) else flags & (os.O_WRONLY | os.O_RDWR)
        )
        if not writes:
            _reads.append(os.fsdecode(path))
    except Exception:  # an audit hook must never break the code it watches
        return


def _installation_dirs() -> list[str]:
    """Folders whose files belong to Python (its standard library, installed packages) or sofac,
    not to the scene (whose files may well lie under the prefix, e.g. /usr/share)."""
    dirs = {sofapython._PACKAGE_DIR}
    for layout in {sysconfig.get_default_scheme(), "posix_user"} & set(sysconfig.get_scheme_names()):
        paths = sysconfig.get_paths(layout)
        dirs.update(paths[key] for key in ("stdlib", "platstdlib", "purelib", "platlib") if key in paths)
    with contextlib.suppress(AttributeError):
        dirs.update(site.getsitepackages())
    return [os.path.realpath(d) + os.sep for d in dirs if d]


@contextlib.contextmanager
def _recording() -> Iterator[list[str]]:
    global _reads, _hook_installed
    if not _hook_installed:
        sys.addaudithook(_audit)  # cannot be removed: it stays idle outside this block
        _hook_installed = True
    reads: list[str] = []
    previous, _reads = _reads, reads
    try:
        yield reads
    finally:
        _reads = previous


def _dependencies(script: Path, reads: list[str], base: Path) -> list[Path]:
    """The script and the regular files it read, outside Python's installation, real paths."""
    skip = _installation_dirs()
    found: list[Path] = [script]
    for name in reads:
        try:
            path = real_path(base / name)
        except (OSError, ValueError, RuntimeError):
            continue
        text = str(path)
        if path.suffix == ".pyc" or any(text.startswith(d) for d in skip) or not path.is_file():
            continue
        if path not in found:
            found.append(path)
    return found


# --- executing a script ------------------------------------------------------------------------


def _user_line(tb: TracebackType | None, display: str) -> SourceLoc:
    """The innermost frame of the user's code in a traceback (the line that failed)."""
    where = SourceLoc(display, 0)
    for frame, line in traceback.walk_tb(tb):
        filename = frame.f_code.co_filename
        if sofapython._is_user_frame(filename):
            where = SourceLoc(sofapython.display_file(filename), line)
    return where


def _report(diagnostics: Diagnostics, error: BaseException, display: str, what: str) -> None:
    loc = _user_line(error.__traceback__, display)
    if isinstance(error, SyntaxError) and error.lineno:
        loc = SourceLoc(sofapython.display_file(error.filename or display), error.lineno)
    if isinstance(error, sofapython.SofaAPIError):
        diagnostics.add(
            "E113", loc, str(error), "use the API listed in docs/python-scenes.md, or write the scene as .scn"
        )
    else:
        detail = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
        diagnostics.add("E113", loc, f"{what} raised {detail}", "fix the script (it runs as Python code)")


def _scene_modules_dropped(before: set[str], directory: str) -> list[str]:
    """Forget the modules the script imported from its folder (so that an edit to one is seen
    next time); returns their source files."""
    sources: list[str] = []
    for name in [n for n in sys.modules if n not in before]:
        module = sys.modules[name]
        origin = getattr(getattr(module, "__spec__", None), "origin", None) or getattr(
            module, "__file__", None
        )
        if isinstance(origin, str) and os.path.realpath(origin).startswith(directory + os.sep):
            sources.append(origin)
            del sys.modules[name]
    return sources


def _controllers_in_order(root: model.Node) -> list[sofapython.Controller]:
    ordered: list[sofapython.Controller] = []
    for node in root.walk():
        ordered.extend(sofapython.controllers_of(node))
    return ordered


def execute_script(
    path: str | Path, diagnostics: Diagnostics, *, data_roots: Sequence[Path] = (), max_bytes: int = 0
) -> PythonScene:
    """Run a scene script's ``createScene(rootNode)``; the tree it built as a scene.

    Problems (unreadable file, syntax error, an exception, an API sofac does not provide) are
    E100/E103/E113 diagnostics at the script's line; :class:`SceneError` is raised after them."""
    from sofac.front.parse import DEFAULT_MAX_BYTES, _read_capped, _TooLarge

    display = str(path)
    given = Path(path)
    scene_dir = Path(os.path.abspath(given)).parent
    start = SourceLoc(display, 0)
    try:
        source = _read_capped(given, max_bytes or DEFAULT_MAX_BYTES)
    except _TooLarge:
        diagnostics.add(
            "E103", start, f"{display} is larger than {max_bytes or DEFAULT_MAX_BYTES} bytes; refused"
        )
        raise SceneError(diagnostics) from None
    except (OSError, ValueError) as exc:
        diagnostics.add("E100", start, f"cannot read {display}: {getattr(exc, 'strerror', None) or exc}")
        raise SceneError(diagnostics) from None
    sofapython._DISPLAY[display] = display
    try:
        code = compile(source, display, "exec", dont_inherit=True)
    except (SyntaxError, ValueError) as error:
        _report(diagnostics, error, display, "compiling the script")
        raise SceneError(diagnostics) from None
    module = ModuleType(f"sofac_scene_{given.stem}")
    module.__file__ = os.path.abspath(given)
    module.__dict__["__builtins__"] = builtins
    real_dir = os.path.realpath(scene_dir)
    modules_before = set(sys.modules)
    root: Any = None
    with (
        sofapython.injected(),
        _recording() as reads,
        contextlib.redirect_stdout(sys.stderr),  # a script's prints never mix with sofac's reports
    ):
        sys.path.insert(0, str(scene_dir))
        try:
            exec(code, module.__dict__)
            create = module.__dict__.get("createScene")
            if not callable(create):
                diagnostics.add(
                    "E113",
                    start,
                    f"{display} defines no createScene(rootNode) function",
                    "a SofaPython3 scene defines def createScene(rootNode): ... adding objects to rootNode",
                )
                raise SceneError(diagnostics)
            line = getattr(getattr(create, "__code__", None), "co_firstlineno", 0)
            root = sofapython.Node._of(model.Node("root", SourceLoc(display, line)))
            returned = create(root)
            if isinstance(returned, sofapython.Node):
                root = returned
        except SceneError:
            raise
        except KeyboardInterrupt:
            raise
        except BaseException as error:  # SystemExit included: the script ends, the scene is bad
            _report(diagnostics, error, display, "the scene script")
            raise SceneError(diagnostics) from None
        finally:
            with contextlib.suppress(ValueError):
                sys.path.remove(str(scene_dir))
            reads.extend(_scene_modules_dropped(modules_before, real_dir))
    tree = root._node
    return PythonScene(
        tree,
        file=given,
        data_roots=default_data_roots(scene_dir, data_roots),
        sources=_dependencies(real_path(given), reads, Path.cwd()),
        controllers=_controllers_in_order(tree),
    )


def refused(path: str | Path) -> Diagnostics:
    """``sofac check --no-exec``: the diagnostic that says a Python scene was not run."""
    diagnostics = Diagnostics()
    diagnostics.add(
        "E114",
        SourceLoc(str(path), 0),
        f"{path} is a Python scene: checking it means running its code, and --no-exec forbids that",
        "check it without --no-exec where running the script is safe, or save it as .scn "
        "(sofac.save(root, 'scene.scn')) and check that",
    )
    return diagnostics


# --- compiling and running ---------------------------------------------------------------------


class ControlledSimulation(Simulation):
    """A simulation whose Python controllers run at SOFA's step boundaries: each controller's
    ``onAnimateBeginEvent(event)`` before a step, ``onAnimateEndEvent(event)`` after it (or
    ``onEvent``), the event being SofaPython3's dict (``type``, ``isHandled``, ``dt``)."""

    def __init__(self, compiled: Compiled, controllers: Sequence[sofapython.Controller]) -> None:
        super().__init__(compiled)
        self.controllers = list(controllers)
        self._begin = self._handlers("onAnimateBeginEvent")
        self._end = self._handlers("onAnimateEndEvent")

    def _handlers(self, method: str) -> list[tuple[sofapython.Controller, Callable[[Any], Any]]]:
        found = []
        for controller in self.controllers:
            handler = getattr(controller, method, None) or getattr(controller, "onEvent", None)
            if callable(handler):
                found.append((controller, handler))
        return found

    def step(self, n: int = 1, *, energy_bound: float | None = None) -> None:
        if n < 0:
            raise ValueError("n must be >= 0")
        with sofapython.injected():
            for _ in range(int(n)):
                self._dispatch(self._begin, "AnimateBeginEvent")
                super().step(1, energy_bound=energy_bound)
                self._dispatch(self._end, "AnimateEndEvent")

    def _dispatch(
        self, handlers: list[tuple[sofapython.Controller, Callable[[Any], Any]]], kind: str
    ) -> None:
        for controller, handler in handlers:
            event = {"type": kind, "isHandled": False, "dt": self.dt}
            try:
                handler(event)
            except Exception as error:
                where = _user_line(error.__traceback__, controller.location.file)
                detail = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
                raise ControllerError(
                    f"{where}: controller {controller.getName()!r} (added at {controller.location}) raised "
                    f"{detail} in {getattr(handler, '__name__', kind)} at step {self.steps + 1} "
                    f"(t={self.time:g})"
                ) from error


def start(compiled: Compiled, scene: model.Scene, controllers: Sequence[sofapython.Controller]) -> Simulation:
    for controller in controllers:
        if controller._running:
            raise SofacError(
                f"controller {controller.getName()!r} ({controller.location}) already drives a simulation "
                "(its Data are views of that simulation): build the tree again, with new controllers, "
                "for another"
            )
    sim = ControlledSimulation(compiled, controllers) if controllers else Simulation(compiled)
    for controller in controllers:
        controller._running = True
    if isinstance(scene, PythonScene):
        scene.started = True
    sofapython.bind(scene.root, sim)
    with sofapython.injected():
        for controller in controllers:
            controller.init()
    return sim


def instantiate(compiled: Compiled, scene: PythonScene) -> Simulation:
    """``Compiled.instantiate()`` of a scene with controllers (sweeps, accuracy studies): each
    simulation gets controllers of its own, from a new run of the script."""
    if scene.started:
        if scene.file is None:
            raise SofacError(
                "a tree built in Python with controllers gives one simulation: build the tree again "
                "(with new controllers) for another"
            )
        scene = execute_script(scene.file, Diagnostics(), data_roots=scene.data_roots)
    return start(compiled, scene, scene.controllers)


def tree_scene(tree: Any, data_roots: Sequence[Path]) -> tuple[model.Scene, list[sofapython.Controller]]:
    if isinstance(tree, model.Scene):
        return tree, list(getattr(tree, "controllers", ()))
    if isinstance(tree, sofapython.Node):
        tree = tree._node
    if not isinstance(tree, model.Node):
        raise TypeError(
            f"sofac.load takes a scene file path or a root node (sofac.model.Node, Sofa.Core.Node), "
            f"not a {type(tree).__name__}"
        )
    if tree.parent is not None:
        raise SofacError(f"node {tree.path!r} is not a root: load the root of its tree ({tree.root!r})")
    controllers = _controllers_in_order(tree)
    scene = PythonScene(tree, data_roots=default_data_roots(Path.cwd(), data_roots), controllers=controllers)
    return scene, controllers


def save(tree: Any, path: str | os.PathLike[str]) -> Path:
    """``sofac.save(root, "scene.scn")``: write a tree built in Python as ``.scn`` XML.

    Python controllers cannot be written to XML: saving a tree that has some raises SofacError
    (remove them, or keep the scene as a script)."""
    from sofac.front.writer import save_scene

    scene, controllers = tree_scene(tree, ())
    if controllers:
        names = ", ".join(f"{c.getName()!r} ({c.location})" for c in controllers)
        raise SofacError(f"the tree has Python controllers ({names}), which a .scn file cannot hold")
    return save_scene(scene, path)
