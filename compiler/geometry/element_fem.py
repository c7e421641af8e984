"""Compile-time side of SOFA's element-based finite elements (runtime/sofac/element_fem.h).

CorotationalFEMForceField, LinearSmallStrainFEMForceField and FEMMass are templated on
"DataType,ElementType"; sofac compiles the Vec3d tetrahedron and hexahedron forms. What is decided
here, once: which element kind a template names and where its cells are, the rotation method of a
corotational field, the NodalMassDensity a FEMMass reads, and the sparsity pattern of FEMMass's
scalar mass matrix (the sorted node pairs of the elements, as SOFA's compressed matrix holds them).
The numbers themselves (stiffness and mass matrices) are computed by the runtime at creation, in
SOFA's order of floating-point operations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sofac.registry.datatypes import split_template

# Element kinds compiled: nodes per element and the topology array holding them.
ELEMENTS: dict[str, tuple[int, str]] = {
    "Tetrahedron": (4, "tetrahedra"),
    "Hexahedron": (8, "hexahedra"),
}

# CorotationalFEMForceField's rotationMethod, by the kernel's code (element_fem.h): 0 the element's
# own frame (SOFA's default: "triangle" for tetrahedra, "hexahedron" for hexahedra), 1 identity,
# 2 polar, 3 stable_polar.
_FRAME_METHOD = {"Tetrahedron": "triangle", "Hexahedron": "hexahedron"}
_ROTATION_CODES = {"identity": 1, "polar": 2, "stable_polar": 3}


def element_of(template: str | None) -> str | None:
    """The element type a "DataType,ElementType" template names ("Vec3d,Hexahedron" -> "Hexahedron")."""
    if not template:
        return None
    parts = split_template(template)
    return parts[1] if len(parts) > 1 else None


def rotation_method(name: str | None, element: str) -> int | None:
    """The kernel's code of a rotationMethod for an element type; None if SOFA does not offer it."""
    if name is None or name == _FRAME_METHOD[element]:
        return 0
    return _ROTATION_CODES.get(name)


@dataclass(frozen=True)
class MassPattern:
    """Compressed rows of the scalar mass matrix: row r holds cols[row_begin[r]:row_begin[r+1]]."""

    row_begin: np.ndarray  # int64, n_rows + 1
    cols: np.ndarray  # int64, sorted within each row

    @property
    def nonzeros(self) -> int:
        return int(self.cols.size)


def mass_pattern(elements: np.ndarray, n_rows: int) -> MassPattern:
    """The node pairs (i, j) of every element, sorted by row then column, without repetition."""
    cells = np.asarray(elements, dtype=np.int64)
    if cells.size == 0:
        return MassPattern(np.zeros(n_rows + 1, dtype=np.int64), np.zeros(0, dtype=np.int64))
    corners = cells.shape[1]
    rows = np.repeat(cells, corners, axis=1).ravel()
    cols = np.tile(cells, (1, corners)).ravel()
    keys = np.unique(rows * np.int64(max(n_rows, 1)) + cols)
    unique_rows, unique_cols = np.divmod(keys, np.int64(max(n_rows, 1)))
    row_begin = np.zeros(n_rows + 1, dtype=np.int64)
    np.add.at(row_begin, unique_rows + 1, 1)
    return MassPattern(np.cumsum(row_begin), unique_cols.astype(np.int64))


def node_densities(values: object) -> np.ndarray:
    """NodalMassDensity's ``property``: one value per node, or fewer (the last one then repeats);
    SOFA's default is a single 1."""
    array = np.asarray(values if values is not None else [1.0], dtype=float).ravel()
    return array if array.size else np.array([1.0])
