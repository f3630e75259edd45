"""Plan positions given on a chart: longitude/latitude (``lonlat: true``) and survey lines from a line-plan file
(``platform.line_plan``: GeoJSON or CSV), both turned into the scene's map coordinates before validation.

- ``lonlat: true`` (needs ``crs``): every plan position of the file is [longitude, latitude] in degrees, WGS 84,
  longitude first (GeoJSON's order): ``platform.waypoints_m``, ``platform.position_m``,
  ``platform.lawnmower.center_m``, ``seabed.center_m`` and the objects' ``position_m``, ``points_m``,
  ``center_m`` and ``translate_m`` (a third number, z, stays metres). pyproj converts them to the
  ``crs``'s eastings and northings.
- ``platform.line_plan`` (mode ``waypoints``, in place of ``waypoints_m``): the survey lines, run in the file's
  order, each from its first point to its last, with a straight transit from one line's end to the next one's
  start. GeoJSON: LineString or MultiLineString features, in longitude/latitude (WGS 84, as RFC 7946 has it)
  converted to ``crs``. CSV: a header naming ``line`` and either ``x, y`` (map coordinates) or ``lon, lat``.

The scene keeps the converted values (what every stage reads) and :func:`restore_given` puts the values as given
back before overrides re-validate it, so a scene converted once is never converted twice.
"""

from __future__ import annotations

import copy
import csv
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from scanner_sim.config.errors import ConfigError

#: Object keys whose first two numbers are a plan position, and whether they hold a list of positions.
OBJECT_POSITIONS = {"position_m": False, "center_m": False, "translate_m": False, "points_m": True}


def to_map(data: Any, base_dir: Path | None) -> tuple[Any, dict]:
    """``data`` (a scene mapping) with its lon/lat positions and its line plan in map coordinates, and what was
    given in their place ({dotted path tuple: value}, :func:`restore_given`). Raises :class:`ConfigError`."""
    if not isinstance(data, Mapping):
        return data, {}
    platform = data.get("platform")
    lonlat = data.get("lonlat") is True
    plan = platform.get("line_plan") if isinstance(platform, Mapping) else None
    if not lonlat and plan is None:
        return data, {}
    if data.get("crs") is None and (lonlat or str(plan).lower().endswith((".geojson", ".json"))):
        key = "lonlat" if lonlat else "platform.line_plan"
        raise ConfigError(f"{key}: longitude/latitude need the scene's crs (a projected CRS in metres, e.g. the UTM "
                          "zone of the site) to convert them to")
    out, given = copy.deepcopy(dict(data)), {}
    project = _projector(data.get("crs")) if data.get("crs") is not None else None
    if lonlat:
        places = [(("platform", "waypoints_m"), True), (("platform", "position_m"), False),
                  (("platform", "lawnmower", "center_m"), False), (("seabed", "center_m"), False)]
        places += [(("objects", i, key), many) for i, obj in enumerate(data.get("objects") or ())
                   if isinstance(obj, Mapping) for key, many in OBJECT_POSITIONS.items() if key in obj]
        for path, many in places:
            value = _get(out, path)
            if value is not None:
                given[path] = copy.deepcopy(value)
                _set(out, path, _converted(value, many, project, ".".join(map(str, path))))
    if plan is not None:
        if isinstance(platform, Mapping) and platform.get("waypoints_m") is not None:
            raise ConfigError("platform.line_plan: give either line_plan or waypoints_m, not both")
        given[("platform", "waypoints_m")] = None
        out["platform"] = {**out["platform"], "waypoints_m": read_line_plan(plan, base_dir, project)}
    return out, given


def restore_given(data: dict, given: dict) -> dict:
    """``data`` (a dumped scene) with the values :func:`to_map` converted put back as given (None: removed)."""
    for path, value in given.items():
        if value is None:
            parent = _get(data, path[:-1])
            if isinstance(parent, dict):
                parent.pop(path[-1], None)
        elif _get(data, path[:-1]) is not None:
            _set(data, path, copy.deepcopy(value))
    return data


def read_line_plan(plan: Any, base_dir: Path | None, project) -> list[list[float]]:
    """The waypoints [[x, y], ...] [m] of a line-plan file (GeoJSON or CSV), lines in the file's order."""
    key = "platform.line_plan"
    if not isinstance(plan, str):
        raise ConfigError(f"{key} = {plan!r}: must be a path to a GeoJSON or CSV file, relative to the scene file")
    path = Path(plan) if Path(plan).is_absolute() else Path(base_dir or Path.cwd()) / plan
    if not path.is_file():
        raise ConfigError(f"{key} = {plan!r}: file not found (looked for {path})")
    try:
        lines = _geojson_lines(path, project) if path.suffix.lower() in (".geojson", ".json") else _csv_lines(
            path, project)
    except (ValueError, KeyError, TypeError, IndexError) as exc:
        raise ConfigError(f"{key} = {plan!r}: {' '.join(str(exc).split())[:160]}") from None
    lines = [line for line in lines if len(line) >= 2]
    if not lines:
        raise ConfigError(f"{key} = {plan!r}: holds no line of two points or more")
    return [list(map(float, p)) for line in lines for p in line]


