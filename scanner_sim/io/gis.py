"""GIS files of a pass in map coordinates: Cloud-Optimized GeoTIFF rasters (rasterio, GDAL's ``COG`` driver) and
GeoJSON feature collections that carry their CRS in a ``crs`` member, each written atomically.

The GeoJSON stays in the scene's map CRS (easting, northing [, z] in metres), named in a ``crs`` member as GDAL
reads and writes it, rather than reprojected to longitude/latitude as RFC 7946 asks: the gap polygons follow
the coverage cells' straight edges and the tracks the survey's own coordinates, exactly, and overlay the point
cloud and the rasters without a transform (docs/outputs.md#gis-products).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence

import numpy as np

from muls.infra.atomic import PathLike, atomic_open, atomic_path
from scanner_sim.io.summary import jsonable

__all__ = ["crs_member", "write_cog", "write_geojson"]


def write_cog(path: PathLike, band: np.ndarray, x0_m: float, y0_m: float, cell_m: float, crs, *, nodata,
              name: str, tags: Mapping[str, str] | None = None) -> None:
    """One band (ny, nx) as a Cloud-Optimized GeoTIFF (deflate), atomically.

    Row 0 of ``band`` is the southern row (as the coverage grid holds it: row = y): it is written north-up.
    (``x0_m``, ``y0_m``) is the south-west corner of cell (0, 0) in ``crs`` (a :class:`pyproj.CRS`), cells are
    ``cell_m`` squares; ``nodata`` marks cells without a value; ``name`` is the band's description and ``tags``
    its metadata (units, the codes of a categorical band).
    """
    import rasterio
    from rasterio.transform import Affine

    ny, nx = band.shape
    profile = {"driver": "COG", "width": nx, "height": ny, "count": 1, "dtype": band.dtype.name, "nodata": nodata,
               "crs": crs.to_wkt(), "transform": Affine(cell_m, 0.0, x0_m, 0.0, -cell_m, y0_m + ny * cell_m),
               "compress": "deflate"}
    with atomic_path(path) as tmp, rasterio.open(tmp, "w", **profile) as ds:
        ds.write(band[::-1], 1)
        ds.set_band_description(1, name)
        ds.update_tags(1, **dict(tags or {}))


def crs_member(crs) -> dict:
    """The GeoJSON ``crs`` member naming ``crs`` (a :class:`pyproj.CRS`): its OGC URN
    (``urn:ogc:def:crs:EPSG::32631``) when it has an authority code, else its WKT (version 1, as GDAL reads it)."""
    from pyproj.enums import WktVersion

    code = crs.to_authority()
    name = f"urn:ogc:def:crs:{code[0]}::{code[1]}" if code else crs.to_wkt(WktVersion.WKT1_GDAL)
    return {"type": "name", "properties": {"name": name}}


def write_geojson(path: PathLike, name: str, crs, features: Sequence[Mapping]) -> None:
    """A GeoJSON FeatureCollection ``name`` of ``features`` (each ``{"type": "Feature", "properties": ...,
    "geometry": ...}``) in ``crs`` (a :class:`pyproj.CRS`, named by :func:`crs_member`), atomically, UTF-8."""
    collection = {"type": "FeatureCollection", "name": name, "crs": crs_member(crs), "features": list(features)}
    text = json.dumps(jsonable(collection), ensure_ascii=False, allow_nan=False)
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text + "\n")
