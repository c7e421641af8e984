"""An interactive window on a running simulation: ``sofac view SCENE``, ``sofac.view(sim)``.

It draws with the renderer of ``sofac render`` (:mod:`sofac.render`: the same layers, colours,
camera fitting and ``VisualStyle``), into an OpenGL window opened with GLFW (the ``glfw`` package:
a thin ctypes binding whose wheels ship the GLFW library, for X11 and Wayland, so nothing else
needs installing, and GLFW itself is small and widely used for exactly this: a window, an OpenGL
context and input events). Keys and mouse (``h`` shows them in the window):

* space play/pause, ``n`` or Right one step, ``r`` reset, ``[``/``]`` slower/faster, ``t`` real time
  or as fast as it can;
* left drag orbits, right (or middle) drag pans, the wheel zooms; ``1``..``8`` the views of
  ``sofac render --view``, ``0`` the first camera;
* ``v`` ``b`` ``f`` ``i`` ``c`` ``m`` ``w`` toggle the layers visual, behavior, force fields,
  interaction force fields, collision, mappings, wireframe; ``g`` the ground grid;
* ``s`` a screenshot (PNG) of what the window shows, ctrl+``s`` starts/stops an MP4 recording,
  ``o`` hides/shows the overlay, ``h`` the keys;
* shift+left drag picks the DOF under the pointer and pulls it with a spring to the pointer, as
  SOFA's mouse interaction does: the spring is applied by the compiled step as the state's point
  force (``<state>.pointForceIndex`` / ``<state>.pointForce``, compiled by
  ``load(..., interactive=True)``), so nothing is recompiled.

A step that diverges or fails leaves the window open, paused, on the last good state, with the
message. Without a display, :class:`NoDisplay` says so and points to ``sofac render``.
"""

from __future__ import annotations

import math
import os
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from sofac.diagnostics import SofacError
from sofac.render import picture as render

VIEW_KEYS = ("front", "back", "left", "right", "top", "bottom", "elevated", "iso")  # keys 1..8
LAYER_KEYS = {
    "v": ("visual", "visual"),
    "b": ("behavior", "behaviorModels"),
    "f": ("force_fields", "forceFields"),
    "i": ("interaction_force_fields", "interactionForceFields"),
    "c": ("collision", "collision"),
    "m": ("mappings", "mappings"),
    "w": ("wireframe", "wireframe"),
}
HELP = (
    "space play/pause   n step   r reset   [ ] slower/faster   t real time/fast",
    "drag orbit   right drag pan   wheel zoom   1-8 views   0 first camera",
    "v b f i c m w layers   g grid   o overlay   s screenshot   ctrl+s record MP4",
    "shift+drag pull a point   h help   q quit",
)
FRAME_BUDGET = 0.035  # seconds of stepping per drawn frame, at most
RECORD_FPS = 30.0
_SPRING: render.RGBA = (1.0, 0.35, 0.85, 1.0)


class NoDisplay(SofacError):
    """No window can be opened here (no display, or GLFW cannot reach it)."""


def display_problem() -> str | None:
    """Why no window can be opened here, or None if one may be."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) and sys.platform.startswith(
        "linux"
    ):
        return "no display: neither DISPLAY nor WAYLAND_DISPLAY is set"
    return None


def no_display_message(why: str) -> str:
    return (
        f"sofac view needs a window, and {why}; draw the scene into files instead with "
        "`sofac render SCENE --steps N --out FILE.png` (or FILE.gif, FILE.mp4), which needs no display"
    )


@dataclass
class Options:
    """What the window starts with."""

    width: int = 960
    height: int = 720
    camera: render.Camera | None = None  # default: the scene's InteractiveCamera, else the front view
    show: Mapping[str, bool] | None = None
    grid: bool = False
    paused: bool = False
    speed: float = 1.0  # simulated seconds per wall-clock second, in real time
    fast: bool = False  # as fast as it can instead of real time
    out_dir: Path = Path()  # screenshots and recordings
    name: str = "scene"  # their file names' stem
    title: str = "sofac view"


# --- OpenGL and GLFW ------------------------------------------------------------------------------


def _window_gl(wayland: bool) -> Any:
    """PyOpenGL on the window system's platform (GLX, or EGL under Wayland)."""
    platform = "egl" if wayland else "glx"
    loaded = sys.modules.get("OpenGL.platform")
    if loaded is not None:
        name = type(getattr(loaded, "PLATFORM", None)).__name__
        if "OSMesa" in name:
            raise SofacError(
                "PyOpenGL was already set up for off-screen drawing in this process (sofac render, "
                "sim.render()); open the window in a fresh Python process, or before drawing off-screen"
            )
    else:
        os.environ["PYOPENGL_PLATFORM"] = platform
    from OpenGL import GL

    return GL


