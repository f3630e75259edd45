"""The seabed from a bathymetry raster: the ``seabed`` section that names a ``raster`` (docs/scene-format.md).

The file is opened when the scene is validated, so ``scanner-sim validate`` refuses a raster without a CRS, with
a rotated grid, smaller than 2 x 2 or without the band, in one line naming the key; its pixels are read when
the scene is built (:mod:`scanner_sim.world.raster`), which refuses a window of nodata alone.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BeforeValidator, PlainSerializer, PrivateAttr, ValidationInfo, WithJsonSchema, model_validator

from scanner_sim.config.base import Choice, Integer, NonNegative, Positive, StrictModel
from scanner_sim.config.crs import not_metric, to_crs
from scanner_sim.config.errors import ConfigError, invalid
from scanner_sim.config.geometry import ReliefConfig, surface
from scanner_sim.config.sections import MAX_SEED


@dataclass(frozen=True)
class RasterGrid:
    """A bathymetry grid in memory, as a raster file would give it: heights (rows, cols) float [m], its affine
    ``transform`` (rasterio's ``Affine``: map x, y of a pixel's corner from (col, row)), CRS (anything pyproj
    reads), nodata value (or None; NaN cells are nodata too) and vertical sign ('elevation_up' or 'depth_down').
    A raster seabed section takes one in place of a file name (:mod:`scanner_sim.world.raster` reads both)."""

    heights: np.ndarray
    transform: object
    crs: object
    nodata: float | None = None
    vertical: str = "elevation_up"
    source: str = "in memory"


def check_grid(transform, width: int, height: int, crs) -> str | None:
    """What is wrong with a raster's grid for a seabed (no CRS, rotated, under 2 x 2), or None."""
    if crs is None or not str(crs):
        return ("the raster has no coordinate reference system; give it one (gdal_edit.py -a_srs EPSG:...) so that "
                "its map coordinates name a place")
    from pyproj.exceptions import CRSError

    try:
        problem = not_metric(to_crs(crs.to_wkt() if hasattr(crs, "to_wkt") else crs))
    except (CRSError, ValueError, TypeError):
        problem = f"{str(crs)[:60]!r} is not one pyproj reads"
    if problem:
        return (f"its CRS {problem}; the world frame is projected, in metres: reproject the raster to such a CRS "
                "first (gdalwarp -t_srs EPSG:..., the site's UTM zone)")
    if transform.b != 0 or transform.d != 0:
        return (f"the raster's grid is rotated or sheared (transform {tuple(round(t, 6) for t in transform)[:6]}); "
                "warp it north-up first (gdalwarp)")
    if width < 2 or height < 2:
        return f"a {width} x {height} grid; a seabed needs at least 2 x 2 cells"
    return None


def open_raster(path: Path, key: str, band: int = 1):
    """The rasterio dataset of ``path``, checked (:func:`check_grid`, the band); :class:`ConfigError` naming
    ``key`` otherwise. The caller closes it."""
    import rasterio

    try:
        ds = rasterio.open(path)
    except Exception as exc:  # rasterio raises RasterioIOError and GDAL's own errors for a file it cannot read
        raise ConfigError(f"{key} = {str(path)!r}: not a raster GDAL can read ({' '.join(str(exc).split())[:100]})"
                          ) from None
    problem = check_grid(ds.transform, ds.width, ds.height, ds.crs)
    if problem is None and not 1 <= band <= ds.count:
        problem = f"band {band} asked for, the raster has {ds.count}"
    if problem:
        ds.close()
        raise ConfigError(f"{key} = {str(path)!r}: {problem}")
    return ds


def read_pixels(ds, band: int, key: str, source: str, window=None) -> np.ndarray:
    """Band ``band`` of the open raster ``ds`` (in ``window``, default all of it); a file GDAL cannot read the
    pixels of (truncated, damaged, a header claiming more pixels than the file holds) is a :class:`ConfigError`
    naming ``key``, the file as the scene gives it (``source``) and the driver's reason."""
    from rasterio.errors import RasterioError

    try:
        return ds.read(band, window=window)
    except RasterioError as exc:  # GDAL's reason is the cause; rasterio's own message says only "Read failed"
        reason = " ".join(str(exc.__cause__ or exc).split())[:160]
        raise ConfigError(f"{key} = {source!r}: the {ds.driver} driver cannot read its pixels ({reason});"
                          " the file is truncated or damaged: write it again") from None


