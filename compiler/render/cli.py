"""``sofac render``: pictures and videos of a simulation (see :mod:`sofac.render.picture`).

Kept apart from the renderer so that building the parser imports nothing heavy (no numpy, no OpenGL).
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from sofac.cli.usage import (
    EXIT_ERRORS,
    EXIT_INTERRUPTED,
    EXIT_OK,
    Failed,
    UsageError,
    data_roots,
    layer_flags,
    reported,
)

FORMATS = (".png", ".gif", ".mp4")
_LAYER_HELP = (
    "LAYERS for --show/--hide: the words of SOFA's VisualStyle displayFlags without show/hide, "
    "case-insensitive: visual (visualModels), behaviorModels (the DOFs), forceFields (springs, element "
    "edges), interactionForceFields, behavior (the three), collision (collisionModels), mappings "
    "(mechanicalMappings), wireframe, all."
)
DEFAULT_FRAMES = 100  # frames of an animation when --every is not given


def _size(text: str) -> tuple[int, int]:
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match:
        raise argparse.ArgumentTypeError(f"not a size WxH: {text!r}")
    width, height = int(match.group(1)), int(match.group(2))
    if not (1 <= width <= 8192 and 1 <= height <= 8192):
        raise argparse.ArgumentTypeError(f"size {text!r}: each side must be from 1 to 8192 pixels")
    return width, height


def _vector(text: str) -> tuple[float, float, float]:
    items = [item for item in text.replace(",", " ").split() if item]
    try:
        values = [float(item) for item in items]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"not three numbers X,Y,Z: {text!r}")
    return values[0], values[1], values[2]


def _words(text: str) -> list[str]:
    words = [item for item in text.replace(",", " ").split() if item]
    if not words:
        raise argparse.ArgumentTypeError("empty list of layers")
    return words


def _color(text: str) -> tuple[float, float, float, float]:
    from sofac.registry.fields import Color, FieldValueError

    try:
        return Color().parse(text)
    except FieldValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


class _Progress:
    """A progress bar on stderr, redrawn in place on a terminal; elsewhere a line per quarter, and
    one a second between them."""

    def __init__(self, total: int, label: str, enabled: bool, stream: TextIO | None = None) -> None:
        self.total = max(total, 1)
        self.label = label
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.done = 0
        self.started = time.perf_counter()
        self._quarter = 0
        self._printed = self.started
        self._tty = self.stream.isatty()

    def advance(self, count: int = 1) -> None:
        self.done = min(self.total, self.done + count)
        if not self.enabled:
            return
        if self._tty:
            width = 30
            filled = round(width * self.done / self.total)
            elapsed = time.perf_counter() - self.started
            bar = "#" * filled + "." * (width - filled)
            self.stream.write(f"\r{self.label:<10} [{bar}] {self.done}/{self.total} {elapsed:5.1f}s")
            self.stream.flush()
        else:
            quarter = 4 * self.done // self.total
            now = time.perf_counter()
            if quarter > self._quarter or now - self._printed >= 1.0:
                self._quarter, self._printed = quarter, now
                print(f"{self.label}: {self.done}/{self.total}", file=self.stream, flush=True)

    def close(self) -> None:
        if self.enabled and self._tty:
            self.stream.write("\n")
            self.stream.flush()


def _camera(args: argparse.Namespace, scene_camera: Any) -> Any:
    """The camera the options ask for: the scene's InteractiveCamera unless --view is given, changed
    by --camera-position, --look-at, --fov."""
    from dataclasses import replace

    from sofac.render.picture import Camera

    camera = Camera.view(args.view) if args.view else (scene_camera or Camera())
    changes: dict[str, Any] = {}
    if args.camera_position is not None:
        changes["position"] = args.camera_position  # looking at the scene's look-at point, else its centre
    if args.look_at is not None:
        changes["look_at"] = args.look_at
        if args.camera_position is None:
            changes["position"] = None  # fitted along the view direction, looking at --look-at
    if args.fov is not None:
        changes["fov"] = args.fov
    return replace(camera, **changes) if changes else camera


def _write(path: Path, frames: list[Any], fps: float) -> None:
    """Write one frame as PNG, several as an animated GIF or an MP4 (H.264)."""
    import imageio.v3 as iio
    import numpy as np

    suffix = path.suffix.lower()
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".png":
        iio.imwrite(path, frames[-1], extension=".png")
    elif suffix == ".gif":
        iio.imwrite(path, np.stack(frames), extension=".gif", plugin="pillow", duration=1000.0 / fps, loop=0)
    else:
        with mp4_writer(path, fps) as writer:
            for frame in frames:
                writer.append_data(even_sides(frame))


def mp4_writer(path: Path, fps: float) -> Any:
    """An imageio writer of H.264 MP4 frames (``append_data``; a context manager)."""
    import imageio.v2 as imageio
    from sofac.diagnostics import SofacError

    try:
        import imageio_ffmpeg  # noqa: F401  (the ffmpeg binary imageio writes MP4 with)
    except ImportError:
        raise SofacError(
            "writing MP4 needs imageio-ffmpeg (pip install imageio-ffmpeg, or run scripts/setup.sh); "
            "--out FILE.gif needs nothing more"
        ) from None
    return imageio.get_writer(
        path, format="FFMPEG", mode="I", fps=fps, codec="libx264", quality=8, macro_block_size=1
    )


def even_sides(frame: Any) -> Any:
    """``frame`` padded to even sides by repeating its last row/column: H.264 in yuv420p needs them."""
    import numpy as np

    height, width = frame.shape[:2]
    if not (height % 2 or width % 2):
        return frame
    return np.pad(frame, ((0, height % 2), (0, width % 2), (0, 0)), mode="edge")


def cmd_render(args: argparse.Namespace) -> int:

    path = Path(args.scene)
    if not path.is_file():
        raise UsageError(f"no such file: {args.scene}")
    out = Path(args.out)
    if out.suffix.lower() not in FORMATS:
        raise UsageError(f"--out {args.out}: the file name must end in {', '.join(FORMATS)}")
    if args.steps < 0:
        raise UsageError("--steps must be >= 0")
    if args.every is not None and args.every < 1:
        raise UsageError("--every must be >= 1")
    if args.fps is not None and not 0 < args.fps <= 100:
        raise UsageError("--fps must be in (0, 100]")
    if args.fov is not None and not 0 < args.fov < 180:
        raise UsageError("--fov must be in (0, 180) degrees")
    if args.dt is not None and not args.dt > 0:
        raise UsageError("--dt must be > 0")
    roots = data_roots(args.data_path)
    show = layer_flags(args)
    animated = out.suffix.lower() != ".png"
    width, height = args.size
    progress_on = not args.no_progress
    try:
        with reported():
            from sofac.pipeline import load
            from sofac.render import picture as render
            from sofac.simulation.loader import SimulationDiverged

            try:
                render.check_show(show)
            except ValueError as error:
                raise UsageError(str(error)) from None
            sim = load(path, dt=args.dt, data_roots=roots)
            renderer = render.Renderer(
                sim,
                width=width,
                height=height,
                camera=_camera(args, render.scene_camera(sim.compiled.checked)),
                grid=args.grid,
                show=show,
                background=args.background or render.DEFAULT_BACKGROUND,
                supersample=args.supersample,
            )
            every = args.every or max(1, math.ceil(args.steps / DEFAULT_FRAMES))
            frames = [renderer.capture()] if animated else []

            def on_frame() -> None:
                if animated:
                    frames.append(renderer.capture())

            bar = _Progress(args.steps, "simulate", progress_on)
            from sofac.cli.run_progress import deferred_interrupt

            try:
                with deferred_interrupt() as stop:
                    _simulate(sim, args.steps, every, bar, on_frame, stop.is_set)
            except SimulationDiverged as error:
                bar.close()
                print(f"sofac: error: {error}", file=sys.stderr)
                raise Failed from None
            bar.close()
            if stop.is_set():
                print(
                    f"sofac: interrupted at step {sim.steps} of {args.steps} (t={sim.time:g}); "
                    f"nothing was written ({args.out} is written once every frame is drawn)",
                    file=sys.stderr,
                )
                return EXIT_INTERRUPTED
            if not animated:
                frames = [renderer.capture()]
            renderer.fit(frames)  # one camera for the whole animation
            bar = _Progress(len(frames), "render", progress_on and animated)
            images = []
            for frame in frames:
                images.append(renderer.render(frame))
                bar.advance()
            bar.close()
            fps = args.fps or min(50.0, max(1.0, 1.0 / (every * sim.dt)))
            _write(out, images, fps)
    except Failed:
        return EXIT_ERRORS
    for warning in renderer.warnings:
        print(f"sofac: warning: {warning}", file=sys.stderr)
    what = f"{len(images)} frames" if animated else f"t={sim.time:g}"
    print(f"sofac: wrote {out} ({width}x{height}, {what})", file=sys.stderr)
    return EXIT_OK


def _simulate(
    sim: Any,
    steps: int,
    every: int,
    bar: _Progress,
    on_frame: Callable[[], None],
    stopped: Callable[[], bool] = lambda: False,
) -> None:
    """Run ``steps`` steps, calling ``on_frame`` after each ``every`` of them, until ``stopped()``."""
    from sofac.cli.run_progress import Slicer

    slicer = Slicer()  # slices of about 0.2 s: the bar moves at least every second
    done = 0
    while done < steps:
        count = min(every, steps - done)
        stepped = 0
        while stepped < count:  # a frame after each full `every`
            if stopped():
                return
            part = slicer.next(count - stepped)
            began = time.perf_counter()
            sim.step(part)
            slicer.took(part, time.perf_counter() - began)
            bar.advance(part)
            stepped += part
        done += count
        if count == every:
            on_frame()


def register(commands: argparse._SubParsersAction, epilog: str) -> None:
    """Add ``render`` to the ``sofac`` parser."""
    parser = commands.add_parser(
        "render",
        help="draw a scene after N steps (PNG), or its motion (GIF, MP4), off-screen",
        description=(
            "Compile SCENE, run it for --steps steps and draw it with OSMesa (off-screen OpenGL: no "
            "display, no GPU): its visual models (OglModel) moved by their mappings, and the debug "
            "layers its VisualStyle asks for (behavior models, force fields, ...). A .png OUT gets "
            "the last frame; a .gif or .mp4 OUT gets a frame every K steps from the start, all drawn "
            "with one camera fitted to the whole motion."
        ),
        epilog=_LAYER_HELP + " " + epilog,
    )
    parser.add_argument("scene", metavar="SCENE", help="the scene file")
    parser.add_argument("--steps", type=int, default=0, metavar="N", help="steps to run (default: 0)")
    parser.add_argument(
        "--every",
        type=int,
        metavar="K",
        help=f"GIF/MP4: a frame every K steps (default: about {DEFAULT_FRAMES} frames in all)",
    )
    parser.add_argument(
        "--size", type=_size, default=(640, 480), metavar="WxH", help="image size (default: 640x480)"
    )
    parser.add_argument(
        "--out", required=True, metavar="FILE", help="the picture or video: FILE.png, FILE.gif or FILE.mp4"
    )
    parser.add_argument(
        "--fps", type=float, metavar="F", help="GIF/MP4 frame rate (default: real time, at most 50)"
    )
    parser.add_argument("--dt", type=float, metavar="DT", help="time step (default: the scene's)")
    parser.add_argument(
        "--view",
        choices=("front", "back", "left", "right", "top", "bottom", "elevated", "iso"),
        help="fit the camera from this side (default: the scene's InteractiveCamera, else front)",
    )
    parser.add_argument("--camera-position", type=_vector, metavar="X,Y,Z", help="the camera's position")
    parser.add_argument("--look-at", type=_vector, metavar="X,Y,Z", help="the point the camera looks at")
    parser.add_argument("--fov", type=float, metavar="DEG", help="vertical field of view (default: 45)")
    parser.add_argument("--grid", action="store_true", help="draw a ground grid under the scene")
    parser.add_argument(
        "--show",
        type=_words,
        action="extend",
        metavar="LAYERS",
        help="draw these layers too (comma-separated, repeatable; see below)",
    )
    parser.add_argument(
        "--hide", type=_words, action="extend", metavar="LAYERS", help="do not draw these layers"
    )
    parser.add_argument(
        "--background", type=_color, metavar="COLOR", help="background: a name, #rrggbb or 'r g b'"
    )
    parser.add_argument(
        "--supersample",
        type=int,
        choices=(1, 2, 3, 4),
        default=2,
        help="draw N times larger per side and average down, for smooth edges (default: 2)",
    )
    parser.add_argument("--data-path", action="append", metavar="DIR", help="folder to search (repeatable)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.set_defaults(handler=cmd_render)
