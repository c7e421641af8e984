"""Shared pytest fixtures: where the team's shared material (the SOFA scene corpus) lives."""

from __future__ import annotations

import os
from pathlib import Path

import pytest


def find_shared() -> Path | None:
    """``../shared`` next to the repository, else ``$SOFAC_SHARED``; None if neither has the corpus."""
    candidates = [Path(__file__).resolve().parents[2] / "shared"]
    if os.environ.get("SOFAC_SHARED"):
        candidates.append(Path(os.environ["SOFAC_SHARED"]))
    for candidate in candidates:
        if (candidate / "corpus" / "sofa").is_dir():
            return candidate
    return None


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    shared = find_shared()
    if shared is None:
        pytest.skip("shared/ (SOFA scene corpus) not available; set SOFAC_SHARED")
    return shared


@pytest.fixture(scope="session")
def corpus_dir(shared_dir: Path) -> Path:
    """``shared/corpus/sofa``: real SOFA scenes with every file they reference."""
    return shared_dir / "corpus" / "sofa"


@pytest.fixture(scope="session", autouse=True)
def compile_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One compile cache for the whole test session (each scene compiles once), away from the user's."""
    if os.environ.get("SOFAC_TEST_CACHE"):
        folder = Path(os.environ["SOFAC_TEST_CACHE"])
    elif os.environ.get("PYTEST_XDIST_WORKER"):
        # pytest-xdist: the workers share one cache (builds take a file lock), so that a scene two
        # workers load still compiles once; their base temporary folders are siblings.
        folder = tmp_path_factory.getbasetemp().parent / "sofac-cache"
        folder.mkdir(exist_ok=True)
    else:
        folder = tmp_path_factory.mktemp("sofac-cache")
    os.environ["SOFAC_CACHE_DIR"] = str(folder)
    return folder


LONG_SUITE = os.environ.get("SOFAC_LONG") == "1"


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "long: a slow test (long regression runs, many compiled scenes); runs only with SOFAC_LONG=1 "
        "(scripts/test-long.sh), CI runs a representative part",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if LONG_SUITE:
        return
    skip = pytest.mark.skip(reason="long suite: run with SOFAC_LONG=1 (scripts/test-long.sh)")
    for item in items:
        if "long" in item.keywords:
            item.add_marker(skip)