def _glfw() -> Any:
    try:
        import glfw
    except ImportError as error:
        raise SofacError(
            f"the glfw package cannot be imported ({error}): run scripts/setup.sh, or pip install glfw"
        ) from None
    return glfw


# --- camera ---------------------------------------------------------------------------------------


class _Eye:
    """The camera the mouse moves: position, target and up, orbiting around the target."""

    def __init__(self, camera: render.Camera) -> None:
        assert camera.position is not None and camera.look_at is not None
        self.fov = camera.fov
        self.position = np.asarray(camera.position, dtype=float)
        self.target = np.asarray(camera.look_at, dtype=float)
        _, _, self.up = render._basis(self.target - self.position, camera.up)

    def camera(self) -> render.Camera:
        return render.Camera(
            position=render._vec3(self.position),
            look_at=render._vec3(self.target),
            up=render._vec3(self.up),
            fov=self.fov,
        )

    def orbit(self, dx: float, dy: float) -> None:
        """Turn around the target: ``dx`` radians about the up axis, then ``dy`` about the right one
        (the up vector turns along, so the camera can go over the top)."""
        offset = self.position - self.target
        _, right, up = render._basis(-offset, self.up)
        offset, right = _rotate(offset, up, -dx), _rotate(right, up, -dx)
        offset, up = _rotate(offset, right, -dy), _rotate(up, right, -dy)
        self.position, self.up = self.target + offset, up

    def pan(self, dx: float, dy: float) -> None:
        """Move sideways by fractions of the view's height at the target."""
        _, right, up = render._basis(self.target - self.position, self.up)
        span = 2 * self.distance * math.tan(math.radians(self.fov) / 2)
        shift = (-dx * right + dy * up) * span
        self.position = self.position + shift
        self.target = self.target + shift

    def zoom(self, factor: float) -> None:
        self.position = self.target + (self.position - self.target) * factor

    @property
    def distance(self) -> float:
        return float(np.linalg.norm(self.position - self.target))


