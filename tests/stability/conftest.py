"""Fixtures of the stability suite: one compile per distinct scene text for the whole session."""

from __future__ import annotations

from pathlib import Path

import pytest

from .scenes import Scenes


@pytest.fixture(scope="session")
def scenes(tmp_path_factory: pytest.TempPathFactory, compile_cache: Path) -> Scenes:
    return Scenes(tmp_path_factory.mktemp("stability-scenes"))
