"""WriteState files: format, round trips, SOFA's time stamps and K numbering, the recorder."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest
from fakesim import FakeInfo, FallingSim, two_body_sim
from sofac.diagnostics import Diagnostics
from sofac.front.parse import parse_scene
from sofac.regress.states import (
    StateBlock,
    StateFileError,
    StateRecorder,
    dumps,
    export_states,
    format_block,
    format_number,
    parse_state_text,
    read_state_file,
    recorded_steps,
    round_as_printed,
    select_states,
    state_file_name,
    write_state_file,
)
from sofac.regress.suite import parse_regression_list, reference_files


@pytest.fixture(scope="session")
def regression_dir(shared_dir: Path) -> Path:
    return shared_dir / "reference" / "sofa-regression"


# --- format ---------------------------------------------------------------------------------------


def test_block_layout_is_sofas() -> None:
    text = format_block(
        0.002, np.array([[0.0, 0.0, 0.0], [1.0, -3e-05, 0.0]]), np.array([[0, 0, 0], [0, -0.02, 0]])
    )
    assert text == "T= 0.002\n  X= 0 0 0 1 -3.0000000000000001e-05 0\n  V= 0 0 0 0 -0.02 0\n"
    assert format_block(0.0, np.zeros((1, 3)), None, precision=6) == "T= 0\n  X= 0 0 0\n"
    # Rigid3d: 7 scalars per DOF, in one line.
    assert format_block(1.0, np.array([[2, 0, 0, 0, 0, 0, 1]]), None) == "T= 1\n  X= 2 0 0 0 0 0 1\n"


def test_numbers_print_as_cpp_streams() -> None:
    assert format_number(0.1 + 0.2) == "0.30000000000000004"
    assert format_number(0.0030000000000000001) == "0.0030000000000000001"
    assert format_number(1.0000000000000007) == "1.0000000000000007"
    assert format_number(2999 * 1e-5, 6) == "0.02999"
    assert format_number(-0.0) == "-0"
    assert format_number(1e-5, 6) == "1e-05"
    assert list(round_as_printed(np.array([1.2345678, -2.22e-16, 123456789.0]))) == [
        1.23457,
        -2.22e-16,
        123457000.0,
    ]


def test_round_trip_plain_and_gzip(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    blocks = [
        StateBlock(
            t, {"X": rng.normal(size=21) * 10.0 ** rng.integers(-20, 20, 21), "V": rng.normal(size=18)}
        )
        for t in (0.0, 0.1 + 0.2, 1e-17, 12345.678)
    ]
    blocks.append(StateBlock(2.0, {"X": np.array([np.inf, -np.inf, 0.0])}))  # no V, non-finite values
    for name in ("state.txt", "state.txt.gz"):
        path = write_state_file(tmp_path / name, blocks)
        again = read_state_file(path)
        assert [b.time for b in again] == [b.time for b in blocks]
        for ours, theirs in zip(again, blocks, strict=True):
            assert ours.vectors.keys() == theirs.vectors.keys()
            for key in ours.vectors:
                assert np.array_equal(ours.vectors[key], theirs.vectors[key])  # bit for bit
    assert (tmp_path / "state.txt").read_text().startswith("T= 0\n  X= ")
    assert gzip.decompress((tmp_path / "state.txt.gz").read_bytes()) == (tmp_path / "state.txt").read_bytes()


def test_sofa_full_precision_files_round_trip_to_the_byte(shared_dir: Path) -> None:
    # Our reference build's WriteState output (17 digits): parse + print gives SOFA's exact text.
    files = sorted((shared_dir / "reference" / "sofa" / "data" / "writestate").glob("*.gz"))
    assert files
    for path in files:
        assert dumps(read_state_file(path), 17) == gzip.decompress(path.read_bytes()).decode()


def test_every_regression_reference_reads(regression_dir: Path) -> None:
    states = sorted(regression_dir.rglob("*_mstate.txt.gz"))
    assert len(states) == 215
    for path in states:
        blocks = read_state_file(path)
        assert blocks and blocks[0].time == 0.0
        sizes = {b.x.size for b in blocks if b.x is not None}
        assert len(sizes) == 1, path
        # 6 significant digits as SOFA prints them: printing again gives the file's exact text.
        assert dumps(blocks, 6) == gzip.decompress(path.read_bytes()).decode(), path
    # The other .gz files are WriteTopology output (not states), three of them truncated: both
    # are refused with a clear error, never a crash.
    others = sorted(set(regression_dir.rglob("*.gz")) - set(states))
    assert others and all(p.name.endswith("_topology.txt.gz") for p in others)
    messages = []
    for path in others:
        with pytest.raises(StateFileError) as info:
            read_state_file(path)
        messages.append(str(info.value))
    assert sum("truncated gzip" in m for m in messages) == 3
    assert sum("not a WriteState line" in m for m in messages) == len(others) - 3


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("  X= 1 2 3\n", "before the first"),
        ("T= 0\n  X= 1 2 x\n", "not a number"),
        ("T= 0 1\n", "exactly one time"),
        ("T= 0\n  X= 1\n  X= 2\n", "given twice"),
        ("T= 0\n  Edges= 0\n", "not a WriteState line"),
    ],
)
def test_malformed_text_is_refused(text: str, message: str) -> None:
    with pytest.raises(StateFileError, match=message):
        parse_state_text(text)


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(StateFileError, match="cannot read"):
        read_state_file(tmp_path / "missing.txt.gz")
    (tmp_path / "bad.txt.gz").write_bytes(b"not gzip at all")
    with pytest.raises(StateFileError, match="gzip"):
        read_state_file(tmp_path / "bad.txt.gz")


# --- time stamps ---------------------------------------------------------------------------------


def test_recorded_steps_follow_writestate() -> None:
    assert recorded_steps(5) == [0, 1, 2, 3, 4]  # the state after the 5th step is not written
    assert recorded_steps(10, every=4) == [0, 4, 8]
    assert recorded_steps(3000, last_only=True) == [0, 2999]
    assert recorded_steps(1, last_only=True) == [0]
    assert recorded_steps(0) == []
    assert recorded_steps(4, every=2, start=3) == [4, 6]
    with pytest.raises(ValueError):
        recorded_steps(3, every=0)


def _stamp_lines(path: Path) -> list[str]:
    return [
        line for line in gzip.decompress(path.read_bytes()).decode().splitlines() if line.startswith("T=")
    ]


def test_stamps_equal_every_regression_reference(
    tmp_path: Path, regression_dir: Path, corpus_dir: Path
) -> None:
    """For each of the 87 scenes: STEPS steps of the scene's dt, recorded as SOFA records its
    references and printed with SOFA's 6 digits, give exactly the reference's ``T=`` lines."""
    entries = parse_regression_list(regression_dir / "scenes.regression-tests").entries
    assert len(entries) == 87
    kinds = set()
    for index, entry in enumerate(entries):
        dt = float(parse_scene(corpus_dir / entry.scene, Diagnostics()).root.get("dt") or 0.01)
        reference = reference_files(regression_dir, entry.scene)[0].path
        expected = _stamp_lines(reference)
        # DistanceMultiMapping's references hold every step although its list line says LAST_ONLY.
        last_only = len(expected) == 2
        kinds.add(last_only)
        sim = FallingSim(dt, [(FakeInfo("/p", "p"), np.zeros((1, 3)), np.zeros((1, 3)))])
        out = tmp_path / str(index)
        with StateRecorder(sim, sim.states(), out, precision=6) as recorder:
            recorder.run(entry.steps, last_only=last_only)
        assert sim.steps_done == entry.steps
        assert _stamp_lines(recorder.paths[0]) == expected, entry.scene
    assert kinds == {True, False}


def test_last_only_and_every_step_examples(tmp_path: Path) -> None:
    # Component/ODESolver/Forward/EulerExplicitSolver.scn: 3000 steps of 1e-5, LAST_ONLY.
    sim = FallingSim(1e-5, [(FakeInfo("/p", "p"), np.zeros((1, 3)), np.zeros((1, 3)))])
    paths = export_states(sim, 3000, tmp_path / "a", last_only=True, precision=6)
    assert _stamp_lines(paths[0]) == ["T= 0", "T= 0.02999"]
    assert sim.step_calls == [2999, 1]  # stepped in chunks, not one call per step
    # DistanceMultiMapping.scn's reference: 100 steps of 0.01, every step: 0, 0.01, ..., 0.99.
    sim = FallingSim(0.01, [(FakeInfo("/p", "p"), np.zeros((1, 3)), np.zeros((1, 3)))])
    paths = export_states(sim, 100, tmp_path / "b", precision=6)
    stamps = _stamp_lines(paths[0])
    assert len(stamps) == 100 and stamps[:3] == ["T= 0", "T= 0.01", "T= 0.02"] and stamps[-1] == "T= 0.99"


# --- the recorder and K numbering ------------------------------------------------------------------


def test_select_states_counts_like_sofa() -> None:
    states = [
        FakeInfo("/free", "free"),
        FakeInfo("/free/visu", "visu", mapped=True),
        FakeInfo("/fixed", "MechanicalObject1", simulated=False),  # no ODE solver above it
        FakeInfo("/body", "body"),
    ]
    assert [s.name for s in select_states(states, mapped=False)] == ["free", "body"]
    assert [s.name for s in select_states(states, mapped=True)] == ["free", "visu", "body"]


def test_k_numbering_of_real_references(regression_dir: Path) -> None:
    # Demos/SofaScene.scn is compared with MAPPED=1: 14 states, K 0..13 in traversal order.
    refs = reference_files(regression_dir, "Demos/SofaScene.scn")
    assert [r.k for r in refs] == list(range(14))
    assert [r.name for r in refs][:5] == ["LogoDOF", "CollisionDOF", "Points", "BeamDOF", "Points"]
    # An unnamed MechanicalObject is named as SOFA names it: MechanicalObject1 in its node.
    refs = reference_files(regression_dir, "Component/ODESolver/Forward/RungeKutta4Solver.scn")
    assert [(r.k, r.name) for r in refs] == [(0, "MechanicalObject1")]
    assert state_file_name(3, "MechanicalObject1") == "3_MechanicalObject1_mstate.txt.gz"
    assert state_file_name(0, "a/b") == "0_a_b_mstate.txt.gz"


def test_sofas_selection_rule_names_every_reference_file(regression_dir: Path, corpus_dir: Path) -> None:
    """The rule :func:`select_states` relies on, checked on the scene model of all 87 scenes: nodes
    depth first (a node before its children), each node's MechanicalObject if an ODE solver is in
    the node or above it, skipped with MAPPED=0 when a mapping is in the node or above it; an
    unnamed MechanicalObject is called MechanicalObject1 (SOFA counts unnamed objects per class in
    each node). This gives exactly the K and NAME of every reference file."""
    from sofac.check.checker import check_file
    from sofac.registry import Category

    mappings = (Category.MAPPING, Category.MULTI_MAPPING)
    for entry in parse_regression_list(regression_dir / "scenes.regression-tests").entries:
        checked, _ = check_file(corpus_dir / entry.scene, allow_unsupported=True)
        assert checked is not None, entry.scene

        def category(component: object, checked: object = checked) -> Category | None:
            found = checked.components.get(id(component))  # type: ignore[attr-defined]
            return found.category if found else None

        names = []
        for node in checked.scene.root.walk():
            states = [c for c in node.objects if category(c) is Category.STATE]
            if not states:
                continue
            above = [node, *node.ancestors()]
            simulated = any(category(c) is Category.ODE_SOLVER for n in above for c in n.objects)
            mapped = any(category(c) in mappings for n in above for c in n.objects)
            if simulated and (entry.mapped or not mapped):
                names.append(states[0].name or "MechanicalObject1")
        refs = reference_files(regression_dir, entry.scene)
        assert [r.k for r in refs] == list(range(len(refs)))
        assert names == [r.name for r in refs], entry.scene


def test_export_free_fall_exactly(tmp_path: Path) -> None:
    sim = two_body_sim(dt=0.5)
    paths = export_states(sim, 4, tmp_path)
    assert [p.name for p in paths] == ["0_dofs_mstate.txt.gz", "1_MechanicalObject1_mstate.txt.gz"]
    for path, info in zip(paths, [s for s in sim.states() if not s.mapped], strict=True):
        blocks = read_state_file(path)
        assert [b.time for b in blocks] == [0.0, 0.5, 1.0, 1.5]  # beginning of steps 0..3
        for k, block in enumerate(blocks):
            x, v = sim.exact(info.path, k)  # the block stamped k*dt holds the state after k steps
            assert np.array_equal(block.x, x.ravel()) and np.array_equal(block.v, v.ravel())
    assert sim.steps_done == 4
    # Mapped states too with mapped=True; K counts them in traversal order.
    paths = export_states(two_body_sim(), 2, tmp_path / "mapped", every=2, mapped=True)
    assert [p.name for p in paths] == [
        "0_dofs_mstate.txt.gz",
        "1_points_mstate.txt.gz",
        "2_MechanicalObject1_mstate.txt.gz",
    ]
    assert [b.time for b in read_state_file(paths[1])] == [0.0]


def test_export_is_deterministic(tmp_path: Path) -> None:
    first = export_states(two_body_sim(), 3, tmp_path / "1")
    second = export_states(two_body_sim(), 3, tmp_path / "2")
    assert [p.read_bytes() for p in first] == [p.read_bytes() for p in second]


def test_recorder_continues_across_runs(tmp_path: Path) -> None:
    sim = two_body_sim()
    with StateRecorder(sim, [sim.states()[0]], tmp_path, every=2) as recorder:
        recorder.run(3)
        recorder.run(3)
    assert [b.time for b in read_state_file(recorder.paths[0])] == [0.0, 1.0, 2.0]
    assert sim.steps_done == 6
    with pytest.raises(ValueError, match="closed"):
        recorder.record()
