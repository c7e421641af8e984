"""Build hook: ship runtime/, templates/ and scenes/ inside the wheel.

All metadata lives in pyproject.toml. The three top-level folders are not Python packages, so
``package-data`` cannot reach them; this ``build_py`` copies them into the built package as
``sofac/_runtime``, ``sofac/_templates`` and ``sofac/_scenes``, where ``sofac.resources`` finds them.
An editable install skips the copy: there ``sofac.resources`` reads the folders of the checkout.
MANIFEST.in puts the same folders into the sdist, so a wheel built from the sdist has them too.
"""

from __future__ import annotations

import os
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent

# repository folder -> folder inside the built package
BUNDLED = {"runtime": "_runtime", "templates": "_templates", "scenes": "_scenes"}
_SKIP_DIRS = {"__pycache__", ".git", ".pytest_cache", ".ruff_cache"}
_SKIP_SUFFIXES = {".pyc", ".pyo", ".swp"}


def _bundled_files() -> list[tuple[Path, Path]]:
    """(source, destination relative to the sofac package) for every file to bundle."""
    pairs: list[tuple[Path, Path]] = []
    for source_name, target_name in BUNDLED.items():
        source_root = HERE / source_name
        if not source_root.is_dir():
            continue
        for dirpath, dirnames, filenames in os.walk(source_root):
            dirnames[:] = sorted(d for d in dirnames if d not in _SKIP_DIRS)
            for filename in sorted(filenames):
                source = Path(dirpath) / filename
                if source.suffix in _SKIP_SUFFIXES or not source.is_file():
                    continue
                pairs.append((source, Path(target_name) / source.relative_to(source_root)))
    return pairs


class BuildPyWithData(build_py):
    def _bundle_targets(self) -> list[tuple[Path, Path]]:
        package_dir = Path(self.build_lib, "sofac")
        return [(source, package_dir / relative) for source, relative in _bundled_files()]

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for source, target in self._bundle_targets():
            self.mkpath(str(target.parent))
            self.copy_file(str(source), str(target), preserve_mode=True)

    def get_outputs(self, include_bytecode: bool = True) -> list[str]:
        outputs = list(super().get_outputs(include_bytecode))
        if not getattr(self, "editable_mode", False):
            outputs.extend(str(target) for _, target in self._bundle_targets())
        return outputs


setup(cmdclass={"build_py": BuildPyWithData})
