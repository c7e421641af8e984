"""``sofac view`` for real: the viewer runs in a virtual X server (Xvfb, Mesa's software OpenGL),
xdotool sends it keys and mouse events, and the screenshots it writes (``s``) are compared: the scene
moves while playing, stays still while paused, steps once, changes camera and layers, and a
shift-drag pulls the picked DOF the way the mouse went. Also: a diverging scene pauses with the
message, no display gives an error naming ``sofac render``, and ``sofac.view(sim)`` returns at once.

Xvfb and xdotool come from scripts/setup.sh (Debian packages xvfb, xdotool).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import sofac
from sofac.render import picture as render

DATA = Path(__file__).parent / "data"
CUBE = DATA / "view_cube.scn"
SIZE = (480, 360)
BACKGROUND = np.array(render.DEFAULT_BACKGROUND[:3]) * 255
BEHAVIOR = np.array(render._BEHAVIOR[:3]) * 255
TIMEOUT = 60.0  # seconds to wait for any one answer of the viewer (a slow, shared machine)

DIVERGING = """<Node name="root" gravity="0 0 0" dt="0.1">
  <DefaultAnimationLoop/>
  <VisualStyle displayFlags="showBehaviorModels showForceFields"/>
  <Node name="bad">
    <EulerExplicitSolver/>
    <MechanicalObject name="dofs" position="0 0 0  1.5 0 0"/>
    <UniformMass vertexMass="0.01"/>
    <FixedProjectiveConstraint indices="0"/>
    <SpringForceField spring="0 1 1e6 0 1"/>
  </Node>
