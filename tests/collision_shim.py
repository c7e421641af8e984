"""A ctypes shim over runtime/sofac/{collision,proximity,contact}.h for tests/test_collision_kernels.py.

Every element test, the tree + narrow phase of one model pair, a brute-force all-pairs loop over the
same element test, the broad phase and the penalty force field, each as a C function; outputs come
back as rows of 13 doubles (point[0], point[1], normal, value, elem1, elem2, id).
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from kernel_shim import I64, D, build_shim
from kernel_shim import doubles as _d
from kernel_shim import indices as _i

SOURCE = (Path(__file__).parent / "collision_shim.cpp").read_text()

KINDS = {"PP": 0, "LP": 1, "LL": 2, "TP": 3, "SS": 4, "SP": 5, "TS": 6, "LS": 7, "TL": 8, "TT": 9}
METHODS = {"min": 0, "new": 1}


class ModelStruct(ctypes.Structure):
    _fields_ = [
        ("x", D),
        ("elements", I64),
        ("flags", ctypes.POINTER(ctypes.c_int)),
        ("normals", D),
        ("size", ctypes.c_int64),
        ("cd", ctypes.c_double),
        ("radii", D),
        ("n_radii", ctypes.c_int64),
        ("radius", ctypes.c_double),
        ("stride", ctypes.c_int64),
    ]


@dataclass
class Model:
    """A collision model's arrays, kept alive while the C struct points at them."""

    x: np.ndarray
    elements: np.ndarray | None = None
    flags: np.ndarray | None = None
    normals: np.ndarray | None = None
    cd: float = 0.0
    radius: float = 1.0
    radii: np.ndarray | None = None
    rigid: bool = False
    struct: ModelStruct = field(init=False)

    def __post_init__(self) -> None:
        self.x = np.ascontiguousarray(self.x, dtype=np.float64)
        if self.elements is not None:
            self.elements = np.ascontiguousarray(self.elements, dtype=np.int64)
        if self.flags is not None:
            self.flags = np.ascontiguousarray(self.flags, dtype=np.int32)
        if self.normals is not None:
            self.normals = np.ascontiguousarray(self.normals, dtype=np.float64)
        if self.radii is not None:
            self.radii = np.ascontiguousarray(self.radii, dtype=np.float64)
        stride = 7 if self.rigid else 3
        size = len(self.elements) if self.elements is not None else self.x.size // stride
        self.struct = ModelStruct(
            _d(self.x),
            _i(self.elements) if self.elements is not None else ctypes.cast(None, I64),
            self.flags.ctypes.data_as(ctypes.POINTER(ctypes.c_int)) if self.flags is not None else None,
            _d(self.normals) if self.normals is not None else ctypes.cast(None, D),
            size,
            self.cd,
            _d(self.radii) if self.radii is not None else ctypes.cast(None, D),
            len(self.radii) if self.radii is not None else 0,
            self.radius,
            stride,
        )


@dataclass
class Output:
    p0: np.ndarray
    p1: np.ndarray
    normal: np.ndarray
    value: float
    elem1: int
    elem2: int
    id: int


def outputs(rows: np.ndarray, n: int) -> list[Output]:
    return [
        Output(r[0:3].copy(), r[3:6].copy(), r[6:9].copy(), float(r[9]), int(r[10]), int(r[11]), int(r[12]))
        for r in rows[:n]
    ]


