"""Packaging: runtime/, templates/ and scenes/ reach a built wheel, and sofac.resources finds them."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest
import sofac
from sofac import resources

REPO = Path(__file__).resolve().parents[1]
BUNDLED = {"runtime": "_runtime", "templates": "_templates", "scenes": "_scenes"}
_IGNORE_ANYWHERE = shutil.ignore_patterns(
    ".git", "*.egg-info", "__pycache__", "*.pyc", ".pytest_cache", ".ruff_cache", ".hypothesis", ".venv",
    "venv",
)  # fmt: skip
_IGNORE_AT_TOP = {"build", "dist", "out", ".pkg"}  # build outputs; compiler/build/ is a package


def _ignore(folder: str, names: list[str]) -> set[str]:
    ignored = set(_IGNORE_ANYWHERE(folder, names))
    if Path(folder) == REPO:
        ignored |= _IGNORE_AT_TOP & set(names)
    return ignored


# --- editable install (this checkout) ------------------------------------------------------------


def test_resources_resolve_in_the_checkout() -> None:
    assert Path(sofac.__file__).resolve().parent == REPO / "compiler", "tests expect the editable install"
    assert resources.runtime_dir() == REPO / "runtime"
    assert resources.templates_dir() == REPO / "templates"
    assert resources.scenes_dir() == REPO / "scenes"
    assert (resources.runtime_dir() / "sofac" / "version.h").is_file()


def test_packaged_location_is_looked_up_first() -> None:
    places = resources.candidates("runtime")
    assert places == [REPO / "compiler" / "_runtime", REPO / "runtime"]


def test_runtime_version_matches_package_version() -> None:
    header = (resources.runtime_dir() / "sofac" / "version.h").read_text()
    match = re.search(r'#define SOFAC_RUNTIME_VERSION "([^"]+)"', header)
    assert match and match.group(1) == sofac.__version__
    parts = {
        key: int(value) for key, value in re.findall(r"#define SOFAC_RUNTIME_VERSION_(\w+) (\d+)", header)
    }
    assert f"{parts['MAJOR']}.{parts['MINOR']}.{parts['PATCH']}" == sofac.__version__


def test_bundled_scene_lookup(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "a.scn").write_text("<Node/>")
    (tmp_path / "b.scn").write_text("<Node/>")
    monkeypatch.setattr(resources, "scenes_dir", lambda: tmp_path)
    assert resources.bundled_scene("b") == (tmp_path / "b.scn").resolve()
    assert resources.bundled_scene("sub/a.scn") == (tmp_path / "sub" / "a.scn").resolve()
    assert resources.bundled_scenes() == [tmp_path / "b.scn", tmp_path / "sub" / "a.scn"]
    with pytest.raises(FileNotFoundError, match=r"b\.scn"):
        resources.bundled_scene("missing")
    with pytest.raises(ValueError, match="outside"):
        resources.bundled_scene("../escape.scn")


def test_missing_resource_says_what_to_do(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(resources, "candidates", lambda name: [tmp_path / "nowhere"])
    with pytest.raises(resources.ResourceNotFoundError, match="reinstall"):
        resources.runtime_dir()


# --- built wheel ---------------------------------------------------------------------------------


def _require_wheel_builder() -> None:
    import setuptools

    version = tuple(int(x) for x in re.findall(r"\d+", setuptools.__version__)[:2])
    if importlib.util.find_spec("wheel") is None and version < (70, 1):
        pytest.fail("building a wheel needs the 'wheel' package: run `bash scripts/setup.sh`")


def _offline_env() -> dict[str, str]:
    env = dict(os.environ)
    env["PIP_NO_INDEX"] = "1"  # the build must not need the network
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


def _build_wheel(source: Path, out: Path) -> Path:
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(source), "--no-deps", "--no-build-isolation", "-q",
         "-w", str(out)],
        check=True, env=_offline_env(), capture_output=True, text=True,
    )  # fmt: skip
    (wheel,) = out.glob("sofac-*.whl")
    return wheel


def _expected_members(source: Path) -> set[str]:
    members = set()
    for folder, packaged in BUNDLED.items():
        for path in (source / folder).rglob("*"):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc":
                members.add(f"sofac/{packaged}/{path.relative_to(source / folder).as_posix()}")
    return members


@pytest.fixture(scope="module")
def source_copy(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the checkout with a nested probe scene, so the test does not depend on scenes/."""
    source = tmp_path_factory.mktemp("src") / "sofac"
    shutil.copytree(REPO, source, ignore=_ignore)
    probe = source / "scenes" / "probe_dir" / "probe.scn"
    probe.parent.mkdir(parents=True, exist_ok=True)
    probe.write_text('<Node name="root"/>\n')
    return source


