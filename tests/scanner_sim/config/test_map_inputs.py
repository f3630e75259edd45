"""Scenes in map coordinates: [longitude, latitude] positions (``lonlat: true``) converted to the scene's crs, and
survey lines from a GeoJSON or CSV line plan."""

import json
import math

import pytest

from scanner_sim.config import ConfigError, parse_scene

#: [m] One degree of longitude at latitude 50.5 deg on the WGS 84 ellipsoid, times UTM's central scale 0.9996:
#: pi/180 a cos(lat) / sqrt(1 - e^2 sin^2 lat), a second way to the eastings pyproj gives near the central meridian.
A, E2 = 6_378_137.0, 0.00669437999014
LAT = math.radians(50.5)
DEG_EAST_M = 0.9996 * math.pi / 180 * A * math.cos(LAT) / math.sqrt(1 - E2 * math.sin(LAT) ** 2)


def scene(tmp_path, platform, **top):
    return parse_scene({"format_version": 1, "name": "chart", "platform": {"depth_m": 5.0, **platform}, **top},
                       base_dir=tmp_path)


def test_lonlat_waypoints_become_utm_eastings_and_northings(tmp_path):
    """On zone 31's central meridian (3 deg E) a point's easting is 500,000 m exactly; 0.001 deg east of it lies
    0.001 x DEG_EAST_M further (to 0.1 m: the projection's curvature over 70 m)."""
    cfg = scene(tmp_path, {"waypoints_m": [[3.0, 50.5], [3.001, 50.5]]}, crs=32631, lonlat=True)
    (x0, y0), (x1, y1) = cfg.platform.waypoints_m
    assert x0 == pytest.approx(500_000.0, abs=1e-6) and 5_590_000 < y0 < 5_600_000
    assert x1 - x0 == pytest.approx(0.001 * DEG_EAST_M, abs=0.1) and y1 == pytest.approx(y0, abs=0.01)


def test_lonlat_scene_is_converted_once_through_overrides(tmp_path):
    """An override re-validates the scene from the positions as given, not from the converted ones."""
    cfg = scene(tmp_path, {"waypoints_m": [[3.0, 50.5], [3.001, 50.5]]}, crs=32631, lonlat=True)
    again = cfg.with_overrides({"survey.seed": 4})
    assert again.platform.waypoints_m == cfg.platform.waypoints_m and again.lonlat


def test_lonlat_needs_crs_and_degrees(tmp_path):
    with pytest.raises(ConfigError, match=r"^lonlat: longitude/latitude need the scene's crs"):
        scene(tmp_path, {"waypoints_m": [[3.0, 50.5], [3.001, 50.5]]}, lonlat=True)
    with pytest.raises(ConfigError, match=r"^platform\.waypoints_m = .*out of range .*longitude first"):
        scene(tmp_path, {"waypoints_m": [[500000.0, 5600000.0], [500010.0, 5600000.0]]}, crs=32631, lonlat=True)


def test_geojson_and_csv_line_plans_give_the_same_track(tmp_path):
    """Two lines of a GeoJSON plan (lon/lat) run in order, joined end to start; a CSV plan of the same lines in map
    coordinates gives the same waypoints (to 1 mm), and one in lon, lat too."""
    lines = [[[3.0, 50.5], [3.001, 50.5]], [[3.001, 50.5001], [3.0, 50.5001]]]
    features = [{"type": "Feature", "properties": {}, "geometry": {"type": "LineString", "coordinates": c}}
                for c in lines]
    (tmp_path / "plan.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    from_geojson = scene(tmp_path, {"line_plan": "plan.geojson"}, crs=32631).platform.waypoints_m
    assert len(from_geojson) == 4
    rows = [f"{i + 1},{x!r},{y!r}" for i, pts in enumerate([from_geojson[:2], from_geojson[2:]]) for x, y in pts]
    (tmp_path / "plan.csv").write_text("line,x,y\n" + "\n".join(rows) + "\n")
    from_csv = scene(tmp_path, {"line_plan": "plan.csv"}).platform.waypoints_m
    (tmp_path / "plan_ll.csv").write_text("line,lon,lat\n" + "\n".join(
        f"{i + 1},{lon},{lat}" for i, pts in enumerate(lines) for lon, lat in pts) + "\n")
    from_ll = scene(tmp_path, {"line_plan": "plan_ll.csv"}, crs=32631).platform.waypoints_m
    for a, b, c in zip(from_geojson, from_csv, from_ll):
        assert a == pytest.approx(b, abs=1e-3) and a == pytest.approx(c, abs=1e-3)
    assert from_geojson[0][0] == pytest.approx(500_000.0, abs=1e-6)
    assert scene(tmp_path, {"line_plan": "plan.csv"}).with_overrides({"survey.seed": 2}).platform.waypoints_m == from_csv


def test_bad_line_plan_is_one_line(tmp_path):
    (tmp_path / "points.geojson").write_text(json.dumps({"type": "Point", "coordinates": [3.0, 50.5]}))
    with pytest.raises(ConfigError, match=r"^platform\.line_plan = 'points\.geojson': a Point geometry"):
        scene(tmp_path, {"line_plan": "points.geojson"}, crs=32631)
    with pytest.raises(ConfigError, match=r"^platform\.line_plan = 'missing\.csv': file not found"):
        scene(tmp_path, {"line_plan": "missing.csv"})


def test_lonlat_places_the_seabed_and_objects_too(tmp_path):
    """The procedural seabed's centre and an object's position are plan positions: converted with the waypoints
    (zone 31's central meridian: easting 500,000 m; 0.00025 deg east of it: 0.00025 x DEG_EAST_M further)."""
    cfg = parse_scene({"format_version": 1, "name": "chart", "crs": 32631, "lonlat": True,
                       "seabed": {"size_m": [60.0, 20.0], "center_m": [3.00025, 50.5], "depth_m": 20.0},
                       "objects": [{"type": "cone_mine", "position_m": [3.0, 50.5]}],
                       "platform": {"altitude_m": 4.0, "waypoints_m": [[3.0, 50.5], [3.0005, 50.5]]}},
                      base_dir=tmp_path)
    assert cfg.objects[0].position_m[0] == pytest.approx(500_000.0, abs=1e-6)
    assert cfg.seabed.center_m[0] == pytest.approx(500_000.0 + 0.00025 * DEG_EAST_M, abs=0.05)
    assert cfg.objects[0].position_m[1] == pytest.approx(cfg.platform.waypoints_m[0][1])
