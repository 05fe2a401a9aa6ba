"""Mesh units (issue 33, item 2): a COLLADA file's ``<unit meter=...>`` is honoured, STL is metres times the URDF
``scale``, and a link whose mesh is far off its link's size gets a note (the usual sign of millimetres read as
metres: myCobot's finger DAE declares millimetres and loaded 1000 times too large, with no word)."""

from __future__ import annotations

import re
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


def test_no_published_arm_of_the_corpus_gets_the_note():
    for sidecar in sorted((Path(__file__).parent / "data" / "arms").glob("*/robot.yaml")):
        robot = load_robot(str(sidecar))
        assert not [n for n in robot.notes if "off the link's size" in n], sidecar