#: What a GeoJSON line plan holds, for the messages.
GEOJSON_PLAN = "a GeoJSON FeatureCollection of LineString or MultiLineString features (or one such Feature or geometry)"


def _geojson_lines(path: Path, project) -> list[list]:
    doc = json.loads(path.read_text())
    if not isinstance(doc, dict):
        raise ValueError(f"the file holds a JSON {type(doc).__name__}; a line plan is {GEOJSON_PLAN}")
    features = doc.get("features") if doc.get("type") == "FeatureCollection" else [doc]
    if not isinstance(features, list):
        raise ValueError(f"its FeatureCollection's features are {features!r:.40}, not a list; a line plan is "
                         f"{GEOJSON_PLAN}")
    lines = []
    for k, feature in enumerate(features):
        geometry = feature.get("geometry", feature) if isinstance(feature, dict) else None
        if not isinstance(geometry, dict):
            raise ValueError(f"{'a null' if geometry is None else 'no'} geometry (feature {k}); a line plan is "
                             f"{GEOJSON_PLAN}")
        kind, coords = geometry.get("type"), geometry.get("coordinates")
        parts = [coords] if kind == "LineString" else coords if kind == "MultiLineString" else None
        if parts is None:
            raise ValueError(f"a {kind} geometry (feature {k}); a line plan holds LineString or MultiLineString "
                             "features")
        if not isinstance(parts, list) or not all(isinstance(part, list) for part in parts):
            raise ValueError(f"feature {k}'s coordinates are {coords!r:.40}; a {kind} has lists of [longitude, "
                             "latitude]")
        try:
            lines += [_converted(part, True, project, "coordinates") for part in parts]
        except ConfigError as exc:
            raise ValueError(f"feature {k}'s {exc}") from None
    return lines


def _csv_lines(path: Path, project) -> list[list]:
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError("no rows under the header")
    names = {k.strip().lower(): k for k in rows[0]}
    geographic = "lon" in names and "lat" in names
    if not geographic and not ("x" in names and "y" in names):
        raise ValueError(f"the header names {list(rows[0])}; it needs line and x, y (map) or lon, lat (degrees)")
    a, b = (names["lon"], names["lat"]) if geographic else (names["x"], names["y"])
    if geographic and project is None:
        raise ValueError("lon, lat columns need the scene's crs to convert them to")
    lines: dict[str, list] = {}
    for number, row in enumerate(rows, start=2):  # the header is the file's line 1
        lines.setdefault(row[names["line"]].strip() if "line" in names else "1", []).append(
            [_csv_number(row, column, number) for column in (a, b)])
    out = list(lines.values())
    return [_converted(line, True, project, "lon, lat") for line in out] if geographic else out


def _csv_number(row: dict, column: str, number: int) -> float:
    """The finite number in ``column`` of a line plan's CSV ``row`` (line ``number`` of the file)."""
    text = row.get(column)
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = math.nan
    if not math.isfinite(value):
        raise ValueError(f"line {number}, column {column!r} = {text!r}: must be a finite number "
                         f"({'map coordinates, metres' if column.strip().lower() in ('x', 'y') else 'degrees'})")
    return value


def _projector(crs):
    """(lon, lat) degrees WGS 84 -> (x, y) [m] in ``crs`` (the scene key's value)."""
    from pyproj import Transformer

    from scanner_sim.config.crs import horizontal_crs, to_crs

    transformer = Transformer.from_crs("EPSG:4326", horizontal_crs(to_crs(crs)), always_xy=True)
    return transformer.transform


def _converted(value, many: bool, project, where: str):
    points = value if many else [value]
    out = []
    for p in points:
        if not isinstance(p, (list, tuple)) or len(p) < 2 or not all(isinstance(c, (int, float)) for c in p):
            raise ConfigError(f"{where} = {value!r}: [longitude, latitude] in degrees, numbers")
        lon, lat = float(p[0]), float(p[1])
        if not (-180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0):
            raise ConfigError(f"{where} = {value!r}: longitude {lon:g} or latitude {lat:g} out of range (lonlat: true "
                              "takes [longitude, latitude] in degrees, longitude first)")
        x, y = project(lon, lat)
        out.append([float(x), float(y), *map(float, p[2:])])
    return out if many else out[0]


def _get(node, path):
    for item in path:
        if isinstance(node, Mapping) and item in node:
            node = node[item]
        elif isinstance(node, list) and isinstance(item, int) and item < len(node):
            node = node[item]
        else:
            return None
    return node


def _set(node, path, value):
    for item in path[:-1]:
        node = node[item]
    node[path[-1]] = value
