"""The documentation's examples run: every ```python and ```sh block of README.md and docs/*.md,
page by page, in order, unless the line before its fence is an HTML comment ``<!-- not run: why -->``
(a synopsis with placeholders, a window that needs a display).

A page's Python blocks share one namespace; its shell blocks run under ``bash -euo pipefail`` with
``sofac`` meaning this interpreter's ``python -m sofac``. Both run in a scratch folder holding
links to the repository's ``scenes/`` and ``examples/``, so what a page writes (``out/...``) stays
out of the checkout. A failing block is reported with the page and the block's first line.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"^(<!-- not run[^\n]*-->\n)?```(python|sh)\n(.*?)^```", re.S | re.M)
SHELL_PRELUDE = 'set -euo pipefail\nsofac() { "$SOFAC_DOCS_PYTHON" -m sofac "$@"; }\n'


def runnable_blocks(page: Path) -> list[tuple[str, str, int]]:
    """(language, code, line of its first code line) of each block of ``page`` that runs."""
    text = page.read_text(encoding="utf-8")
    found = []
    for match in BLOCK.finditer(text):
        if match.group(1):
            continue
        first_line = text.count("\n", 0, match.start(3)) + 1
        found.append((match.group(2), match.group(3), first_line))
    return found


ALL_PAGES = (ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")))
PAGES = [page for page in ALL_PAGES if runnable_blocks(page)]


def test_the_pages_that_must_have_examples_have_them() -> None:
    names = {page.name for page in PAGES}
    assert {"README.md", "tutorial.md", "running.md"} <= names
    assert len(runnable_blocks(ROOT / "docs" / "tutorial.md")) >= 11


def test_a_not_run_marker_skips_only_its_own_block(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    fence = "```"
    page.write_text(
        f"{fence}python\na = 1\n{fence}\n<!-- not run: synopsis -->\n{fence}sh\nsofac X\n{fence}\n"
        f"{fence}sh\necho\n{fence}\n"
    )
    assert runnable_blocks(page) == [("python", "a = 1\n", 2), ("sh", "echo\n", 9)]


@pytest.mark.parametrize("page", PAGES, ids=[page.name for page in PAGES])
def test_the_page_examples_run(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for folder in ("scenes", "examples"):
        (tmp_path / folder).symlink_to(ROOT / folder)
    monkeypatch.chdir(tmp_path)
    environment = {**os.environ, "SOFAC_DOCS_PYTHON": sys.executable}
    namespace: dict[str, object] = {"__name__": "__docs__"}
    shown = page.relative_to(ROOT)
    for language, code, line in runnable_blocks(page):
        if language == "python":
            # Blank lines in front: a traceback names the page's own line numbers.
            exec(compile("\n" * (line - 1) + code, str(shown), "exec"), namespace)
            continue
        script = SHELL_PRELUDE + code
        result = subprocess.run(
            ["bash", "-c", script], cwd=tmp_path, env=environment, capture_output=True, text=True, check=False
        )
        assert result.returncode == 0, f"{shown}:{line}: shell block failed:\n{result.stdout}{result.stderr}"
