"""``sofac view``: an interactive window on a running scene (see :mod:`sofac.view`).

Kept apart from the viewer so that building the parser imports nothing heavy (no numpy, no GLFW).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sofac.cli.usage import EXIT_ERRORS, EXIT_OK, Failed, UsageError, data_roots, layer_flags, reported
from sofac.render.cli import _LAYER_HELP, _camera, _size, _vector, _words

_KEYS_HELP = (
    "Keys: space play/pause, n (or Right) one step, r reset, [ ] slower/faster, t real time or as fast "
    "as it can, 1-8 the views front back left right top bottom elevated iso, 0 the first camera, "
    "v b f i c m w toggle the layers visual, behavior, force fields, interaction force fields, collision, "
    "mappings, wireframe, g the grid, o the overlay, s a screenshot (PNG in --out-dir), ctrl+s "
    "start/stop an MP4, h help, q quit. Mouse: drag orbits, right drag pans, the wheel zooms, shift+drag "
    "pulls the point under the pointer with a spring (applied by the compiled step: nothing is recompiled)."
)


def cmd_view(args: argparse.Namespace) -> int:

    path = Path(args.scene)
    if not path.is_file():
        raise UsageError(f"no such file: {args.scene}")
    if args.dt is not None and not args.dt > 0:
        raise UsageError("--dt must be > 0")
    if args.threads < 1:
        raise UsageError("--threads must be >= 1")
    if not 0 < args.speed <= 64:
        raise UsageError("--speed must be in (0, 64]")
    if args.fov is not None and not 0 < args.fov < 180:
        raise UsageError("--fov must be in (0, 180) degrees")
    roots = data_roots(args.data_path)
    show = layer_flags(args)
    from sofac.viewer import window as view

    why = view.display_problem()  # before compiling: say it at once
    if why:
        print(f"sofac: error: {view.no_display_message(why)}", file=sys.stderr)
        return EXIT_ERRORS
    width, height = args.size
    try:
        with reported():
            from sofac.pipeline import load
            from sofac.render import picture as render

            try:
                render.check_show(show)
            except ValueError as error:
                raise UsageError(str(error)) from None
            sim = load(path, dt=args.dt, data_roots=roots, threads=args.threads, interactive=True)
            options = view.Options(
                width=width,
                height=height,
                camera=_camera(args, render.scene_camera(sim.compiled.checked)),
                show=show,
                grid=args.grid,
                paused=args.paused,
                speed=args.speed,
                fast=args.fast,
                out_dir=Path(args.out_dir),
                name=path.stem,
                title=f"sofac view - {path.name}",
            )
            viewer = view.Viewer(sim, options)
            try:
                viewer.run()
            except view.NoDisplay as error:
                print(f"sofac: error: {error}", file=sys.stderr)
                raise Failed from None
    except Failed:
        return EXIT_ERRORS
    return EXIT_OK


def register(commands: argparse._SubParsersAction, epilog: str) -> None:
    """Add ``view`` to the ``sofac`` parser."""
    parser = commands.add_parser(
        "view",
        help="watch a scene run in a window: play, pause, step, camera, layers, pull points with the mouse",
        description=(
            "Compile SCENE and open a window that runs it in real time (or as fast as it can) and "
            "draws it as sofac render does, with an overlay of the time, step, ms/step, real-time "
            "factor and energy. A step that diverges or fails pauses the window on the last good "
            "state with the message. Needs a display; without one, use sofac render."
        ),
        epilog=_KEYS_HELP + " " + _LAYER_HELP + " " + epilog,
    )
    parser.add_argument("scene", metavar="SCENE", help="the scene file")
    parser.add_argument("--dt", type=float, metavar="DT", help="time step (default: the scene's)")
    parser.add_argument("--threads", type=int, default=1, metavar="N", help="OpenMP threads (default: 1)")
    parser.add_argument("--data-path", action="append", metavar="DIR", help="folder to search (repeatable)")
    parser.add_argument(
        "--size", type=_size, default=(960, 720), metavar="WxH", help="window size (default: 960x720)"
    )
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
        "--show", type=_words, action="extend", metavar="LAYERS", help="draw these layers too (see below)"
    )
    parser.add_argument(
        "--hide", type=_words, action="extend", metavar="LAYERS", help="do not draw these layers"
    )
    parser.add_argument("--paused", action="store_true", help="open paused (space plays)")
    parser.add_argument(
        "--speed", type=float, default=1.0, metavar="X", help="simulated seconds per second (default: 1)"
    )
    parser.add_argument("--fast", action="store_true", help="run as fast as it can rather than in real time")
    parser.add_argument(
        "--out-dir", default=".", metavar="DIR", help="where screenshots and recordings go (default: .)"
    )
    parser.set_defaults(handler=cmd_view)
