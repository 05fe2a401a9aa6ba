"""Mesh units (issue 33, item 2): a COLLADA file's ``<unit meter=...>`` is honoured, STL is metres times the URDF
``scale``, and a link whose mesh is far off its link's size gets a note (the usual sign of millimetres read as
metres: myCobot's finger DAE declares millimetres and loaded 1000 times too large, with no word); its ``<up_axis>`` is
not applied, as RViz and MoveIt read it."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh

from roarmctl.errors import DescriptionError
from roarmctl.robot.loader import load_robot
from roarmctl.robot.meshes import read_triangles

EXTENTS = (100.0, 40.0, 20.0)  # the box's size in the file's own unit


def dae(unit: float | None, extents=EXTENTS) -> bytes:
    """A COLLADA box of ``extents`` file units, declaring ``<unit meter=unit>`` (none: no <unit>)."""
    text = trimesh.creation.box(extents=extents).export(file_type="dae").decode()
    if unit is not None:
        text = text.replace("<asset>", f'<asset>\n    <unit meter="{unit!r}" name="u"/>', 1)
    return text.encode()


@pytest.mark.parametrize("unit", [None, 1.0, 0.001, 0.01, 0.0254, 2.5])
def test_collada_unit_scales_the_vertices_as_pycollada_reads_it(tmp_path, unit):
    import collada

    path = tmp_path / "m.dae"
    path.write_bytes(dae(unit))
    parsed = collada.Collada(str(path))  # independent reading: pycollada's own unit and raw vertices
    metres = parsed.assetInfo.unitmeter or 1.0
    raw = np.vstack([p.vertex for g in parsed.geometries for p in g.primitives]).astype(float)
    v, _ = read_triangles(path, 1.0, "mesh")
    assert np.allclose(np.ptp(v, axis=0), np.ptp(raw, axis=0) * metres, rtol=1e-12)
    assert np.allclose(np.ptp(v, axis=0), np.array(EXTENTS) * (unit or 1.0), rtol=1e-12)
    v2, _ = read_triangles(path, [2.0, 1.0, 0.5], "mesh")  # the URDF's scale multiplies on top
    assert np.allclose(np.ptp(v2, axis=0), np.ptp(v, axis=0) * [2.0, 1.0, 0.5], rtol=1e-12)


@pytest.mark.parametrize("unit", ["0", "-1", "1e9"])
def test_a_collada_unit_that_is_no_length_is_refused(tmp_path, unit):
    path = tmp_path / "m.dae"
    path.write_bytes(re.sub(rb'meter="[^"]*"', f'meter="{unit}"'.encode(), dae(0.001)))
    with pytest.raises(DescriptionError, match=r"<unit meter=.*not a length unit"):
        read_triangles(path, 1.0, "mesh", error=DescriptionError)


#: A node transform (a quarter turn about z and a shift, in file units) so that the file's frames matter.
NODE_MATRIX = "<matrix>0 -1 0 30  1 0 0 -5  0 0 1 7  0 0 0 1</matrix>"


def assimp_cli():
    """The ``assimp`` command of the cmeel-assimp wheel (Pinocchio's dependency) and its library folder; None without."""
    import sysconfig

    prefix = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix"
    return (prefix / "bin" / "assimp", prefix / "lib") if (prefix / "bin" / "assimp").is_file() else None


def assimp_vertices(path: Path, tmp: Path) -> np.ndarray:
    """The distinct vertices assimp makes of ``path`` with every node transform applied (``export -ptv``)."""
    cli = assimp_cli()
    if cli is None:
        pytest.skip("no assimp command (cmeel-assimp)")
    out = tmp / (path.stem + ".obj")
    subprocess.run([str(cli[0]), "export", str(path), str(out), "-ptv"], env={**os.environ, "LD_LIBRARY_PATH": str(cli[1])},
                   check=True, capture_output=True, timeout=60)
    return np.unique(np.round(trimesh.load(out, process=False, force="mesh").vertices, 7), axis=0)


@pytest.mark.parametrize("unit", [None, 0.001, 0.0254])
@pytest.mark.parametrize("up", ["Z_UP", "Y_UP", "X_UP", None])
def test_collada_up_axis_is_not_applied_as_rviz_and_moveit_read_it(tmp_path, unit, up):
    """RViz and MoveIt (geometric_shapes) read a COLLADA file with assimp and drop the rotation assimp puts on its
    root for a file that is not Y_UP, keeping the unit's scale (ros-visualization/rviz#1689, moveit/geometric_shapes
    #52): a robot's mesh is in its link's frame whatever <up_axis> says. So roarmctl's triangles for every <up_axis>
    (and none) equal assimp's for the same file marked Y_UP (assimp's own convention: no root rotation), the node
    transform and the unit applied; and assimp itself turns the Z_UP and X_UP files (the rotation dropped)."""
    base = dae(unit).decode().replace('<node id="node0" name="node0">', f'<node id="node0" name="node0">{NODE_MATRIX}', 1)
    assert NODE_MATRIX in base

    def variant(axis):
        text = re.sub(r"<up_axis>.*?</up_axis>", f"<up_axis>{axis}</up_axis>" if axis else "", base)
        path = tmp_path / f"m_{axis}.dae"
        path.write_text(text)
        return path

    reference = assimp_vertices(variant("Y_UP"), tmp_path)
    v, _ = read_triangles(variant(up), 1.0, "mesh")
    ours = np.unique(np.round(v, 7), axis=0)
    assert ours.shape == reference.shape and np.allclose(ours, reference, atol=1e-6)
    if up in ("Z_UP", "X_UP"):  # what the ROS tools undo: assimp's own reading turns the mesh
        assert not np.allclose(assimp_vertices(variant(up), tmp_path), reference, atol=1e-6)


PUBLISHED = Path(__file__).parent / "data" / "collada" / "ur5e"


def test_a_published_z_up_collada_lies_where_its_collision_stl_does(tmp_path):
    """UR5e's wrist-3 visual DAE (published, <up_axis>Z_UP</up_axis>) and its collision STL sit at one origin in UR's
    URDF: read as roarmctl reads them (up_axis not applied) their boxes agree to 0.5 mm, and the triangles equal
    assimp's of the file marked Y_UP (RViz's reading); assimp's own reading of the Z_UP file is turned (a box
    off by centimetres), the rotation RViz and MoveIt drop."""
    dae_text = (PUBLISHED / "wrist3.dae").read_text()
    assert "<up_axis>Z_UP</up_axis>" in dae_text
    v, _ = read_triangles(PUBLISHED / "wrist3.dae", 1.0, "mesh")
    c, _ = read_triangles(PUBLISHED / "wrist3.stl", 1.0, "mesh")
    assert np.allclose(v.min(axis=0), c.min(axis=0), atol=5e-4) and np.allclose(v.max(axis=0), c.max(axis=0), atol=5e-4)
    (tmp_path / "y_up.dae").write_text(dae_text.replace("<up_axis>Z_UP</up_axis>", "<up_axis>Y_UP</up_axis>"))
    reference = assimp_vertices(tmp_path / "y_up.dae", tmp_path)
    ours = np.unique(np.round(v, 7), axis=0)
    assert ours.shape == reference.shape and np.allclose(ours, reference, atol=1e-6)
    turned = assimp_vertices(PUBLISHED / "wrist3.dae", tmp_path)
    assert np.abs(turned.max(axis=0) - c.max(axis=0)).max() > 0.01


URDF = """<robot name="r">
  <link name="base"/>
  <link name="l1"><collision><geometry><mesh filename="{mesh}"{scale}/></geometry></collision></link>
  <link name="l2"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.1 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


@pytest.mark.parametrize("mesh, scale, noted", [
    ("mm.stl", "", True),  # 100 mm read as 100 m
    ("mm.stl", ' scale="0.001 0.001 0.001"', False),
    ("mm.dae", "", False),  # declares millimetres
    ("plain.dae", "", True),  # no <unit>: metres, 100 m
    ("tiny.stl", "", True),  # 0.1 mm across for a 10 cm link
])
def test_a_mesh_far_off_its_link_size_gets_a_note(tmp_path, mesh, scale, noted):
    (tmp_path / "mm.stl").write_bytes(trimesh.creation.box(extents=EXTENTS).export(file_type="stl"))
    (tmp_path / "tiny.stl").write_bytes(trimesh.creation.box(extents=(1e-4, 1e-4, 1e-4)).export(file_type="stl"))
    (tmp_path / "mm.dae").write_bytes(dae(0.001))
    (tmp_path / "plain.dae").write_bytes(dae(None))
    (tmp_path / "arm.urdf").write_text(URDF.format(mesh=mesh, scale=scale))
    robot = load_robot(str(tmp_path / "arm.urdf"))
    said = [n for n in robot.notes if "more than 10x off the link's size" in n]
    assert bool(said) == noted, robot.notes
    if noted:
        assert "l1 (" in said[0]
    shape = next(s for s in robot.collision if s.link == "l1")
    size = float(np.max(np.ptp(shape.mesh.vertices, axis=0)))
    assert size == pytest.approx({"mm.stl": 0.1 if scale else 100.0, "mm.dae": 0.1, "plain.dae": 100.0,
                                  "tiny.stl": 1e-4}[mesh], rel=1e-6)  # STL holds float32


@pytest.mark.slow
def test_no_published_arm_of_the_corpus_gets_the_note():
    for sidecar in sorted((Path(__file__).parent / "data" / "arms").glob("*/robot.yaml")):
        robot = load_robot(str(sidecar))
        assert not [n for n in robot.notes if "off the link's size" in n], sidecar
