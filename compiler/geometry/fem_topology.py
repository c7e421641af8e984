"""Element lists SOFA derives from a regular grid, for the finite-element kernels (runtime/sofac/fem.h).

Grid points are numbered ``i + nx * (j + ny * k)`` (GridTopology::getIndex) for ``counts = (nx, ny, nz)``
points per axis; cells likewise ``ci + (nx-1) * (cj + (ny-1) * ck)``.

- :func:`hexahedra_from_grid`: GridTopology's hexahedra (z slowest, x fastest), corners in SOFA's
  order (0,0,0) (1,0,0) (1,1,0) (0,1,0) (0,0,1) (1,0,1) (1,1,1) (0,1,1), which is also the order
  sofa::geometry::Hexahedron and HexahedronFEMForceField use (no reordering happens).
- :func:`tetrahedra_from_hexahedra` / :func:`tetrahedra_from_grid`: what TetrahedronFEMForceField::init
  builds when its topology has hexahedra but no tetrahedra (RegularGridTopology has none: MeshTopology
  only returns tetrahedra that were given). Each cell is split into 6 tetrahedra after mirroring its
  corners, by swapping the corner pairs along x (geometry::Hexahedron::xEdges (0,1) (4,5) (3,2) (7,6))
  when the cell's x index is **even**, along y ((4,7) (5,6) (1,2) (0,3)) when its y index is odd and
  along z ((4,0) (5,1) (6,2) (7,3)) when its z index is odd, in that order; then
  ``(c0,c5,c1,c6) (c0,c1,c3,c6) (c1,c3,c6,c2) (c6,c3,c0,c7) (c6,c7,c0,c5) (c7,c5,c4,c0)``.
  The parity is taken from the cell's position in the hexahedron list with the grid's cell counts
  ``nx-1``, ``ny-1``; for a topology that is not a GridTopology SOFA uses ``nx = 2, ny = 1`` (pass
  those to :func:`tetrahedra_from_hexahedra`).

  The split does not keep a consistent orientation: a mirrored cell gives tetrahedra of negative
  signed volume (an odd number of mirrors: 408 of the 810 tetrahedra of a 4x4x16 grid). SOFA does
  not care (it uses |volume| and the stiffness is invariant under the sign), nor do the kernels;
  anything else that needs positive orientation (e.g. a mass from these tetrahedra) must take |V|.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "HEXA_X_EDGES",
    "HEXA_Y_EDGES",
    "HEXA_Z_EDGES",
    "TETRA_SPLIT",
    "hexahedra_from_grid",
    "tetrahedra_from_grid",
    "tetrahedra_from_hexahedra",
]

HEXA_X_EDGES: tuple[tuple[int, int], ...] = ((0, 1), (4, 5), (3, 2), (7, 6))
HEXA_Y_EDGES: tuple[tuple[int, int], ...] = ((4, 7), (5, 6), (1, 2), (0, 3))
HEXA_Z_EDGES: tuple[tuple[int, int], ...] = ((4, 0), (5, 1), (6, 2), (7, 3))
TETRA_SPLIT: tuple[tuple[int, int, int, int], ...] = (
    (0, 5, 1, 6),
    (0, 1, 3, 6),
    (1, 3, 6, 2),
    (6, 3, 0, 7),
    (6, 7, 0, 5),
    (7, 5, 4, 0),
)

# Corner offsets (dx, dy, dz) of the hexahedron corners 0..7.
_CORNERS = np.array(
    [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)], dtype=np.int64
)


def _counts(counts: Sequence[int]) -> tuple[int, int, int]:
    if len(counts) != 3:
        raise ValueError(f"grid counts need 3 values (nx, ny, nz), got {len(counts)}")
    nx, ny, nz = (int(c) for c in counts)
    if min(nx, ny, nz) < 1:
        raise ValueError(f"grid counts must be >= 1, got {(nx, ny, nz)}")
    return nx, ny, nz


def hexahedra_from_grid(counts: Sequence[int]) -> np.ndarray:
    """GridTopology's hexahedra, shape ``((nx-1)(ny-1)(nz-1), 8)``, int64; empty if any count is 1."""
    nx, ny, nz = _counts(counts)
    cx, cy, cz = nx - 1, ny - 1, nz - 1
    if cx * cy * cz == 0:
        return np.zeros((0, 8), dtype=np.int64)
    k, j, i = np.meshgrid(np.arange(cz), np.arange(cy), np.arange(cx), indexing="ij")
    base = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)  # x fastest, z slowest
    corner = base[:, None, :] + _CORNERS[None, :, :]
    return corner[..., 0] + nx * (corner[..., 1] + ny * corner[..., 2])


