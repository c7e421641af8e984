"""Property tests: mutated corpus scenes only ever produce diagnostics, never an exception.

Each example takes one scene of :data:`SAMPLE` (real SOFA scenes from ``shared/corpus/sofa``),
applies a mutation to its text (delete an attribute, swap a template, corrupt a number, truncate
the file, duplicate a component, misspell a component), writes it to a temporary folder and checks
it with the corpus and the scene's own folder as data roots, so its includes, macros and meshes are
still found. Whatever the mutation, :func:`sofac.check.checker.check_file` must return normally and every
diagnostic must name a file, a line that exists in that file, and a code from ``CODES``.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from sofac.check.checker import check_file
from sofac.diagnostics import CODES, Diagnostics

pytest.importorskip("hypothesis")
from hypothesis import given, settings
from hypothesis import strategies as st

# A fixed sample of the corpus, chosen by hand to cover its kinds of files.
SAMPLE = (
    # with <include> or unknown-tag macros (Objects/*.xml)
    "Demos/chainHybrid.scn",
    "Component/Visual/DirectionalLight.scn",
    "Benchmark/Analysis/constantMomentum.scn",
    "Component/LinearSolver/Direct/FEMBAR_SparseLDLSolver.scn",
    "Component/Topology/Container/Grid/SparseGridTopology.scn",
    # not well-formed XML that SOFA (and sofac, with W105) accepts
    "Component/MechanicalLoad/EllipsoidForceField.scn",
    "Component/Visual/RecordedCamera.scn",
    "Demos/fallingBeamAugmentedLagrangianCollision.scn",
    # plain scenes: meshes, BoxROI, springs, FEM, rigid frames, mappings, a test .xml
    "Demos/liver.scn",
    "Component/Engine/Select/BoxROI_1d.scn",
    "Component/SolidMechanics/Spring/StiffSpringForceField.scn",
    "Component/SolidMechanics/FEM/TetrahedronFEMForceField.scn",
    "Component/SolidMechanics/Spring/JointSpringForceField.scn",
    "Component/Mapping/NonLinear/RigidMapping-basic.scn",
    "Sofa/Component/ODESolver/Backward/tests/scenes/EulerImplicitSpringDynamicTest.xml",
)

# 25 per test keeps the file fast in CI; SOFAC_MUTATION_EXAMPLES=1000 searches harder locally.
MAX_EXAMPLES = int(os.environ.get("SOFAC_MUTATION_EXAMPLES", "25"))
TEMPLATES = ("Vec3d", "Rigid3d", "Vec2d", "Vec3", "Rigid3", "Vec1d", "Vec6d", "Rigid2d", "Bogus", "")
BAD_NUMBERS = ("nan", "inf", "-inf", "abc", "1e400", "-1", "0", "-0", "1e-400", "", "1,5", "0x10", "9" * 40)

_ATTRIBUTE = re.compile(r"""\s[A-Za-z_][\w.:-]*\s*=\s*(?:"[^"]*"|'[^']*')""")
_TEMPLATE_VALUE = re.compile(r"""(\btemplate\s*=\s*)(?:"[^"]*"|'[^']*')""")
_NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![\w.])")
_START_TAG = re.compile(r"<([A-Za-z_][\w]*)\b")
_EMPTY_ELEMENT = re.compile(r"<(?!Node\b)[A-Za-z_]\w*\b[^<>]*/>")


# --- mutations: each takes the text and a draw function, returns the mutated text ------------------

Draw = Callable[[st.SearchStrategy[Any]], Any]


def _pick(draw: Draw, matches: list[re.Match[str]]) -> re.Match[str] | None:
    if not matches:
        return None
    return matches[int(draw(st.integers(0, len(matches) - 1)))]


def delete_attribute(text: str, draw: Draw) -> str:
    found = _pick(draw, list(_ATTRIBUTE.finditer(text)))
    return text if found is None else text[: found.start()] + text[found.end() :]


def swap_template(text: str, draw: Draw) -> str:
    template = draw(st.sampled_from(TEMPLATES))
    found = _pick(draw, list(_TEMPLATE_VALUE.finditer(text)))
    if found is not None:
        return f'{text[: found.start()]}{found.group(1)}"{template}"{text[found.end() :]}'
    # No template= written: add one to some component.
    tag = _pick(draw, [m for m in _START_TAG.finditer(text) if m.group(1) != "Node"])
    if tag is None:
        return text
    return f'{text[: tag.end()]} template="{template}"{text[tag.end() :]}'


def corrupt_number(text: str, draw: Draw) -> str:
    found = _pick(draw, list(_NUMBER.finditer(text)))
    if found is None:
        return text
    return text[: found.start()] + str(draw(st.sampled_from(BAD_NUMBERS))) + text[found.end() :]


def duplicate_component(text: str, draw: Draw) -> str:
    found = _pick(draw, list(_EMPTY_ELEMENT.finditer(text)))
    if found is None:
        return text
    return text[: found.end()] + "\n" + found.group(0) + text[found.end() :]