</Node>
"""


def _tool(name: str) -> str:
    found = shutil.which(name)
    if found is None:
        pytest.fail(f"{name} is not installed: run scripts/setup.sh (Debian packages xvfb, xdotool)")
    return found


@pytest.fixture(scope="module")
def display() -> Iterator[str]:
    """A virtual X server of its own, on the display number it picks."""
    read, write = os.pipe()
    server = subprocess.Popen(
        [_tool("Xvfb"), "-displayfd", str(write), "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
        pass_fds=(write,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write)
    with os.fdopen(read) as answer:
        number = answer.readline().strip()
    if not number:
        server.kill()
        pytest.fail("Xvfb did not start")
    yield f":{number}"
    server.terminate()
    server.wait(10)


class Session:
    """One ``sofac view`` process: its stderr lines as they come, keys and mouse through xdotool."""

    def __init__(self, display: str, scene: Path, out: Path, *options: str) -> None:
        sofac.load(scene, interactive=True)  # compiled here, without a time limit: the viewer starts warm
        self.env = {**os.environ, "DISPLAY": display}
        self.env.pop("WAYLAND_DISPLAY", None)
        self.out = out
        command = [sys.executable, "-m", "sofac", "view", str(scene), "--size", "x".join(map(str, SIZE))]
        self.process = subprocess.Popen(
            [*command, "--out-dir", str(out), *options],
            env=self.env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: list[str] = []
        self.seen = 0  # lines already matched by wait()
        self._changed = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()
        self.wait(r"window open")
        title = f"^sofac view - {re.escape(scene.name)}$"  # the window of this process, not another's
        self.window = self.xdotool("search", "--sync", "--name", title).split()[0]
        self.xdotool("windowfocus", "--sync", self.window)

    def _read(self) -> None:
        assert self.process.stderr is not None
        for line in self.process.stderr:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()

    def wait(self, pattern: str) -> re.Match[str]:
        """The next stderr line matching ``pattern`` (after those matched before)."""
        deadline = time.monotonic() + TIMEOUT
        with self._changed:
            while True:
                for index in range(self.seen, len(self.lines)):
                    match = re.search(pattern, self.lines[index])
                    if match:
                        self.seen = index + 1
                        return match
                left = deadline - time.monotonic()
                if left <= 0 or (self.process.poll() is not None and len(self.lines) == self.seen):
                    log = "\n".join(self.lines)
                    pytest.fail(f"sofac view never printed /{pattern}/; it printed:\n{log}")
                self._changed.wait(min(left, 0.5))

    def xdotool(self, *args: str) -> str:
        done = subprocess.run(
            [_tool("xdotool"), *args], env=self.env, capture_output=True, text=True, timeout=TIMEOUT
        )
        assert done.returncode == 0, done.stderr
        return done.stdout

    def key(self, name: str, answer: str) -> re.Match[str]:
        self.xdotool("key", name)
        return self.wait(answer)

    def shot(self) -> tuple[np.ndarray, float, int]:
        """A screenshot (``s``): the picture, the time and the step it shows."""
        match = self.key("s", r"wrote (\S+\.png) \(t=(\S+), step (\d+)\)")
        return iio.imread(match.group(1)), float(match.group(2)), int(match.group(3))

    def close(self) -> int:
        if self.process.poll() is None:
            self.xdotool("key", "q")
        return self.process.wait(TIMEOUT)


def _cube_pixels(image: np.ndarray) -> np.ndarray:
    return np.abs(image.astype(float) - BACKGROUND).sum(axis=2) > 40


def _centre(image: np.ndarray) -> np.ndarray:
    """(x, y) of the mean of the pixels that are not background."""
    ys, xs = np.nonzero(_cube_pixels(image))
    assert len(xs), "nothing drawn"
    return np.array([xs.mean(), ys.mean()])


@pytest.fixture(scope="module")
def cube_session(display: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Session]:
    session = Session(display, CUBE, tmp_path_factory.mktemp("view"), "--paused")
    session.key("o", r"overlay off")  # pictures of the scene alone
    yield session
    session.close()


def test_playing_moves_the_scene_and_pausing_stops_it(cube_session: Session) -> None:
    start, time0, step0 = cube_session.shot()
    assert (time0, step0) == (0.0, 0)
    cube_session.key("space", r"playing")
    steps = 0
    while steps < 10:  # real time: wait for ten steps (0.2 s of simulated time)
        moved, _, steps = cube_session.shot()
    assert not np.array_equal(moved, start)
    paused = cube_session.key("space", r"paused \(t=\S+, step (\d+)\)")
    first, _, step1 = cube_session.shot()
    time.sleep(0.5)
    second, _, step2 = cube_session.shot()
    assert step1 == step2 == int(paused.group(1))
    assert np.array_equal(first, second)


def test_one_step_advances_one_step_and_moves(cube_session: Session) -> None:
    before, time_before, step = cube_session.shot()
    cube_session.key("n", rf"stepped to t=\S+, step {step + 1}\b")
    after, time_after, step_after = cube_session.shot()
    assert step_after == step + 1
    assert time_after == pytest.approx(time_before + 0.02)
    assert not np.array_equal(before, after)


def test_view_keys_change_the_camera(cube_session: Session) -> None:
    front, _, step = cube_session.shot()
    cube_session.key("4", r"view right")
    side, _, side_step = cube_session.shot()
    assert side_step == step  # paused: only the camera changed
    assert np.abs(side.astype(int) - front).sum() > 0.02 * front.size * 255
    cube_session.key("0", r"view first")  # back to the camera the window opened with
    again, _, _ = cube_session.shot()
    assert np.array_equal(again, front)


def test_layer_keys_toggle_layers(cube_session: Session) -> None:
    shown, _, _ = cube_session.shot()
    assert _cube_pixels(shown).mean() > 0.05
    cube_session.key("v", r"layer visual off")
    hidden, _, _ = cube_session.shot()
    assert not _cube_pixels(hidden).any()
    cube_session.key("b", r"layer behaviorModels on")
    dots, _, _ = cube_session.shot()
    near_behavior = np.abs(dots.astype(float) - BEHAVIOR).sum(axis=2) < 40
    assert near_behavior.sum() > 8 * 9  # eight DOFs, a few pixels each
    cube_session.key("b", r"layer behaviorModels off")
    cube_session.key("v", r"layer visual on")


def test_shift_drag_pulls_the_picked_dof_the_way_the_mouse_goes(cube_session: Session) -> None:
    cube_session.key("r", r"reset")
    before, _, _ = cube_session.shot()
    x, y = (int(c) for c in _centre(before))
    session = cube_session
    session.xdotool("mousemove", "--window", session.window, str(x), str(y))
    session.xdotool("keydown", "shift", "mousedown", "1")
    picked = session.wait(r"picked (\S+)\[(\d+)\] at \((\S+), (\S+), (\S+)\)")
    for dx in range(20, 141, 20):  # 140 pixels to the right, in a few moves
        session.xdotool("mousemove", "--window", session.window, str(x + dx), str(y))
    session.key("space", r"playing")
    elapsed = 0.0
    while elapsed < 1.0:  # a second of simulated time with the spring on
        pulled, elapsed, _ = session.shot()
    session.xdotool("mouseup", "1", "keyup", "shift")
    released = session.wait(r"released (\S+)\[(\d+)\] at \((\S+), (\S+), (\S+)\)")
    session.key("space", r"paused")
    assert released.group(1, 2) == picked.group(1, 2)
    assert float(released.group(3)) > float(picked.group(3)) + 0.3  # world x is the screen's right
    shift = _centre(pulled) - _centre(before)
    assert shift[0] > 25, shift


def test_recording_writes_an_mp4(cube_session: Session) -> None:
    cube_session.key("space", r"playing")
    started = cube_session.key("ctrl+s", r"recording (\S+\.mp4)")
    time.sleep(1.0)
    done = cube_session.key("ctrl+s", r"wrote (\S+\.mp4) \((\d+) frames\)")
    cube_session.key("space", r"paused")
    assert done.group(1) == started.group(1) and int(done.group(2)) > 0
    frames = list(iio.imiter(done.group(1)))
    assert len(frames) == int(done.group(2))
    assert frames[0].shape[:2] == (SIZE[1], SIZE[0])


def test_divergence_pauses_with_the_message_and_the_window_stays(display: str, tmp_path: Path) -> None:
    scene = tmp_path / "diverging.scn"
    scene.write_text(DIVERGING)
    session = Session(display, scene, tmp_path)
    try:
        session.wait(r"paused: SimulationDiverged: .*/bad/dofs")
        image, _, step = session.shot()  # still answering
        again, _, step_again = session.shot()
        assert step == step_again and np.array_equal(image, again)  # paused
        red = (image[..., 0] > 200) & (image[..., 1] < 140) & (image[..., 2] < 130)
        assert red.sum() > 50  # the message, in red, in the overlay
    finally:
        assert session.close() == 0


def test_without_a_display_it_says_so_and_points_to_render(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run(
        [sys.executable, "-m", "sofac", "view", str(CUBE)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 1
    assert "no display" in done.stderr and "sofac render" in done.stderr
    assert "Traceback" not in done.stderr


def test_an_unreachable_display_is_an_error_not_a_hang(tmp_path: Path) -> None:
    env = {**os.environ, "DISPLAY": ":4095"}
    env.pop("WAYLAND_DISPLAY", None)
    done = subprocess.run(
        [sys.executable, "-m", "sofac", "view", str(CUBE)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 1
    assert "GLFW cannot open one" in done.stderr and "sofac render" in done.stderr
    assert "Traceback" not in done.stderr


def test_sofac_view_returns_at_once_and_closes(display: str, tmp_path: Path) -> None:
    script = f"""