class Shim:
    def __init__(self, lib: ctypes.CDLL) -> None:
        self.lib = lib
        m = ctypes.POINTER(ModelStruct)
        i64, dbl, integer = ctypes.c_int64, ctypes.c_double, ctypes.c_int
        lib.element_test.argtypes = [integer, integer, m, i64, m, i64, dbl, dbl, integer, D, I64]
        lib.element_test.restype = i64
        lib.detect.argtypes = [integer, integer, m, m, integer, dbl, dbl, integer, D, i64, I64]
        lib.detect.restype = i64
        lib.brute_force.argtypes = [integer, integer, m, m, dbl, dbl, integer, integer, D, i64]
        lib.brute_force.restype = i64
        lib.point_tree.argtypes = [D, i64, integer, dbl, I64, I64, D]
        lib.point_tree.restype = i64
        lib.flags.argtypes = [I64, i64, i64, ctypes.POINTER(ctypes.c_int)]
        lib.broad_phase.argtypes = [D, D, i64, ctypes.POINTER(ctypes.c_int8), dbl, I64]
        lib.broad_phase.restype = i64
        lib.penalty.argtypes = [i64, I64, D, D, D, D, D, D, D, D, D, D, D, dbl, D, D, i64, i64]
        lib.penalty.restype = dbl
        lib.penalty_from_outputs.argtypes = [D, i64, i64, D, I64, dbl, dbl, D, dbl, dbl, dbl, I64, D, D]
        lib.penalty_from_outputs.restype = i64
        lib.barycentric.argtypes = [D, I64, I64, D, I64, ctypes.POINTER(ctypes.c_int), i64, D, D, D]
        lib.allocations.restype = ctypes.c_long
        lib.triangle_normals.argtypes = [m, D]
        lib.lmd_test.argtypes = [integer, m, i64, m, i64, dbl, dbl, integer, dbl, dbl, integer]
        lib.lmd_test.argtypes += [D, I64, i64, I64, i64, i64, integer, D, I64]
        lib.lmd_test.restype = i64
        lib.contact_order.argtypes = [integer, i64, I64, ctypes.POINTER(ctypes.c_int), I64, i64, I64, I64]
        lib.contact_order.restype = i64
        lib.self_detect.argtypes = [integer, integer, m, m, integer, I64, I64, integer, dbl, dbl, integer]
        lib.self_detect.argtypes += [integer, D, i64]
        lib.self_detect.restype = i64
        lib.self_filter.argtypes = [integer, i64, i64, I64, I64, I64, ctypes.c_char_p]
        lib.tree_structure.argtypes = [D, D, i64, integer, I64, I64, D]
        lib.drop_points.argtypes = [D, i64, i64, dbl, dbl, dbl, dbl, dbl, dbl, dbl, I64]
        lib.drop_points.restype = ctypes.c_long
        lib.self_points.argtypes = [i64, i64, I64, I64]
        lib.self_lines.argtypes = [i64, i64, I64, I64, I64]
        lib.pretest_run.argtypes = [integer, m, i64, D, i64, integer, dbl, dbl, dbl, I64, I64, I64, D, I64]
        lib.pretest_run.restype = i64

    def test(
        self,
        method: str,
        kind: str,
        a: Model,
        e1: int,
        b: Model,
        e2: int,
        alarm: float,
        contact: float,
        option: int = 0,
    ) -> tuple[list[Output], tuple[int, int]]:
        rows = np.zeros((16, 13))
        counters = np.zeros(2, dtype=np.int64)
        n = self.lib.element_test(
            METHODS[method], KINDS[kind], ctypes.byref(a.struct), e1, ctypes.byref(b.struct), e2, alarm,
            contact, option, _d(rows), _i(counters),
        )  # fmt: skip
        assert n >= 0
        return outputs(rows, n), (int(counters[0]), int(counters[1]))

    def lmd(
        self, kind: str, a: Model, e1: int, b: Model, e2: int, alarm: float, contact: float, *,
        mesh: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None, cones: int = 3, filter: bool = True,
        angle_cone: float = 0.0, cone_factor: float = 0.5, both_side: bool = False,
    ) -> tuple[list[Output], tuple[int, int]]:  # fmt: skip
        """A LocalMinDistance test; `mesh` = (x, triangles, edges) of the topology the cones read
        (`cones`: 1 the point's, 2 the line's, 3 both)."""
        x, tris, edges = mesh if mesh is not None else (np.zeros((1, 3)), np.zeros((0, 3)), np.zeros((0, 2)))
        x = np.ascontiguousarray(x, dtype=np.float64)
        tris = np.ascontiguousarray(tris, dtype=np.int64)
        edges = np.ascontiguousarray(edges, dtype=np.int64)
        rows = np.zeros((4, 13))
        counters = np.zeros(2, dtype=np.int64)
        n = self.lib.lmd_test(
            KINDS[kind], ctypes.byref(a.struct), e1, ctypes.byref(b.struct), e2, alarm, contact, int(filter),
            angle_cone, cone_factor, int(both_side), _d(x), _i(tris), len(tris), _i(edges), len(edges),
            len(x), cones if mesh is not None else 0, _d(rows), _i(counters),
        )  # fmt: skip
        assert n >= 0
        return outputs(rows, n), (int(counters[0]), int(counters[1]))

    def contact_order(
        self, steps: list[list[tuple[int, int, int]]], n_models: int, sofa_expression: bool
    ) -> tuple[list[tuple[list[tuple[int, int]], list[tuple[int, int]]]], tuple[int, int]]:
        """Per step, the output map's and the contact map's key orders; steps list (model 1,
        model 2, found contacts) in broad-phase order."""
        flat = [p for step in steps for p in step]
        pairs = np.array([(a, b) for a, b, _ in flat], dtype=np.int64).reshape(-1, 2)
        found = np.array([f for _, _, f in flat], dtype=np.int32)
        sizes = np.array([len(s) for s in steps], dtype=np.int64)
        orders = np.zeros(4 * len(flat) * len(steps) + 2 * len(steps) + 8, dtype=np.int64)
        allocations = np.zeros(2, dtype=np.int64)
        n = self.lib.contact_order(
            int(sofa_expression), n_models, _i(pairs), found.ctypes.data_as(ctypes.POINTER(ctypes.c_int)),
            _i(sizes), len(steps), _i(orders), _i(allocations),
        )  # fmt: skip
        result, current, first = [], [], None
        values = orders[:n].tolist()
        i = 0
        while i < len(values):
            if values[i] == -1:
                first, current = current, []
                i += 1
            elif values[i] == -2:
                result.append((first, current))
                current = []
                i += 1
            else:
                current.append((values[i], values[i + 1]))
                i += 2
        return result, (int(allocations[0]), int(allocations[1]))

    def detect(
        self, method: str, kind: str, a: Model, b: Model, depth: int, alarm: float, contact: float,
        option: int = 0, first: bool = True,
    ) -> tuple[list[Output], np.ndarray]:  # fmt: skip
        capacity = 20000
        rows = np.zeros((capacity, 13))
        counters = np.zeros(4, dtype=np.int64)
        counters[0] = 0 if first else 1
        n = self.lib.detect(
            METHODS[method], KINDS[kind], ctypes.byref(a.struct), ctypes.byref(b.struct), depth, alarm,
            contact, option, _d(rows), capacity, _i(counters),
        )  # fmt: skip
        assert n <= capacity
        return outputs(rows, n), counters

    def brute_force(
        self, method: str, kind: str, a: Model, b: Model, alarm: float, contact: float, option: int = 0,
        boxes: bool = False,
    ) -> list[Output]:  # fmt: skip
        capacity = 20000
        rows = np.zeros((capacity, 13))
        n = self.lib.brute_force(
            METHODS[method], KINDS[kind], ctypes.byref(a.struct), ctypes.byref(b.struct), alarm, contact,
            option, int(boxes), _d(rows), capacity,
        )  # fmt: skip
        return outputs(rows, n)

    def self_filter(
        self, rule: int, n1: int, n2: int, cells: np.ndarray, around: list[list[int]] | None = None
    ) -> np.ndarray:
        """SelfCollisionFilter `rule` over every (e1, e2) as a boolean n1 x n2 mask; `around` the
        first model's edgesAroundVertex (line rules)."""
        cells = np.ascontiguousarray(cells, dtype=np.int64)
        offsets, items = csr(around or [])
        mask = np.zeros(n1 * n2, dtype=np.int8)
        self.lib.self_filter(
            rule, n1, n2, _i(cells), _i(offsets), _i(items), mask.ctypes.data_as(ctypes.c_char_p)
        )
        return mask.reshape(n1, n2).astype(bool)

    def self_detect(
        self, method: str, kind: str, a: Model, b: Model, rule: int, around: list[list[int]] | None = None,
        *, depth: int = 6, alarm: float, contact: float, option: int = 0, brute: bool = False,
    ) -> list[Output]:  # fmt: skip
        """Two models of one node (or one model twice) through the narrow phase with SOFA's element
        filter (SelfCollisionFilter `rule`), or every element pair through it (`brute`)."""
        capacity = 20000
        rows = np.zeros((capacity, 13))
        offsets, items = csr(around or [])
        n = self.lib.self_detect(
            METHODS[method], KINDS[kind], ctypes.byref(a.struct), ctypes.byref(b.struct), rule, _i(offsets),
            _i(items), depth, alarm, contact, option, int(brute), _d(rows), capacity,
        )  # fmt: skip
        assert n <= capacity
        return outputs(rows, n)

    def pretest_run(
        self, kind: str, b: Model, xs: np.ndarray, pretest: bool, alarm: float, contact: float,
        floor_cd: float,
    ) -> dict[str, np.ndarray | int]:  # fmt: skip
        """PenaltyContacts on a static floor and `b` over the positions `xs` (steps, points, 3)."""
        xs = np.ascontiguousarray(xs, dtype=np.float64)
        steps, n_points = xs.shape[0], xs.shape[1]
        skipped, found, contacts = (np.zeros(steps, dtype=np.int64) for _ in range(3))
        energy, mismatches = np.zeros(steps), np.zeros(1, dtype=np.int64)
        fast = self.lib.pretest_run(
            KINDS[kind], ctypes.byref(b.struct), n_points, _d(xs), steps, int(pretest), alarm, contact,
            floor_cd, _i(skipped), _i(found), _i(contacts), _d(energy), _i(mismatches),
        )  # fmt: skip
        return {"skipped": skipped, "outputs": found, "contacts": contacts, "energy": energy,
                "mismatches": int(mismatches[0]), "fast_motions": int(fast)}  # fmt: skip


# runtime SelfCollisionFilter::Rule
SAME_MODEL, SAME_LINES, TRIANGLE_POINT, LINE_POINT = 1, 2, 3, 4


def csr(lists: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Adjacency lists as (offsets, items), the runtime's Adjacency."""
    offsets = np.cumsum([0] + [len(items) for items in lists]).astype(np.int64)
    items = np.array([i for items in lists for i in items] or [0], dtype=np.int64)
    return offsets, items


def make_shim(tmp_path_factory: pytest.TempPathFactory) -> Shim:
    return Shim(build_shim(tmp_path_factory, "collision", SOURCE))