@pytest.fixture(scope="module")
def built_wheel(source_copy: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    _require_wheel_builder()
    return _build_wheel(source_copy, tmp_path_factory.mktemp("dist"))


def test_wheel_contains_runtime_templates_and_scenes(built_wheel: Path, source_copy: Path) -> None:
    names = set(zipfile.ZipFile(built_wheel).namelist())
    assert "sofac/_runtime/sofac/version.h" in names
    assert "sofac/_templates/README.md" in names
    assert "sofac/_scenes/probe_dir/probe.scn" in names
    expected = _expected_members(source_copy)
    assert expected <= names, sorted(expected - names)
    for packaged in BUNDLED.values():
        assert not any(n.startswith(f"sofac/{packaged}/") and "__pycache__" in n for n in names)
    # the package itself and the console script
    assert {"sofac/cli/main.py", "sofac/cli/report.py", "sofac/resources.py", "sofac/__main__.py"} <= names
    # every stage and tool package, and each of their modules
    package = REPO / "compiler"
    modules = {f"sofac/{p.relative_to(package).as_posix()}" for p in package.rglob("*.py")}
    assert modules <= names, sorted(modules - names)
    assert "sofac/registry/sofa_catalog.json" in names  # SOFA's list of components (package data)
    entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    assert "sofac = sofac.cli.main:main" in zipfile.ZipFile(built_wheel).read(entry_points).decode()


def test_resources_resolve_from_the_installed_wheel(built_wheel: Path, tmp_path: Path) -> None:
    target = tmp_path / "site"
    with zipfile.ZipFile(built_wheel) as archive:
        archive.extractall(target)  # a wheel is installed by unpacking it (no dependencies needed here)
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]);"
        "from sofac import resources as r;"
        "print(r.runtime_dir()); print(r.templates_dir()); print(r.scenes_dir());"
        "print(r.bundled_scene('probe_dir/probe'))"
    )
    # -S: no site-packages, so the editable install of the checkout cannot shadow the wheel.
    result = subprocess.run(
        [sys.executable, "-S", "-c", code, str(target)], capture_output=True, text=True, check=True
    )
    lines = result.stdout.splitlines()
    package = target.resolve() / "sofac"
    assert [Path(line).resolve() for line in lines] == [
        package / "_runtime",
        package / "_templates",
        package / "_scenes",
        package / "_scenes" / "probe_dir" / "probe.scn",
    ]


def test_sdist_carries_the_folders_and_builds_the_same_wheel(source_copy: Path, tmp_path: Path) -> None:
    _require_wheel_builder()
    dist = tmp_path / "sdist"
    code = "import sys, setuptools.build_meta as b; b.build_sdist(sys.argv[1])"
    subprocess.run(
        [sys.executable, "-c", code, str(dist)],
        cwd=source_copy, check=True, capture_output=True, text=True, env=_offline_env(),
    )  # fmt: skip
    (sdist,) = dist.glob("sofac-*.tar.gz")
    with tarfile.open(sdist) as archive:
        names = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
        if hasattr(tarfile, "data_filter"):
            archive.extractall(tmp_path / "unpacked", filter="data")
        else:  # Python < 3.10.12 / 3.11.4; the archive is our own
            archive.extractall(tmp_path / "unpacked")
    for required in ("setup.py", "MANIFEST.in", "runtime/sofac/version.h", "templates/README.md",
                     "scenes/probe_dir/probe.scn"):  # fmt: skip
        assert required in names
    (root,) = (tmp_path / "unpacked").iterdir()
    wheel = _build_wheel(root, tmp_path / "wheel")
    wheel_names = set(zipfile.ZipFile(wheel).namelist())
    assert _expected_members(source_copy) <= wheel_names