def tetrahedra_from_hexahedra(hexahedra: np.ndarray, nx: int = 2, ny: int = 1) -> np.ndarray:
    """TetrahedronFEMForceField's 6-tetrahedra split of a hexahedron list, shape ``(6 m, 4)``.

    ``nx``, ``ny`` are the numbers of *cells* along x and y used for the parity (SOFA: grid points - 1
    for a GridTopology, else 2 and 1).
    """
    hexa = np.asarray(hexahedra, dtype=np.int64).reshape(-1, 8)
    if len(hexa) == 0:
        return np.zeros((0, 4), dtype=np.int64)
    if nx < 1 or ny < 1:
        raise ValueError(f"cell counts must be >= 1, got nx={nx}, ny={ny}")
    cells = hexa.copy()
    index = np.arange(len(cells))
    for mask, edges in (
        ((index % nx) % 2 == 0, HEXA_X_EDGES),
        (((index // nx) % ny) % 2 == 1, HEXA_Y_EDGES),
        ((index // (nx * ny)) % 2 == 1, HEXA_Z_EDGES),
    ):
        for a, b in edges:
            swapped = cells[mask, b].copy()
            cells[mask, b] = cells[mask, a]
            cells[mask, a] = swapped
    split = np.array(TETRA_SPLIT, dtype=np.int64)
    return cells[:, split].reshape(-1, 4)


def tetrahedra_from_grid(counts: Sequence[int]) -> np.ndarray:
    """The tetrahedra TetrahedronFEMForceField builds on a RegularGridTopology of ``counts`` points."""
    nx, ny, _ = _counts(counts)
    return tetrahedra_from_hexahedra(hexahedra_from_grid(counts), max(nx - 1, 1), max(ny - 1, 1))


# The element lists a topology container holds, lowest dimension first.
CELL_KINDS = ("edges", "triangles", "quads", "tetrahedra", "hexahedra")
TETRA_FACES = ((0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2))
HEXA_FACES = ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))


# Topology.cpp's trianglesOrientationInTetrahedronArray: face j of a tetrahedron, opposite corner j,
# outward for a positively oriented tetrahedron.
TETRA_ORIENTED_FACES = ((1, 2, 3), (0, 3, 2), (1, 3, 0), (0, 2, 1))


def tetrahedron_container_triangles(tetrahedra: np.ndarray) -> np.ndarray:
    """The triangle array SOFA's TetrahedronSetTopologyContainer builds from its tetrahedra
    (createTriangleSetArray): tetrahedron by tetrahedron, face by face in
    trianglesOrientationInTetrahedronArray's order, each face turned so that its smallest index
    comes first; a face is added when neither it nor its opposite orientation is there yet (a
    shared face keeps the orientation of its first tetrahedron)."""
    seen: set[tuple[int, int, int]] = set()
    triangles: list[tuple[int, int, int]] = []
    for tetrahedron in np.asarray(tetrahedra, dtype=np.int64).reshape(-1, 4).tolist():
        for face in TETRA_ORIENTED_FACES:
            v = [tetrahedron[k] for k in face]
            while v[0] > v[1] or v[0] > v[2]:
                v = [v[1], v[2], v[0]]
            if (v[0], v[2], v[1]) in seen or (v[0], v[1], v[2]) in seen:
                continue
            seen.add((v[0], v[1], v[2]))
            triangles.append((v[0], v[1], v[2]))
    return np.asarray(triangles, dtype=np.int64).reshape(-1, 3)


def tetrahedron_surface_triangles(
    tetrahedra: np.ndarray, triangles: np.ndarray | None = None, flip: bool = False
) -> np.ndarray:
    """Tetra2TriangleTopologicalMapping's output (its init): the triangles of the input container's
    triangle array (``triangles`` when the container was given some, else the array it builds from
    its tetrahedra) that belong to one tetrahedron only, in that array's order, as (t0 t1 t2), or
    (t0 t2 t1) with flipNormals."""
    tetrahedra = np.asarray(tetrahedra, dtype=np.int64).reshape(-1, 4)
    if triangles is None or not np.size(triangles):
        array = tetrahedron_container_triangles(tetrahedra)
    else:
        array = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    counts: dict[tuple[int, ...], int] = {}
    for tetrahedron in tetrahedra.tolist():
        for face in TETRA_ORIENTED_FACES:
            key = tuple(sorted(tetrahedron[k] for k in face))
            counts[key] = counts.get(key, 0) + 1
    single = np.array([counts.get(tuple(sorted(t)), 0) == 1 for t in array.tolist()], dtype=bool)
    surface = array[single].reshape(-1, 3)
    return surface[:, [0, 2, 1]] if flip else surface


def boundary_faces(
    cells: np.ndarray, faces: Sequence[Sequence[int]], points: np.ndarray | None
) -> np.ndarray:
    """The faces of volume elements that belong to one element only (the surface), in element
    order; with ``points``, turned to face away from their element's centre (else as ``faces``
    lists them, outward for positively oriented elements)."""
    cells = np.asarray(cells, dtype=np.int64)
    if not len(cells):
        return np.zeros((0, len(faces[0])), dtype=np.int64)
    # Element by element, faces in `faces` order (row e * len(faces) + f).
    all_faces = cells[:, np.array(faces)].reshape(-1, len(faces[0]))
    owners = np.repeat(np.arange(len(cells)), len(faces))
    _, first, counts = np.unique(np.sort(all_faces, axis=1), axis=0, return_index=True, return_counts=True)
    single = np.sort(first[counts == 1])
    surface, owner = all_faces[single], owners[single]
    if points is None or cells.max() >= len(points):
        return surface
    a, b, c = (points[surface[:, k]] for k in range(3))
    centres = points[cells[owner]].mean(axis=1)
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), centres - a) > 0
    surface[inward] = surface[inward][:, ::-1]
    return surface
