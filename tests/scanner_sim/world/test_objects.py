"""The objects' meshes: every object type the scene format accepts has a builder, and a builder's mesh is the solid
its keys describe (closed, outward, of the volume and extent its sizes give, lying along its heading)."""

import math

import numpy as np
import pytest
import trimesh

from scanner_sim.config.geometry import OBJECT_TYPES, ConeMineObject, CylinderMineObject
from scanner_sim.world.objects import OBJECT_BUILDERS, object_mesh


def test_every_object_type_of_the_scene_format_has_a_builder():
    assert set(OBJECT_BUILDERS) == set(OBJECT_TYPES.values())


def _solid(mesh) -> trimesh.Trimesh:
    solid = trimesh.Trimesh(mesh.vertices, mesh.faces, process=True)
    assert solid.is_watertight
    return solid


@pytest.mark.parametrize("heading_deg, along", [(0.0, 1), (90.0, 0)])
def test_a_cylinder_mine_lies_along_its_compass_heading_buried_by_its_share_of_the_diameter(heading_deg, along):
    """Heading 0 is north (+y), 90 east (+x); the axis is horizontal; burial 0.25 puts half a radius below ground."""
    r, length, ground = 0.3, 2.0, -10.0
    obj = CylinderMineObject(type="cylinder_mine", position_m=[4.0, -2.0, ground], radius_m=r, length_m=length,
                             heading_deg=heading_deg, burial_fraction=0.25)
    solid = _solid(object_mesh(obj, 0, None))
    lo, hi = solid.bounds
    assert hi[along] - lo[along] == pytest.approx(length, abs=1e-9)
    assert hi[1 - along] - lo[1 - along] == pytest.approx(2 * r, abs=1e-9)
    assert lo[2] == pytest.approx(ground - 0.5 * r, abs=1e-9)
    assert 0.5 * (lo[:2] + hi[:2]) == pytest.approx([4.0, -2.0], abs=1e-9)
    # 32 sections: the inscribed polygon's area, (n/2) sin(2 pi/n) r^2; positive: the normals point outward
    assert solid.volume == pytest.approx(16 * math.sin(2 * math.pi / 32) * r**2 * length, rel=1e-9)


def test_a_cone_mine_stands_on_the_ground_with_the_volume_of_its_frustum():
    r1, r2, h = 0.5, 0.2, 0.4
    obj = ConeMineObject(type="cone_mine", position_m=[0.0, 0.0, -5.0], bottom_radius_m=r1, top_radius_m=r2, height_m=h)
    solid = _solid(object_mesh(obj, 0, None))
    assert solid.bounds[:, 2] == pytest.approx([-5.0, -5.0 + h])
    # a frustum of regular 32-gons: h/3 (A1 + A2 + sqrt(A1 A2)), A = 16 sin(2 pi/32) r^2
    area = lambda r: 16 * math.sin(2 * math.pi / 32) * r**2  # noqa: E731
    assert solid.volume == pytest.approx(h / 3 * (area(r1) + area(r2) + np.sqrt(area(r1) * area(r2))), rel=1e-9)
