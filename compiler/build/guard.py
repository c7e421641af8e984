"""Run the C++ compiler so that it never outlives sofac.

``g++`` forks ``cc1plus`` and ``as``: killing sofac (even with ``kill -9``) must end all of them.
The compiler runs in a process group of its own under a small guard process (this file, run as a
script: it imports nothing from sofac). On Linux the guard asks the kernel for SIGTERM when its
parent dies (``PR_SET_PDEATHSIG``), and on SIGTERM or SIGINT it kills the compiler's whole group
before exiting. ``run()`` is the parent's side: the same result as ``subprocess.run``, and on a
timeout or an interruption it ends the guard the same way.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

_PR_SET_PDEATHSIG = 1


def run(arguments: Sequence[str], *, cwd: Path, timeout: float) -> subprocess.CompletedProcess[str]:
    """``arguments`` run in ``cwd`` under the guard; raises subprocess.TimeoutExpired or OSError as
    subprocess.run does."""
    command = [sys.executable, "-I", "-S", __file__, str(os.getpid()), *arguments]
    with subprocess.Popen(
        command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    ) as guard:
        try:
            out, err = guard.communicate(timeout=timeout)
        except BaseException:
            guard.terminate()  # the guard ends the compiler's group, then itself
            guard.communicate()
            raise
    return subprocess.CompletedProcess(list(arguments), guard.returncode, out, err)


def _guard(parent: int, arguments: list[str]) -> int:
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
        if os.getppid() != parent:  # the parent died before the request took effect
            return 128 + signal.SIGTERM
    started: list[subprocess.Popen[bytes]] = []

    def end(signum: int, _frame: object) -> None:
        for compiler in started:  # no wait(): the main thread may hold Popen's wait lock
            with contextlib.suppress(ProcessLookupError):
                os.killpg(compiler.pid, signal.SIGKILL)
        os._exit(128 + signum)

    signal.signal(signal.SIGTERM, end)  # before the compiler starts: no window without them
    signal.signal(signal.SIGINT, end)
    started.append(subprocess.Popen(arguments, start_new_session=True))
    return started[0].wait()


if __name__ == "__main__":
    sys.exit(_guard(int(sys.argv[1]), sys.argv[2:]))
