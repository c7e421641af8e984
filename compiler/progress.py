"""A progress bar on stderr for commands that run many simulations (accuracy, sweep)."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO


class Progress:
    """A progress bar on stderr: tqdm when installed, else a line rewritten in place (a line per
    configuration when stderr is not a terminal)."""

    def __init__(self, total: int, enabled: bool, stream: TextIO | None = None) -> None:
        self.total = total
        self.done = 0
        self.enabled = enabled
        self.stream = stream or sys.stderr
        self.started = time.perf_counter()
        self._tqdm: Any = None
        if enabled:
            try:
                from tqdm import tqdm  # type: ignore[import-untyped]
            except ImportError:
                pass
            else:
                self._tqdm = tqdm(total=total, file=self.stream, unit="run", leave=False)

    def start(self, label: str) -> None:
        if not self.enabled:
            return
        if self._tqdm is not None:
            self._tqdm.set_description(label)
        elif self.stream.isatty():
            self._draw(label)

    def advance(self, label: str) -> None:
        self.done += 1
        if not self.enabled:
            return
        if self._tqdm is not None:
            self._tqdm.update(1)
        elif self.stream.isatty():
            self._draw(label)
        else:
            print(f"  [{self.done}/{self.total}] {label}", file=self.stream, flush=True)

    def _draw(self, label: str) -> None:
        width = 24
        filled = round(width * self.done / self.total) if self.total else width
        elapsed = time.perf_counter() - self.started
        bar = "#" * filled + "." * (width - filled)
        text = f"\r[{bar}] {self.done}/{self.total} {elapsed:5.0f}s {label}"
        self.stream.write(f"{text[:100]:<100}")
        self.stream.flush()

    def close(self) -> None:
        if not self.enabled:
            return
        if self._tqdm is not None:
            self._tqdm.close()
        elif self.stream.isatty():
            self.stream.write("\r" + " " * 100 + "\r")
            self.stream.flush()