def misspell_component(text: str, draw: Draw) -> str:
    found = _pick(draw, [m for m in _START_TAG.finditer(text) if m.group(1) != "Node"])
    if found is None:
        return text
    name = found.group(1)
    at = int(draw(st.integers(0, len(name) - 1)))
    how = draw(st.sampled_from(("swap", "drop", "double", "case")))
    if how == "swap" and at + 1 < len(name):
        wrong = name[:at] + name[at + 1] + name[at] + name[at + 2 :]
    elif how == "drop" and len(name) > 1:
        wrong = name[:at] + name[at + 1 :]
    elif how == "case":
        wrong = name.swapcase()
    else:
        wrong = name[: at + 1] + name[at:]
    # The closing tag of a non-empty element must follow, or the file is no longer XML (also fine).
    return text[: found.start(1)] + wrong + text[found.end(1) :]


MUTATIONS: dict[str, Callable[[str, Draw], str]] = {
    "delete_attribute": delete_attribute,
    "swap_template": swap_template,
    "corrupt_number": corrupt_number,
    "duplicate_component": duplicate_component,
    "misspell_component": misspell_component,
}


# --- the property ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("mutations")


def _line_count(path: Path) -> int:
    data = path.read_bytes().replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    return data.count(b"\n") + (1 if data and not data.endswith(b"\n") else 0)


def check_only_diagnostics(data: bytes, original: Path, corpus_dir: Path, workdir: Path) -> Diagnostics:
    """Check mutated scene bytes; assert that only well-formed diagnostics come out."""
    scene = workdir / original.name
    scene.write_bytes(data)
    _, diags = check_file(scene, data_roots=[original.parent, corpus_dir])  # must not raise
    lines: dict[str, int] = {}
    for diag in diags:
        assert diag.code in CODES, diag
        assert diag.loc.file, diag
        named = Path(diag.loc.file)
        assert named.is_file(), diag
        if diag.loc.file not in lines:
            lines[diag.loc.file] = _line_count(named)
        assert 1 <= diag.loc.line <= max(lines[diag.loc.file], 1), (str(diag), lines[diag.loc.file])
        assert diag.message, diag
    return diags


@pytest.fixture(scope="module")
def sample(corpus_dir: Path) -> list[Path]:
    paths = [corpus_dir / name for name in SAMPLE]
    missing = [str(p) for p in paths if not p.is_file()]
    assert not missing, f"corpus files of the sample are missing: {missing}"
    return paths


def test_sample_covers_includes_and_repaired_xml(sample: list[Path], corpus_dir: Path, workdir: Path) -> None:
    """The sample has scenes with includes and not-well-formed ones; unmutated copies check as
    the originals do (so the data roots given to the mutated copies are right)."""
    with_includes = repaired = 0
    for path in sample:
        checked, original = check_file(path)
        copied = check_only_diagnostics(path.read_bytes(), path, corpus_dir, workdir)
        assert sorted(d.code for d in copied) == sorted(d.code for d in original), path
        with_includes += checked is not None and len(checked.scene.sources) > 1
        repaired += any(d.code == "W105" for d in original)
    assert with_includes >= 4 and repaired >= 3


_settings = settings(max_examples=MAX_EXAMPLES, deadline=None)


@pytest.mark.parametrize("mutation", sorted(MUTATIONS))
@_settings
@given(data=st.data())
def test_mutated_scene_gives_only_diagnostics(
    mutation: str, data: st.DataObject, sample: list[Path], corpus_dir: Path, workdir: Path
) -> None:
    original = data.draw(st.sampled_from(sample), label="scene")
    text = original.read_text(encoding="utf-8", errors="surrogateescape")
    mutated = MUTATIONS[mutation](text, data.draw)
    check_only_diagnostics(mutated.encode("utf-8", errors="surrogateescape"), original, corpus_dir, workdir)


@_settings
@given(data=st.data())
def test_truncated_scene_gives_only_diagnostics(
    data: st.DataObject, sample: list[Path], corpus_dir: Path, workdir: Path
) -> None:
    original = data.draw(st.sampled_from(sample), label="scene")
    raw = original.read_bytes()
    cut = data.draw(st.integers(0, len(raw)), label="cut")
    diags = check_only_diagnostics(raw[:cut], original, corpus_dir, workdir)
    if cut < len(raw.rstrip()):
        # Cutting before the closing tag of the root always leaves unfinished XML.
        assert diags.has_errors()


@_settings
@given(data=st.data())
def test_several_mutations_give_only_diagnostics(
    data: st.DataObject, sample: list[Path], corpus_dir: Path, workdir: Path
) -> None:
    original = data.draw(st.sampled_from(sample), label="scene")
    text = original.read_text(encoding="utf-8", errors="surrogateescape")
    for name in data.draw(
        st.lists(st.sampled_from(sorted(MUTATIONS)), min_size=2, max_size=5), label="steps"
    ):
        text = MUTATIONS[name](text, data.draw)
    check_only_diagnostics(text.encode("utf-8", errors="surrogateescape"), original, corpus_dir, workdir)
