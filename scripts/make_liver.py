"""Generate the meshes of ``scenes/liver.scn``: a smooth, lobed, liver-like organ.

    pip install gmsh          # only this script needs it; the scene, tests and demo do not
    python scripts/make_liver.py

The organ is the level set ``f(p) = t`` of a sum of anisotropic Gaussian blobs (metaballs): a large
right lobe, a smaller flattened left lobe and a small caudate bump, blended smoothly into one body
about 0.24 x 0.12 x 0.15 m (x across the body, y up, z front to back). The surface is star-shaped
from the origin, so each point of a gmsh triangulation of the unit sphere is pushed out along its
direction to the level set (bisection). gmsh then tetrahedralizes the coarse version of that
surface (``scenes/liver.msh``, Gmsh format 2.2 ASCII, tetrahedra only) and a finer version is written
as the visual surface (``scenes/liver-surface.obj``). Finally the three fixed nodes of the scene (the
volume nodes nearest to three attachment points on the top of the organ, where the ligaments hold a
real liver) are printed; ``scenes/liver.scn`` lists them.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

# (centre, semi-axes) of each blob, in metres.
BLOBS: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = (
    ((-0.035, 0.0, 0.0), (0.085, 0.06, 0.07)),  # right lobe
    ((0.065, 0.012, -0.005), (0.065, 0.032, 0.05)),  # left lobe, thinner
    ((-0.005, -0.03, -0.035), (0.03, 0.025, 0.025)),  # caudate lobe, below and behind
)
LEVEL = float(np.exp(-1.0))  # one blob alone: exactly its ellipsoid
ATTACHMENTS = np.array([[-0.06, 0.06, 0.03], [0.0, 0.06, -0.03], [0.06, 0.04, 0.01]])


def field(points: np.ndarray) -> np.ndarray:
    """The blob sum at each row of ``points``."""
    total = np.zeros(len(points))
    for centre, axes in BLOBS:
        q = (((points - np.asarray(centre)) / np.asarray(axes)) ** 2).sum(axis=1)
        total += np.exp(-q)
    return total


def push_to_surface(directions: np.ndarray) -> np.ndarray:
    """Points ``r d`` with ``field(r d) = LEVEL`` for unit directions ``d`` (star-shaped surface)."""
    radii = np.linspace(0.0, 0.3, 301)
    samples = field((directions[:, None, :] * radii[None, :, None]).reshape(-1, 3)).reshape(
        len(directions), len(radii)
    )
    inside = samples > LEVEL
    crossings = (inside[:, :-1] != inside[:, 1:]).sum(axis=1)
    if not inside[:, 0].all() or (crossings != 1).any():
        raise SystemExit("the blob surface is not star-shaped from the origin")
    lo = radii[inside.sum(axis=1) - 1]
    hi = lo + radii[1]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        above = field(directions * mid[:, None]) > LEVEL
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    return directions * (0.5 * (lo + hi))[:, None]


def sphere_triangulation(size: float) -> tuple[np.ndarray, np.ndarray]:
    """gmsh's triangulation of the unit sphere with element size ``size``: (points, triangles)."""
    import gmsh

    gmsh.model.add("sphere")
    gmsh.model.occ.addSphere(0.0, 0.0, 0.0, 1.0)
    gmsh.model.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", size)
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    gmsh.model.mesh.generate(2)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    index = {int(tag): i for i, tag in enumerate(tags)}
    _, element_nodes = gmsh.model.mesh.getElementsByType(2)
    triangles = np.array([index[int(t)] for t in element_nodes], dtype=np.int64).reshape(-1, 3)
    points = np.asarray(coords).reshape(-1, 3)
    gmsh.model.remove()
    # The sphere's seam duplicates nodes: merge them.
    _, first, inverse = np.unique(np.round(points, 9), axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    points = points[first]
    triangles = inverse[triangles]
    keep = (
        (triangles[:, 0] != triangles[:, 1])
        & (triangles[:, 1] != triangles[:, 2])
        & (triangles[:, 0] != triangles[:, 2])
    )
    return points / np.linalg.norm(points, axis=1)[:, None], triangles[keep]


def outward(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``triangles`` wound so that their normals point away from the origin."""
    a, b, c = (points[triangles[:, k]] for k in range(3))
    flip = (np.cross(b - a, c - a) * (a + b + c)).sum(axis=1) < 0
    triangles = triangles.copy()
    triangles[flip] = triangles[flip][:, [0, 2, 1]]
    return triangles


def tetrahedralize(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """gmsh's tetrahedral mesh of the volume bounded by the closed surface: (points, tetrahedra)."""
    import gmsh

    gmsh.model.add("liver")
    surface = gmsh.model.addDiscreteEntity(2)
    node_tags = np.arange(1, len(points) + 1)
    gmsh.model.mesh.addNodes(2, surface, node_tags.tolist(), points.reshape(-1).tolist())
    gmsh.model.mesh.addElementsByType(surface, 2, [], (triangles + 1).reshape(-1).tolist())
    loop = gmsh.model.geo.addSurfaceLoop([surface])
    volume = gmsh.model.geo.addVolume([loop])
    gmsh.model.geo.synchronize()
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay
    gmsh.option.setNumber("Mesh.Optimize", 1)
    gmsh.model.mesh.generate(3)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    index = {int(tag): i for i, tag in enumerate(tags)}
    _, element_nodes = gmsh.model.mesh.getElementsByType(4, volume)
    tetrahedra = np.array([index[int(t)] for t in element_nodes], dtype=np.int64).reshape(-1, 4)
    gmsh.model.remove()
    return np.asarray(coords).reshape(-1, 3), tetrahedra


def write_msh(path: Path, points: np.ndarray, tetrahedra: np.ndarray) -> None:
    """Gmsh format 2.2 ASCII, tetrahedra only (1-based node numbers)."""
    lines = ["$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$Nodes", str(len(points))]
    lines += [f"{i + 1} {x:.9g} {y:.9g} {z:.9g}" for i, (x, y, z) in enumerate(points)]
    lines += ["$EndNodes", "$Elements", str(len(tetrahedra))]
    lines += [f"{i + 1} 4 2 1 1 " + " ".join(str(n + 1) for n in tet) for i, tet in enumerate(tetrahedra)]
    lines += ["$EndElements"]
    path.write_text("\n".join(lines) + "\n")


def write_obj(path: Path, points: np.ndarray, triangles: np.ndarray) -> None:
    lines = ["# liver-like organ, visual surface (scripts/make_liver.py)"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in points]
    lines += ["f " + " ".join(str(n + 1) for n in tri) for tri in triangles]
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--volume-size", type=float, default=0.3, help="element size on the unit sphere")
    parser.add_argument("--surface-size", type=float, default=0.09, help="same, for the visual surface")
    parser.add_argument("--out", type=Path, default=REPO / "scenes")
    args = parser.parse_args()

    import gmsh

    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        directions, triangles = sphere_triangulation(args.volume_size)
        surface = push_to_surface(directions)
        points, tetrahedra = tetrahedralize(surface, outward(surface, triangles))
        directions, fine = sphere_triangulation(args.surface_size)
        visual = push_to_surface(directions)
        fine = outward(visual, fine)
    finally:
        gmsh.finalize()

    a, b, c, d = (points[tetrahedra[:, k]] for k in range(4))
    volumes = np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0
    negative = volumes < 0
    tetrahedra[negative] = tetrahedra[negative][:, [0, 2, 1, 3]]
    used = np.unique(tetrahedra)
    if len(used) != len(points):
        raise SystemExit(f"{len(points) - len(used)} nodes belong to no tetrahedron")

    args.out.mkdir(parents=True, exist_ok=True)
    write_msh(args.out / "liver.msh", points, tetrahedra)
    write_obj(args.out / "liver-surface.obj", visual, fine)
    fixed = [int(np.argmin(np.linalg.norm(points - p, axis=1))) for p in ATTACHMENTS]
    print(f"{len(points)} nodes, {len(tetrahedra)} tetrahedra, volume {abs(volumes).sum():.6g} m^3")
    print(f"visual surface: {len(visual)} points, {len(fine)} triangles")
    print(f"bounding box: {points.min(axis=0)} .. {points.max(axis=0)}")
    print("fixed nodes (scenes/liver.scn, FixedProjectiveConstraint indices):", *fixed)


if __name__ == "__main__":
    main()