def _rotate(vector: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """``vector`` turned by ``angle`` radians about the unit ``axis`` (Rodrigues)."""
    axis = axis / np.linalg.norm(axis)
    cos, sin = math.cos(angle), math.sin(angle)
    return vector * cos + np.cross(axis, vector) * sin + axis * (axis @ vector) * (1 - cos)


def ray(camera: render.Camera, x: float, y: float, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """The ray (origin, unit direction) through pixel ``(x, y)`` (x right, y down) of a resolved camera."""
    eye, target = camera._ends()
    forward, right, up = render._basis(target - eye, camera.up)
    tan_y = math.tan(math.radians(camera.fov) / 2)
    ndc_x, ndc_y = 2 * x / width - 1, 1 - 2 * y / height
    direction = forward + ndc_x * tan_y * (width / height) * right + ndc_y * tan_y * up
    return eye, direction / np.linalg.norm(direction)


def ray_hits(
    origin: np.ndarray, direction: np.ndarray, points: np.ndarray, triangles: np.ndarray
) -> float | None:
    """The distance along the ray to the nearest triangle it crosses (Möller-Trumbore), or None."""
    if not len(triangles):
        return None
    a, b, c = (points[triangles[:, k]] for k in range(3))
    edge1, edge2 = b - a, c - a
    p = np.cross(direction, edge2)
    det = np.einsum("ij,ij->i", edge1, p)
    with np.errstate(all="ignore"):  # parallel triangles: inf and NaN, filtered out below
        inverse = 1.0 / det
        t_vec = origin - a
        u = np.einsum("ij,ij->i", t_vec, p) * inverse
        q = np.cross(t_vec, edge1)
        v = (q @ direction) * inverse
        t = np.einsum("ij,ij->i", edge2, q) * inverse
        hit = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & np.isfinite(t)
    return float(t[hit].min()) if hit.any() else None


# --- picking --------------------------------------------------------------------------------------


@dataclass
class Pick:
    """A DOF pulled by the mouse spring toward ``target``."""

    state: str
    index: int
    target: np.ndarray  # world point the spring pulls to
    normal: np.ndarray  # the drag plane's normal (the view direction when picked)
    anchor: np.ndarray  # a point of the drag plane
    stiffness: float
    damping: float
    error: np.ndarray | None = None  # target - x when the force was last set

    # The spring is applied explicitly (the force of the step's start), so its stiffness starts
    # from what the DOF's mass alone keeps stable (omega dt = 0.45). A DOF held by stiff, implicitly
    # integrated neighbours is stable with far more, and needs it to follow the mouse: while the
    # DOF neither overshoots the target nor closes in on it quickly, the stiffness grows by GROWTH a
    # step; an overshoot halves it (never under where it started, at most MOST_GAIN times that).
    GROWTH = 1.05
    MOST_GAIN = 1e4

    def adapt(self, error: np.ndarray, start: float) -> None:
        last = self.error
        self.error = error
        if last is None:
            return
        if float(error @ last) < 0:
            self.stiffness = max(self.stiffness / 2, start)
        elif np.linalg.norm(error) > 0.9 * np.linalg.norm(last):
            self.stiffness = min(self.stiffness * self.GROWTH, start * self.MOST_GAIN)


class _PointForces:
    """The point-force parameters of the states the compiled step computes forces on."""

    def __init__(self, sim: Any) -> None:
        self.sim = sim
        params = sim.params()
        self.states = [p for p in sim.objects() if f"{p}.pointForceIndex" in params]
        # The parameter views, looked up once: set before every step while a DOF is pulled.
        self.views = {p: (params[f"{p}.pointForceIndex"], params[f"{p}.pointForce"]) for p in self.states}
        self.start_stiffness = 0.0  # the picked DOF's stiffness when picked

    def clear(self) -> None:
        for point, _ in self.views.values():
            point[0] = -1

    def apply(self, pick: Pick) -> None:
        """The spring's force on the picked DOF now: k (target - x) - c v."""
        state = self.sim[pick.state]
        x = render._as_points3(state.position[pick.index : pick.index + 1])[0]
        v = np.zeros(3)
        velocity = state.velocity[pick.index]
        v[: min(3, len(velocity))] = velocity[:3]
        pick.adapt(pick.target - x, self.start_stiffness)
        force = pick.stiffness * (pick.target - x) - pick.damping * v
        point, vector = self.views[pick.state]
        vector[:] = 0.0  # a rigid frame's torque stays zero: the spring pulls its centre
        count = min(3, len(vector))
        vector[:count] = force[:count]
        point[0] = pick.index

    def mass(self, path: str, index: int) -> float:
        """The mass that sizes the mouse spring on a DOF (see _dof_mass)."""
        return _dof_mass(self.sim, path, index)


def _dof_mass(sim: Any, path: str, index: int) -> float:
    """The mass of a DOF, measured from the kinetic energy of a unit velocity given to it alone
    (the velocities are put back): M_ii, whatever the mass component. For a DOF with no mass of
    its own (a mapped state's), the mean mass per DOF of the independent states. 1 if neither."""
    saved = {p: sim[p].velocity.copy() for p in sim.objects()}
    try:
        for velocity in saved:
            sim[velocity].velocity[...] = 0.0
        if not sim[path].info.mapped:
            sim[path].velocity[index, 0] = 1.0
            mass = 2.0 * sim.energy().kinetic
            if mass > 0 and math.isfinite(mass):
                return mass
        independent = [info for info in sim.states() if not info.mapped and info.size]
        for info in independent:
            sim[info.path].velocity[:, 0] = 1.0
        total = 2.0 * sim.energy().kinetic
        count = sum(info.size for info in independent)
        return total / count if total > 0 and math.isfinite(total) and count else 1.0
    finally:
        for state, velocity in saved.items():
            sim[state].velocity[...] = velocity


# --- the window -----------------------------------------------------------------------------------


class Viewer:
    """The window and its loop; ``run()`` returns when the window is closed."""

    def __init__(
        self, sim: Any, options: Options | None = None, *, log: Callable[[str], None] | None = None
    ) -> None:
        self.sim = sim
        self.options = options or Options()
        self.log = log or (lambda message: print(f"sofac view: {message}", file=sys.stderr, flush=True))
        opts = self.options
        self.renderer = render.Renderer(
            sim, width=opts.width, height=opts.height, camera=opts.camera, grid=opts.grid, show=opts.show,
            supersample=1,
        )  # fmt: skip
        self.running = not opts.paused
        self.fast = opts.fast
        self.speed = opts.speed
        self.help = False
        self.overlay = True
        self.message = ""  # an error that stopped the simulation
        self.notice = ""  # an error of a key or mouse action (the simulation goes on)
        self.forces = _PointForces(sim)
        self.forces.clear()
        self.pick: Pick | None = None
        self.ms_per_step = 0.0
        self.realtime_factor = 0.0
        self.shots = 0
        self.recording: Any = None
        self.recorded = 0
        self._record_path: Path | None = None
        self._last_record = 0.0
        self._budget = 0.0  # simulated time owed to the wall clock, in real time
        self._rtf_window: list[tuple[float, float]] = []  # (wall, sim time) samples
        self._good = self._save()
        self._drag: tuple[str, float, float] | None = None  # (what, x, y) of the mouse drag going on
        self._closed = threading.Event()
        self._first_camera: render.Camera | None = None
        self.eye: _Eye | None = None
        self._window: Any = None
        self._glfw: Any = None
        self.GL: Any = None

    # --- state ------------------------------------------------------------------------------------
    def _save(self) -> list[tuple[np.ndarray, np.ndarray]]:
        return [(self.sim[p].position.copy(), self.sim[p].velocity.copy()) for p in self.sim.objects()]

    def _restore(self, saved: list[tuple[np.ndarray, np.ndarray]]) -> None:
        for path, (x, v) in zip(self.sim.objects(), saved, strict=True):
            state = self.sim[path]
            state.position[...] = x
            state.velocity[...] = v

    def step(self, count: int) -> int:
        """Run ``count`` steps (one at a time while a DOF is pulled: the spring follows it);
        returns the number run. An error pauses, restores the last good state and keeps the message."""
        if count <= 0 or self.message:
            return 0
        self._good = self._save()
        started = time.perf_counter()
        done = 0
        try:
            if self.pick is None:
                self.sim.step(count)
                done = count
            else:
                for _ in range(count):
                    self.forces.apply(self.pick)
                    self.sim.step(1)
                    done += 1
        except Exception as error:  # divergence, contact, a parameter: shown, the window stays
            self._fail(error)
            return done
        elapsed = time.perf_counter() - started
        if done:
            per_step = 1000.0 * elapsed / done
            self.ms_per_step = per_step if not self.ms_per_step else 0.8 * self.ms_per_step + 0.2 * per_step
        return done

    def _fail(self, error: Exception) -> None:
        self.running = False
        last_finite = getattr(error, "last_finite", None)  # SimulationDiverged's, nearer than ours
        if last_finite:
            for path, (x, v) in last_finite.items():
                self.sim[path].position[...] = x
                self.sim[path].velocity[...] = v
        else:
            self._restore(self._good)
        text = str(error) or type(error).__name__
        self.message = f"{type(error).__name__}: {text}"
        self.log(f"paused: {self.message}")
        self.message += "\nPaused on the last good state: r resets."

    def reset(self) -> None:
        self.sim.reset()
        self.forces.clear()
        self.pick = None
        self.message = ""
        self._budget = 0.0
        self._good = self._save()
        self.log("reset")

    def advance(self, wall: float) -> None:
        """Step for ``wall`` seconds of wall-clock time: as much simulated time (times the speed) in
        real time, or as many steps as fit in the frame budget when fast."""
        if not self.running:
            return
        dt = self.sim.dt
        # Steps that fit in a frame, from the time steps took so far (one until that is known).
        most = max(1, int(FRAME_BUDGET * 1000.0 / self.ms_per_step)) if self.ms_per_step > 0 else 1
        if self.fast:
            count = most
        else:
            self._budget += min(wall, 0.25) * self.speed
            count = int(self._budget / dt + 1e-9)
            if count > most:  # cannot keep up: the simulation falls behind the clock
                count, self._budget = most, 0.0
            else:
                self._budget -= count * dt
        self.step(count)

    # --- layers and camera ------------------------------------------------------------------------
    def layer_on(self, layer: str) -> bool:
        nodes = {id(item.component.node): item.component.node for item in self.renderer.checked}
        return any(getattr(self.renderer.layers(node), layer) for node in nodes.values())

    def toggle_layer(self, layer: str, word: str) -> None:
        on = not self.layer_on(layer)
        self.renderer.show[word] = on
        self.log(f"layer {word} {'on' if on else 'off'}")

    def set_view(self, name: str | None) -> None:
        """A camera fitted from a named side (None: the first camera) to what is drawn now."""
        if name is None:
            assert self._first_camera is not None
            self.eye = _Eye(self._first_camera)
        else:
            _, (low, high) = self.renderer.scene_primitives()
            width, height = self._size()
            self.eye = _Eye(render.Camera.view(name, margin=1.3).resolve(low, high, width / height))
        self.log(f"view {name or 'first'}")

    def _fit(self) -> render.Camera:
        _, (low, high) = self.renderer.scene_primitives()
        width, height = self._size()
        spec = self.renderer.camera_spec  # with room around: the scene moves
        return replace(spec, margin=max(spec.margin, 1.3)).resolve(low, high, width / height)

    def _size(self) -> tuple[int, int]:
        if self._window is None:
            return self.options.width, self.options.height
        width, height = self._glfw.get_framebuffer_size(self._window)
        return max(int(width), 1), max(int(height), 1)

    # --- picking ----------------------------------------------------------------------------------
    def start_pick(self, x: float, y: float) -> Pick | None:
        """Pick the DOF under framebuffer pixel ``(x, y)``: the one nearest to where the ray meets a
        visual surface, else the nearest to the eye among those drawn within a few pixels."""
        assert self.eye is not None
        camera = self.eye.camera()
        width, height = self._size()
        origin, direction = ray(camera, x, y, width, height)
        frame = self.renderer.capture()
        surface = None
        for primitive in self.renderer.scene_primitives(frame)[0]:
            if isinstance(primitive, render._Mesh):
                hit = ray_hits(origin, direction, primitive.points, primitive.triangles.astype(np.int64))
                if hit is not None and (surface is None or hit < surface):
                    surface = hit
        best: tuple[float, str, int] | None = None
        radius = 12.0 * max(1.0, height / 720.0)
        for path in self.forces.states:
            points = render._as_points3(frame[path])
            if not len(points):
                continue
            if surface is not None:
                where = origin + surface * direction
                distance = np.linalg.norm(points - where, axis=1)
            else:
                screen = camera.project(points, width, height)
                near = np.hypot(screen[:, 0] - x, screen[:, 1] - y) <= radius
                distance = np.where(near, (points - origin) @ direction, np.inf)
            distance = np.where(np.isfinite(distance), distance, np.inf)
            index = int(np.argmin(distance))
            if np.isfinite(distance[index]) and (best is None or distance[index] < best[0]):
                best = (float(distance[index]), path, index)
        if best is None:
            self.log("pick: nothing under the pointer")
            return None
        _, path, index = best
        point = render._as_points3(frame[path][index : index + 1])[0]
        forward = render._unit(np.asarray(camera.look_at) - np.asarray(camera.position))
        mass = self.forces.mass(path, index)
        omega = 0.45 / self.sim.dt  # the spring is applied explicitly: omega dt well under 2
        self.pick = Pick(path, index, point.copy(), forward, point.copy(), mass * omega**2, mass * omega)
        self.forces.start_stiffness = self.pick.stiffness
        self.log(f"picked {path}[{index}] at {_format(point)}")
        return self.pick

    def drag_pick(self, x: float, y: float) -> None:
        """Move the spring's end to where the ray through ``(x, y)`` meets the drag plane."""
        if self.pick is None or self.eye is None:
            return
        width, height = self._size()
        origin, direction = ray(self.eye.camera(), x, y, width, height)
        across = float(direction @ self.pick.normal)
        if abs(across) < 1e-9:
            return
        distance = float((self.pick.anchor - origin) @ self.pick.normal) / across
        self.pick.target = origin + distance * direction

    def release_pick(self) -> None:
        if self.pick is None:
            return
        state = self.sim[self.pick.state]
        point = render._as_points3(state.position[self.pick.index : self.pick.index + 1])[0]
        self.log(
            f"released {self.pick.state}[{self.pick.index}] at {_format(point)} "
            f"(pulled toward {_format(self.pick.target)})"
        )
        self.forces.clear()
        self.pick = None

    # --- pictures ---------------------------------------------------------------------------------
    def screenshot(self, image: np.ndarray) -> Path:
        from sofac.render.cli import _write

        self.shots += 1
        path = self.options.out_dir / f"{self.options.name}-{self.shots:03d}.png"
        _write(path, [image], 1.0)
        self.log(f"wrote {path} (t={self.sim.time:g}, step {self.sim.steps})")
        return path

    def toggle_recording(self) -> None:
        from sofac.render.cli import mp4_writer

        if self.recording is None:
            self.shots += 1
            path = self.options.out_dir / f"{self.options.name}-{self.shots:03d}.mp4"
            path.parent.mkdir(parents=True, exist_ok=True)
            self.recording, self._record_path, self.recorded = mp4_writer(path, RECORD_FPS), path, 0
            self.log(f"recording {path}")
        else:
            self.recording.close()
            self.log(f"wrote {self._record_path} ({self.recorded} frames)")
            self.recording = None

    def _record(self, image: np.ndarray) -> None:
        from sofac.render.cli import even_sides

        now = time.perf_counter()
        if now - self._last_record < 1.0 / RECORD_FPS - 1e-3:
            return
        self._last_record = now
        self.recording.append_data(even_sides(image))
        self.recorded += 1

    # --- window loop ------------------------------------------------------------------------------
    def run(self) -> None:
        """Open the window and run until it is closed (q, Esc, or the window's close button)."""
        why = display_problem()
        if why:
            raise NoDisplay(no_display_message(why))
        glfw = self._glfw = _glfw()
        wayland = bool(os.environ.get("WAYLAND_DISPLAY")) and not os.environ.get("DISPLAY")
        if hasattr(glfw, "PLATFORM"):
            glfw.init_hint(glfw.PLATFORM, glfw.PLATFORM_WAYLAND if wayland else glfw.PLATFORM_X11)
        errors: list[str] = []
        glfw.set_error_callback(
            lambda code, text: errors.append(text.decode() if isinstance(text, bytes) else text)
        )
        if not glfw.init():
            raise NoDisplay(
                no_display_message(f"GLFW cannot open one ({'; '.join(errors) or 'no reason given'})")
            )
        try:
            glfw.window_hint(glfw.SAMPLES, 4)
            window = glfw.create_window(
                self.options.width, self.options.height, self.options.title, None, None
            )
            if not window:
                raise NoDisplay(
                    no_display_message(f"no OpenGL window could be created ({'; '.join(errors)})")
                )
            self._window = window
            glfw.make_context_current(window)
            glfw.swap_interval(1)
            self.GL = _window_gl(wayland)
            self._first_camera = self._fit()
            self.eye = _Eye(self._first_camera)
            glfw.set_key_callback(window, self._guarded(self._on_key))
            glfw.set_mouse_button_callback(window, self._guarded(self._on_button))
            glfw.set_cursor_pos_callback(window, self._guarded(self._on_cursor))
            glfw.set_scroll_callback(window, self._guarded(self._on_scroll))
            self.log(f"window open ({'playing' if self.running else 'paused'}; h for the keys)")
            last = time.perf_counter()
            while not glfw.window_should_close(window):
                if self.running:
                    glfw.poll_events()
                else:
                    glfw.wait_events_timeout(0.05)
                now = time.perf_counter()
                before = self.sim.time
                self.advance(now - last)
                self._sample_rtf(now, self.sim.time - before)
                last = now
                self._frame()
                glfw.swap_buffers(window)
                rest = 1 / 60 - (time.perf_counter() - now)
                if rest > 0:
                    time.sleep(rest)
        finally:
            if self.recording is not None:
                self.toggle_recording()
            self.forces.clear()
            glfw.terminate()
            self._window = None
            self._closed.set()

    def _guarded(self, handler: Callable[..., None]) -> Callable[..., None]:
        """``handler`` with its errors (a screenshot that cannot be written, ...) shown in the
        overlay and logged, rather than raised through GLFW out of the window's loop."""

        def guarded(*args: Any) -> None:
            try:
                handler(*args)
            except Exception as error:
                self.notice = f"{type(error).__name__}: {error}"
                self.log(self.notice)

        return guarded

    def _sample_rtf(self, now: float, advanced: float) -> None:
        window = self._rtf_window
        window.append((now, advanced))
        while window and now - window[0][0] > 1.0:
            window.pop(0)
        span = now - window[0][0] if len(window) > 1 else 0.0
        self.realtime_factor = sum(a for _, a in window[1:]) / span if span > 0 else 0.0

    def _frame(self) -> None:
        with np.errstate(all="ignore"):  # the last states before a divergence: huge, drawn as they are
            self._draw_frame()

    def _draw_frame(self) -> None:
        GL = self.GL
        assert self.eye is not None
        width, height = self._size()
        primitives, _ = self.renderer.scene_primitives()
        if self.pick is not None:
            state = self.sim[self.pick.state]
            point = render._as_points3(state.position[self.pick.index : self.pick.index + 1])[0]
            ends = np.array([point, self.pick.target])
            primitives.append(render._Lines(ends, np.tile(_SPRING, (2, 1)), 2.0))
            primitives.append(render._Points(ends, _SPRING, 8.0))
        render.draw_primitives(GL, primitives, self.eye.camera(), width, height, self.renderer.background)
        if self.overlay:
            self._overlay(width, height)
        if self._wants_image():  # what the window shows
            image = self._read(width, height)
            if self.recording is not None and self.running:
                self._record(image)
            while self._pending_shots:
                self._pending_shots -= 1
                self.screenshot(image)

    _pending_shots = 0

    def _wants_image(self) -> bool:
        return bool(self._pending_shots) or self.recording is not None

    def _read(self, width: int, height: int) -> np.ndarray:
        GL = self.GL
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        data = GL.glReadPixels(0, 0, width, height, GL.GL_RGB, GL.GL_UNSIGNED_BYTE)
        return np.ascontiguousarray(np.flipud(np.frombuffer(data, np.uint8).reshape(height, width, 3)))

    def status(self) -> list[str]:
        """The overlay's lines."""
        try:
            energy = self.sim.energy()
            energy_text = f"energy {energy.kinetic + energy.potential:.6g} (kinetic {energy.kinetic:.4g})"
        except Exception as error:
            energy_text = f"energy: {error}"
        achieved = f"x{self.realtime_factor:.2f} real time" if self.running else "paused"
        pace = "as fast as it can" if self.fast else f"real time x{self.speed:g}"
        lines = [
            f"t = {self.sim.time:.4f} s   step {self.sim.steps}   dt {self.sim.dt:g}   "
            f"{self.ms_per_step:.3f} ms/step",
            f"{pace} ({achieved})",
            energy_text,
        ]
        if self.pick is not None:
            lines.append(f"pulling {self.pick.state}[{self.pick.index}]")
        if self.recording is not None:
            lines.append(f"recording {self._record_path} ({self.recorded} frames)")
        if self.notice:
            lines.append(self.notice)
        if self.help:
            lines.extend(HELP)
        return lines

    def _overlay(self, width: int, height: int) -> None:
        lines = self.status()
        text = _text_image(lines, self.message)
        GL = self.GL
        rows, columns = text.shape[:2]
        GL.glEnable(GL.GL_BLEND)
        GL.glBlendFunc(GL.GL_SRC_ALPHA, GL.GL_ONE_MINUS_SRC_ALPHA)
        GL.glDisable(GL.GL_DEPTH_TEST)
        GL.glPixelStorei(GL.GL_UNPACK_ALIGNMENT, 1)
        GL.glWindowPos2i(8, max(0, height - rows - 8))
        GL.glDrawPixels(columns, rows, GL.GL_RGBA, GL.GL_UNSIGNED_BYTE, np.ascontiguousarray(np.flipud(text)))
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glDisable(GL.GL_BLEND)

    # --- input ------------------------------------------------------------------------------------
    def _on_key(self, window: Any, key: int, scancode: int, action: int, mods: int) -> None:
        glfw = self._glfw
        if action not in (glfw.PRESS, glfw.REPEAT):
            return
        name = glfw.get_key_name(key, scancode)
        if key in (glfw.KEY_ESCAPE, glfw.KEY_Q):
            glfw.set_window_should_close(window, True)
        elif key == glfw.KEY_SPACE:
            self.running = not self.running and not self.message
            self._budget = 0.0
            self.log("playing" if self.running else f"paused (t={self.sim.time:g}, step {self.sim.steps})")
        elif key in (glfw.KEY_N, glfw.KEY_RIGHT):
            self.running = False
            self.step(1)
            self.log(f"stepped to t={self.sim.time:g}, step {self.sim.steps}")
        elif key == glfw.KEY_R:
            self.reset()
        elif key == glfw.KEY_S and mods & glfw.MOD_CONTROL:
            self.toggle_recording()
        elif key == glfw.KEY_S:
            self._pending_shots += 1
        elif key == glfw.KEY_T:
            self.fast = not self.fast
            self._budget = 0.0
            self.log("as fast as it can" if self.fast else "real time")
        elif key == glfw.KEY_LEFT_BRACKET or name == "[":
            self.speed = max(self.speed / 2, 1 / 64)
            self.log(f"speed x{self.speed:g}")
        elif key == glfw.KEY_RIGHT_BRACKET or name == "]":
            self.speed = min(self.speed * 2, 64.0)
            self.log(f"speed x{self.speed:g}")
        elif key == glfw.KEY_H:
            self.help = not self.help
        elif key == glfw.KEY_O:
            self.overlay = not self.overlay
            self.log(f"overlay {'on' if self.overlay else 'off'}")
        elif key == glfw.KEY_G:
            self.renderer.grid = not self.renderer.grid
            self.log(f"grid {'on' if self.renderer.grid else 'off'}")
        elif glfw.KEY_1 <= key <= glfw.KEY_8:
            self.set_view(VIEW_KEYS[key - glfw.KEY_1])
        elif key == glfw.KEY_0:
            self.set_view(None)
        elif name and name.lower() in LAYER_KEYS:
            self.toggle_layer(*LAYER_KEYS[name.lower()])

    def _cursor(self) -> tuple[float, float]:
        """The pointer in framebuffer pixels."""
        glfw = self._glfw
        x, y = glfw.get_cursor_pos(self._window)
        window_width, window_height = glfw.get_window_size(self._window)
        width, height = self._size()
        return x * width / max(window_width, 1), y * height / max(window_height, 1)

    def _on_button(self, window: Any, button: int, action: int, mods: int) -> None:
        glfw = self._glfw
        x, y = self._cursor()
        if action == glfw.PRESS:
            if button == glfw.MOUSE_BUTTON_LEFT and mods & glfw.MOD_SHIFT:
                self._drag = ("pick", x, y) if self.start_pick(x, y) else None
            elif button == glfw.MOUSE_BUTTON_LEFT:
                self._drag = ("orbit", x, y)
            else:
                self._drag = ("pan", x, y)
        elif action == glfw.RELEASE:
            if self._drag is not None and self._drag[0] == "pick":
                self.release_pick()
            self._drag = None

    def _on_cursor(self, window: Any, _x: float, _y: float) -> None:
        if self._drag is None or self.eye is None:
            return
        what, x0, y0 = self._drag
        x, y = self._cursor()
        _, height = self._size()
        if what == "pick":
            self.drag_pick(x, y)
            return
        dx, dy = (x - x0) / height, (y - y0) / height
        if what == "orbit":
            self.eye.orbit(dx * math.pi, dy * math.pi)
        else:
            self.eye.pan(dx, dy)
        self._drag = (what, x, y)

    def _on_scroll(self, window: Any, _dx: float, dy: float) -> None:
        if self.eye is not None:
            self.eye.zoom(0.9 ** float(dy))


def _format(point: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.4g}" for c in point) + ")"


_FONT: Any = None


def _text_image(lines: list[str], error: str) -> np.ndarray:
    """The overlay: ``lines`` (white) and ``error`` (red, wrapped) on a translucent dark box, RGBA."""
    global _FONT
    from PIL import Image, ImageDraw, ImageFont

    if _FONT is None:
        try:
            _FONT = ImageFont.load_default(size=14)
        except TypeError:  # Pillow < 10.1: the fixed bitmap font
            _FONT = ImageFont.load_default()
    import textwrap

    rows = [(line, (235, 235, 235, 255)) for line in lines]
    for part in error.splitlines():
        rows.extend((wrapped, (255, 110, 100, 255)) for wrapped in textwrap.wrap(part, 100) or [""])
    height_of_row = 18
    width = max(int(_FONT.getlength(text)) for text, _ in rows) + 12
    image = Image.new("RGBA", (width, height_of_row * len(rows) + 8), (0, 0, 0, 150))
    draw = ImageDraw.Draw(image)
    for k, (text, color) in enumerate(rows):
        draw.text((6, 4 + k * height_of_row), text, font=_FONT, fill=color)
    return np.asarray(image, dtype=np.uint8)


# --- Python entry point ---------------------------------------------------------------------------


class ViewerHandle:
    """A viewer running in a thread of its own (``sofac.view(sim)``): ``wait()``, ``close()``.

    The viewer steps the simulation while its window is open: do not step it from another thread
    meanwhile."""

    def __init__(self, viewer: Viewer) -> None:
        self.viewer = viewer
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="sofac view", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            self.viewer.run()
        except BaseException as error:  # kept for wait(): a thread cannot raise into its caller
            self.error = error
            self.viewer._closed.set()

    @property
    def is_running(self) -> bool:
        return self._thread.is_alive()

    def wait(self, timeout: float | None = None) -> None:
        """Until the window is closed; raises what stopped the viewer, if anything did."""
        self._thread.join(timeout)
        if self.error is not None:
            raise self.error

    def close(self) -> None:
        window, glfw = self.viewer._window, self.viewer._glfw
        if window is not None and glfw is not None:
            glfw.set_window_should_close(window, True)
            glfw.post_empty_event()
        self.wait()


def view(sim: Any, *, block: bool | None = None, **options: Any) -> ViewerHandle | None:
    """Open a window on ``sim`` (options: see :class:`Options`; ``view="iso"`` picks a named view).

    ``block=None`` returns at once with a :class:`ViewerHandle` where GLFW may run off the main
    thread (Linux, Windows), and blocks until the window is closed on macOS, where it may not."""
    why = display_problem()
    if why:
        raise NoDisplay(no_display_message(why))
    name = options.pop("view", None)
    if name is not None:
        options["camera"] = render.Camera.view(name)
    viewer = Viewer(sim, Options(**options))
    if block is None:
        block = sys.platform == "darwin"
    if block:
        viewer.run()
        return None
    return ViewerHandle(viewer)


__all__ = ["NoDisplay", "Options", "Pick", "Viewer", "ViewerHandle", "display_problem", "ray", "view"]
