"""Long runs that say where they are: ``sofac run``'s progress bar and its Ctrl-C report.

The steps are run in slices sized to last about a fifth of a second each (measured as they run),
so that the bar moves at least every second whatever a step costs, and so that Ctrl-C is taken
between two slices: the simulation is then at a whole step, which the report names. Slicing does
not change the numbers: a step depends on the state only, not on how steps are grouped in calls.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import TextIO

SLICE_SECONDS = 0.2  # the wall time a slice of steps aims at
SHOW_AFTER = 1.0  # a run shorter than this draws no bar


class Slicer:
    """Slice sizes that last about SLICE_SECONDS each, from the time the previous ones took."""

    def __init__(self, limit: int = 100_000) -> None:
        self.size = 1
        self.limit = limit

    def next(self, remaining: int) -> int:
        return max(1, min(self.size, remaining))

    def took(self, steps: int, seconds: float) -> None:
        if seconds <= 0:
            self.size = min(self.limit, self.size * 4)
            return
        wanted = int(steps * SLICE_SECONDS / seconds)
        self.size = max(1, min(self.limit, wanted, self.size * 4))  # grow gradually


def _duration(seconds: float) -> str:
    seconds = max(0, round(seconds))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}h{minutes:02d}m" if hours else f"{minutes}m{secs:02d}s" if minutes else f"{secs}s"


class StepBar:
    """One line on a terminal: steps, simulated time, ms/step, real-time factor, ETA."""

    def __init__(self, total: int, enabled: bool, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stderr
        self.total = total
        self.enabled = enabled and self.stream.isatty()
        self.started = time.perf_counter()
        self.drawn = False

    def line(self, done: int, sim_time: float, start_time: float) -> str:
        elapsed = time.perf_counter() - self.started
        per_step = elapsed / done if done else 0.0
        simulated = sim_time - start_time
        factor = f"{simulated / elapsed:.3g}x real time" if elapsed > 0 else ""
        eta = _duration(per_step * (self.total - done))
        share = 100.0 * done / self.total if self.total else 100.0
        return (
            f"step {done}/{self.total} ({share:.0f}%) t={sim_time:.6g} {per_step * 1e3:.4g} ms/step "
            f"{factor} ETA {eta}"
        )

    def update(self, done: int, sim_time: float, start_time: float) -> None:
        if not self.enabled or time.perf_counter() - self.started < SHOW_AFTER:
            return
        self.stream.write("\r" + self.line(done, sim_time, start_time)[:110].ljust(110))
        self.stream.flush()
        self.drawn = True

    def close(self) -> None:
        if self.drawn:
            self.stream.write("\r" + " " * 110 + "\r")
            self.stream.flush()


@contextlib.contextmanager
def deferred_interrupt() -> Iterator[threading.Event]:
    """Ctrl-C sets the event instead of raising, so the run stops between two slices (main
    thread only: elsewhere the event is never set and Ctrl-C keeps its usual effect)."""
    event = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield event
        return
    previous = signal.signal(signal.SIGINT, lambda _signum, _frame: event.set())
    try:
        yield event
    finally:
        signal.signal(signal.SIGINT, previous)


def run_in_slices(
    step: Callable[[int], None],
    steps: int,
    *,
    now: Callable[[], float],
    bar: StepBar,
    stop: threading.Event,
) -> int:
    """Call ``step(k)`` until ``steps`` steps are done or ``stop`` is set; returns the steps done.
    ``now()`` is the simulation time, for the bar."""
    slicer = Slicer()
    start_time = now()
    done = 0
    while done < steps and not stop.is_set():
        count = slicer.next(steps - done)
        began = time.perf_counter()
        step(count)
        slicer.took(count, time.perf_counter() - began)
        done += count
        bar.update(done, now(), start_time)
    bar.close()
    return done
