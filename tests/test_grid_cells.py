"""The cells of a 3-D RegularGridTopology, numbered as SOFA's GridTopology::GridUpdate makes them
(points x + nx (y + ny z))."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sofac.check.checker import check_file

SCENE = """\
<Node name="root"><DefaultAnimationLoop/>
  <RegularGridTopology name="grid" n="2 2 2" min="0 0 0" max="1 1 1" {flags}/>
  <MechanicalObject name="dofs"/>
</Node>
"""


def _cells(tmp_path: Path, flags: str = "") -> dict[str, list[list[int]]]:
    path = tmp_path / "grid.scn"
    path.write_text(SCENE.format(flags=flags))
    checked, diags = check_file(path)
    assert diags.errors == []
    grid = next(c for c in checked.scene.root.components() if c.type_name == "RegularGridTopology")
    out = {}
    for kind, corners in (("hexahedra", 8), ("quads", 4), ("triangles", 3), ("edges", 2)):
        value = checked.value(grid, kind)
        out[kind] = [] if value is None else np.asarray(value, dtype=np.int64).reshape(-1, corners).tolist()
    return out


def test_a_cube_has_sofas_quads_triangles_and_edges(tmp_path: Path) -> None:
    cells = _cells(tmp_path)
    assert cells["hexahedra"] == [[0, 1, 3, 2, 4, 5, 7, 6]]
    # XY planes (z = 0, 1), then XZ (y = 0, 1), then YZ (x = 0, 1)
    quads = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
    assert cells["quads"] == quads
    assert cells["triangles"] == [t for q in quads for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])]
    # createEdgeSetArray on those triangles: (t1 t2) (t2 t0) (t0 t1), each pair once, first met
    assert cells["edges"][:5] == [[1, 3], [3, 0], [0, 1], [3, 2], [2, 0]]
    assert len(cells["edges"]) == 12 + 6  # the cube's edges and one diagonal per face


def test_without_triangles_the_edges_are_the_grid_lines(tmp_path: Path) -> None:
    cells = _cells(tmp_path, 'computeTriangleList="0" computeQuadList="0"')
    assert cells["quads"] == [] and cells["triangles"] == []
    x_lines = [[0, 1], [2, 3], [4, 5], [6, 7]]
    y_lines = [[0, 2], [1, 3], [4, 6], [5, 7]]
    z_lines = [[0, 4], [1, 5], [2, 6], [3, 7]]
    assert cells["edges"] == x_lines + y_lines + z_lines


GRID_SCENE = """\
<Node name="root" gravity="0 -9.81 0" dt="0.01"><DefaultAnimationLoop/>
  <Node name="a"><EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
    <CGLinearSolver iterations="100" tolerance="1e-20" threshold="1e-30"/>
    <RegularGridTopology name="grid" n="3 2 2" min="0 0 0" max="2 1 1"/>
    <MechanicalObject name="regular"/>
    <UniformMass totalMass="1"/>
    <FixedProjectiveConstraint indices="0 3 6 9"/>
    <HexahedronFEMForceField youngModulus="1000" poissonRatio="0.3"/>
  </Node>
  <Node name="b"><EulerImplicitSolver rayleighStiffness="0" rayleighMass="0"/>
    <CGLinearSolver iterations="100" tolerance="1e-20" threshold="1e-30"/>
    <GridTopology name="grid" n="3 2 2"/>
    <MechanicalObject name="plain" position="{points}"/>
    <UniformMass totalMass="1"/>
    <FixedProjectiveConstraint indices="0 3 6 9"/>
    <HexahedronFEMForceField youngModulus="1000" poissonRatio="0.3"/>
  </Node>
  <Node name="c">
    <GridTopology name="short" n="2 2 1" position="1 2 3"/>
    <MechanicalObject name="padded"/>
  </Node>
</Node>
"""
LATTICE = [(x, y, z) for z in range(2) for y in range(2) for x in range(3)]


def test_grid_topology_gives_regular_grid_cells_to_the_states_points(tmp_path: Path) -> None:
    """GridTopology has no geometry: with the MechanicalObject's points on the same lattice, the
    cells (GridUpdate's) and so the whole run are RegularGridTopology's."""
    from sofac.pipeline import compile_scene

    path = tmp_path / "grids.scn"
    path.write_text(GRID_SCENE.format(points="  ".join(f"{x} {y} {z}" for x, y, z in LATTICE)))
    checked, diags = check_file(path)
    assert diags.errors == []
    regular, plain = (
        next(c for c in checked.scene.root.components() if c.type_name == kind)
        for kind in ("RegularGridTopology", "GridTopology")
    )
    for kind in ("hexahedra", "quads", "triangles", "edges"):
        assert np.array_equal(checked.value(regular, kind), checked.value(plain, kind)), kind
    simulation = compile_scene(path).instantiate()
    simulation.step(5)
    assert np.array_equal(simulation["regular"].position, simulation["plain"].position)
    assert simulation["plain"].position[2, 1] < 0  # it sagged


def test_grid_topology_points_are_its_position_list_resized(tmp_path: Path) -> None:
    """SOFA's GridTopology::getPoint reads its own position list: nx ny nz points, 0 0 0 past the
    end of the list (and every point at the origin without one)."""
    path = tmp_path / "grids.scn"
    path.write_text(GRID_SCENE.format(points="  ".join(f"{x} {y} {z}" for x, y, z in LATTICE)))
    checked, diags = check_file(path)
    assert diags.errors == []
    padded = next(c for c in checked.scene.root.components() if c.label == "padded")
    assert checked.positions(padded).tolist() == [[1, 2, 3], [0, 0, 0], [0, 0, 0], [0, 0, 0]]


def test_grid_topology_resolution_below_one_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "bad.scn"
    path.write_text(
        '<Node name="root"><DefaultAnimationLoop/>\n  <GridTopology n="0 2 2"/>\n'
        "  <MechanicalObject/>\n</Node>\n"
    )
    _, diags = check_file(path)
    assert [(d.code, d.loc.line) for d in diags.errors] == [("E207", 2)]


def test_grid_read_through_src_has_the_legacy_resolution(tmp_path: Path) -> None:
    """Component/Visual/DataDisplay.scn: a grid given by nx ny nz / xmin..zmax, read by another
    RegularGridTopology through src=: SOFA's parse wrote them into n, min and max, which src links,
    so the second grid has the 100 points too (index 99 is valid)."""
    path = tmp_path / "src.scn"
    path.write_text(
        '<Node name="root"><DefaultAnimationLoop/>\n'
        '  <Node name="Mesh">\n'
        '    <RegularGridTopology name="Grid" nx="10" ny="10" nz="1" xmin="0" xmax="9" ymin="0" ymax="9" '
        'zmin="0" zmax="1"/>\n'
        '    <MechanicalObject name="MO"/>\n'
        "  </Node>\n"
        '  <Node name="Simulation">\n'
        '    <RegularGridTopology src="@/Mesh/Grid"/>\n'
        '    <MechanicalObject name="dofs"/>\n'
        '    <FixedProjectiveConstraint indices="0 9 99"/>\n'
        "  </Node>\n"
        "</Node>\n"
    )
    checked, diags = check_file(path)
    assert diags.errors == [] and diags.warnings == []
    states = {c.label: c for c in checked.scene.root.components() if c.type_name == "MechanicalObject"}
    source, copy = checked.positions(states["MO"]), checked.positions(states["dofs"])
    assert source.shape == (100, 3) and np.array_equal(source, copy)
    assert source[99].tolist() == [9.0, 9.0, 0.0]
