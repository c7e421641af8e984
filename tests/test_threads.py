"""OpenMP (``threads``): split element loops and parallel groups give the serial numbers bit for bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sofac
from sofac.check import checker as check
from sofac.codegen import cpp as generate
from sofac.plan import planner as plan
from sofac.plan.ir import Op, call, independent_groups
from sofac.plan.lower.common import MIN_ELEMENTS_PER_THREAD, element_split

BEAM = """
    <Node name="{name}">
        <EulerImplicitSolver rayleighStiffness="0.1" rayleighMass="0.1"/>
        <CGLinearSolver iterations="25" tolerance="0" threshold="0"/>
        <RegularGridTopology name="grid" n="{n}" min="{offset} 0 0" max="{far} 1 1"/>
        <MechanicalObject name="dofs"/>
        <UniformMass totalMass="1"/>
        <BoxROI name="clamped" box="{lo} -1 -1 {hi} 2 2"/>
        <FixedProjectiveConstraint indices="@clamped.indices"/>
        <{fem} youngModulus="1e5" poissonRatio="0.3" method="{method}"/>
    </Node>"""


def _scene(tmp_path: Path, name: str, beams: list[dict[str, str]]) -> Path:
    nodes = []
    for index, beam in enumerate(beams):
        offset = 3.0 * index  # side by side, never touching
        nodes.append(
            BEAM.format(
                name=f"beam{index}", offset=offset, far=offset + 5, lo=offset - 0.01, hi=offset + 0.01, **beam
            )
        )
    path = tmp_path / name
    path.write_text(f'<Node name="root" dt="0.01" gravity="0 -9.81 0">{"".join(nodes)}\n</Node>\n')
    return path


TETRA = {"n": "31 5 5", "fem": "TetrahedronFEMForceField", "method": "large"}  # 2,880 tetrahedra
HEXA = {"n": "23 11 11", "fem": "HexahedronFEMForceField", "method": "large"}  # 2,200 hexahedra


def _states(sim: sofac.Simulation) -> np.ndarray:
    return np.concatenate([np.ravel(a) for p in sim.objects() for a in (sim[p].position, sim[p].velocity)])


def _run(path: Path, threads: int, steps: int = 6) -> tuple[sofac.Simulation, np.ndarray]:
    sim = sofac.load(path, threads=threads)
    sim.step(steps)
    return sim, _states(sim)


def _split_loops(sim: sofac.Simulation) -> int:
    return sum(b.key.endswith(".split_bounds") for b in sim.plan.buffers)


@pytest.mark.parametrize(
    ("beams", "splits"),
    [
        ([TETRA], 1),  # one split, used by add_force and add_dforce
        ([dict(TETRA, method="small")], 1),
        ([HEXA], 1),
        ([TETRA, HEXA], 2),  # two groups, each with a split loop (nested in the parallel groups)
    ],
    ids=["tetra-large", "tetra-small", "hexa-large", "two-groups"],
)
def test_threads_give_the_serial_numbers(tmp_path: Path, beams: list[dict[str, str]], splits: int) -> None:
    path = _scene(tmp_path, "beams.scn", beams)
    serial, expected = _run(path, 1)
    threaded, got = _run(path, 2)
    assert _split_loops(serial) == 0
    assert _split_loops(threaded) == splits
    tip = serial[serial.objects()[0]].position[:, 1].min()
    assert tip < -1e-4  # the beams sag: the comparison is about real motion
    np.testing.assert_array_equal(got, expected)


def test_independent_groups_step_in_parallel(tmp_path: Path) -> None:
    two = _scene(tmp_path, "two.scn", [TETRA, HEXA])
    checked, diagnostics = check.check_file(two)
    threaded = plan.plan_scene(checked, diagnostics, threads=2)
    source = generate.generate_source(threaded)
    assert "#pragma omp parallel for schedule(dynamic, 1) num_threads(2)" in source
    assert "case 1: step_g1(S, dt); break;" in source
    serial = generate.generate_source(plan.plan_scene(checked, diagnostics))
    assert threaded.parallel_groups
    assert "#pragma omp" not in serial
    # A call of group 1 on a buffer of group 0 makes them dependent.
    shared = {threaded.dt.ident, threaded.gravity.ident}
    assert independent_groups(threaded.groups, shared)
    first, second = threaded.groups
    second.forces.append(Op("test", [call("fill", first.states[0].x, 0.0)]))
    assert not independent_groups(threaded.groups, shared)
    # One group: nothing to run side by side.
    one = _scene(tmp_path, "one.scn", [TETRA])
    checked, diagnostics = check.check_file(one)
    single = plan.plan_scene(checked, diagnostics, threads=2)
    assert not single.parallel_groups


def test_small_loops_stay_serial(tmp_path: Path) -> None:
    small = dict(TETRA, n="11 3 3")  # 240 tetrahedra, below MIN_ELEMENTS_PER_THREAD per thread
    assert MIN_ELEMENTS_PER_THREAD > 240
    sim = sofac.load(_scene(tmp_path, "small.scn", [small]), threads=2)
    assert _split_loops(sim) == 0


def test_element_split_keeps_the_serial_order() -> None:
    # A strip of 12 three-node elements over 3 chunks of whole 4-element blocks; a node belongs to
    # the first chunk touching it.
    cells = np.array([[i, i + 1, i + 2] for i in range(12)])
    bounds, slot_of, slot_node = element_split(cells, 3)
    np.testing.assert_array_equal(bounds, [0, 4, 8, 12])
    # chunk 1 (elements 4-7) shares nodes 4 and 5 with chunk 0; chunk 2 (8-11) shares 8 and 9 with chunk 1
    deferred = slot_of.reshape(cells.shape) >= 0
    expected = np.zeros(cells.shape, dtype=bool)
    expected[[4, 4, 5, 8, 8, 9], [0, 1, 0, 0, 1, 0]] = True
    np.testing.assert_array_equal(deferred, expected)
    np.testing.assert_array_equal(slot_of[slot_of >= 0], np.arange(6))
    np.testing.assert_array_equal(slot_node, [4, 5, 5, 8, 9, 9])
    # Chunks start at whole blocks of 4 elements, the last one ends at the last element.
    np.testing.assert_array_equal(element_split(cells[:10], 2)[0], [0, 4, 10])
    # Replaying the split serially (chunks in order, deferred slots last) adds every contribution
    # of a node in element order, as the serial loop does.
    order: dict[int, list[int]] = {}
    for e, corners in enumerate(cells):
        for k, node in enumerate(corners):
            if slot_of[3 * e + k] < 0:
                order.setdefault(int(node), []).append(e)
    for slot, node in enumerate(slot_node):
        e = int(np.flatnonzero(slot_of == slot)[0]) // 3
        order.setdefault(int(node), []).append(e)
    assert all(elements == sorted(elements) for elements in order.values())


def test_threads_must_be_positive(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="threads must be a positive integer"):
        sofac.load(_scene(tmp_path, "one.scn", [TETRA]), threads=0)