import time, sofac
sim = sofac.load({str(CUBE)!r}, interactive=True)
handle = sofac.view(sim, paused=True, width=200, height=150)
print("returned", handle.is_running, flush=True)
while handle.viewer.eye is None and handle.is_running:
    time.sleep(0.05)
handle.close()
print("closed", handle.is_running, sim.steps, flush=True)
"""
    env = {**os.environ, "DISPLAY": display}
    env.pop("WAYLAND_DISPLAY", None)
    done = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=TIMEOUT
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["returned", "True", "closed", "False", "0"]


# --- the geometry of the camera and the mouse, without a window -----------------------------------


def test_the_ray_through_a_pixel_passes_through_the_point_drawn_there() -> None:
    from sofac.viewer.window import ray

    camera = render.Camera(position=(1.0, 2.0, 5.0), look_at=(0.2, -0.1, 0.3), fov=50.0)
    points = np.array([[0.0, 0.0, 0.0], [0.5, -0.4, 1.0], [-0.7, 0.3, -0.2]])
    for point, (x, y) in zip(points, camera.project(points, *SIZE), strict=True):
        origin, direction = ray(camera, x, y, *SIZE)
        along = (point - origin) @ direction
        assert np.linalg.norm(origin + along * direction - point) < 1e-9


def test_a_ray_meets_the_nearest_triangle_it_crosses() -> None:
    from sofac.viewer.window import ray_hits

    square = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    two_layers = np.r_[square, square + np.array([0.0, 0.0, 2.0])]
    triangles = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    down = np.array([0.0, 0.0, -1.0])
    assert ray_hits(np.array([0.3, 0.6, 5.0]), down, two_layers, triangles) == pytest.approx(3.0)
    assert ray_hits(np.array([1.5, 0.5, 5.0]), down, two_layers, triangles) is None  # beside
    assert ray_hits(np.array([0.3, 0.6, 5.0]), -down, two_layers, triangles) is None  # behind


def test_orbiting_keeps_the_distance_and_a_full_turn_comes_back() -> None:
    from sofac.viewer.window import _Eye

    eye = _Eye(render.Camera(position=(0.0, 0.0, 4.0), look_at=(0.0, 1.0, 0.0)))
    start, distance = eye.position.copy(), eye.distance
    eye.orbit(0.3, 0.2)
    assert eye.distance == pytest.approx(distance) and not np.allclose(eye.position, start)
    eye.orbit(0.0, -0.2)
    for _ in range(4):
        eye.orbit(-0.3 / 4 + 2 * np.pi / 4, 0.0)
    np.testing.assert_allclose(eye.position, start, atol=1e-9)


def test_the_mouse_spring_is_sized_by_the_picked_dofs_mass() -> None:
    from sofac.viewer.window import _dof_mass

    sim = sofac.load(CUBE)
    velocity = sim["/cube/dofs"].velocity.copy()
    assert _dof_mass(sim, "/cube/dofs", 4) == pytest.approx(1.0 / 8)  # totalMass 1 over 8 DOFs
    assert np.array_equal(sim["/cube/dofs"].velocity, velocity)  # put back