def _path_or_grid(value: Any) -> Any:
    if isinstance(value, dict) and set(value) == set(RasterGrid.__dataclass_fields__):
        value = RasterGrid(**value)  # a grid dumped by with_overrides, back to itself
    if not isinstance(value, (str, RasterGrid)):
        raise invalid("must be a path to a raster file (relative to the scene file) or, from Python, a "
                      "scanner_sim.config.raster_seabed.RasterGrid", value=value)
    return value


def _grid_json(value: Any) -> Any:
    """A raster source as JSON: the path, or a grid's digest (its heights' bytes, transform, CRS, nodata, sign)."""
    if not isinstance(value, RasterGrid):
        return value
    import hashlib

    digest = hashlib.sha256(np.ascontiguousarray(value.heights, np.float64).tobytes())
    digest.update(repr((tuple(value.transform)[:6], str(value.crs), value.nodata, value.vertical)).encode())
    return {"in_memory_grid_sha256": digest.hexdigest()}


#: A raster file's path, or (from Python) a grid in memory.
RasterSource = Annotated[Any, BeforeValidator(_path_or_grid), PlainSerializer(_grid_json, when_used="json"),
                         WithJsonSchema({"type": "string", "description": "Path relative to the scene file."})]


def _resolve(raster: Any, info: ValidationInfo, key: str, band: int) -> Path | None:
    """The raster file, resolved against the scene file's folder and opened once to check it (None for a grid)."""
    if isinstance(raster, RasterGrid):
        problem = check_grid(raster.transform, raster.heights.shape[1], raster.heights.shape[0], raster.crs)
        if problem:
            raise invalid(problem, key=key, value=raster.source)
        return None
    path = Path(raster)
    path = path if path.is_absolute() else Path((info.context or {}).get("base_dir") or Path.cwd()) / path
    if not path.is_file():
        raise invalid(f"file not found (looked for {path}); give a path relative to the scene file", key=key,
                      value=raster)
    try:
        open_raster(path, key, band).close()
    except ConfigError as exc:
        raise invalid(str(exc).split(": ", 1)[1], key=key, value=raster) from None
    return path


class MicroReliefConfig(ReliefConfig):
    """Fractal relief added to the refined raster (synthetic: the outputs say so); none by default."""

    rms_m: NonNegative = 0.0
    """RMS height [m]; 0 = none."""
    wavelength_m: Positive = 2.0
    """Largest feature wavelength [m]."""
    seed: Integer(ge=0, le=MAX_SEED) = 0


class ClassMaterial(surface("terrigenous_sand", "seabed")):
    """The material of one class code."""


class SeabedClassesConfig(StrictModel):
    """A class raster (integer codes) and the material of each code; cells of no code take the seabed's."""

    raster: str
    """Path relative to the scene file; any CRS-equal raster, sampled at each cell's centre."""
    band: Integer(ge=1) = 1
    materials: dict[int, ClassMaterial]
    """Code -> {material: ...} or {reflectance: ...}."""
    _resolved: Path = PrivateAttr()

    @model_validator(mode="after")
    def _file(self, info: ValidationInfo):
        self._resolved = _resolve(self.raster, info, "raster", self.band)
        return self

    @property
    def resolved_raster(self) -> Path:
        return self._resolved


class RasterSeabedConfig(surface("terrigenous_sand", "seabed")):
    """The seabed of a bathymetry raster (GeoTIFF, BAG, NetCDF, ASCII grid), read in a window around the survey
    and refined bilinearly to ``resolution_m``."""

    raster: RasterSource
    """Path relative to the scene file (from Python: a RasterGrid in memory)."""
    band: Integer(ge=1) = 1
    vertical: Choice("auto", "elevation_up", "depth_down") = "auto"
    """Sign of the values: auto (from the file), elevation_up (z) or depth_down (-z)."""
    nodata: float | None = None
    """Nodata value; null = the file's."""
    resolution_m: Positive = 0.25
    """Node spacing the raster is refined to (at most, an integer fraction of its cell) [m]."""
    margin_m: NonNegative = 25.0
    """Read the raster this far around the survey's plan [m]."""
    micro_relief: MicroReliefConfig = MicroReliefConfig()
    classes: SeabedClassesConfig | None = None
    """A class raster giving each cell's material; null = the section's material everywhere."""
    _resolved: Path | None = PrivateAttr(None)

    @model_validator(mode="after")
    def _file(self, info: ValidationInfo):
        self._resolved = _resolve(self.raster, info, "raster", self.band)
        return self

    @property
    def resolved_raster(self) -> Path | None:
        """The raster file, resolved against the scene file's folder (None for a grid in memory)."""
        return self._resolved

