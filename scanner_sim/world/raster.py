"""A seabed from a bathymetry raster (GeoTIFF, BAG, NetCDF, ASCII grid: whatever GDAL reads), through rasterio.

The rules (docs/scene-format.md#seabed-from-a-raster):

- **Grid.** A pixel's value is the seabed at the pixel's centre. The raster must have a CRS, north-up axes (no
  rotation or shear in its transform) and at least 2 x 2 pixels. Its map coordinates are the world's x, y.
- **Vertical sign.** ``vertical: elevation_up`` reads a value as z (up, metres; the seabed below the surface is
  negative), ``depth_down`` as -z. ``auto`` takes BAG as elevation (the BAG format defines band 1 as elevation,
  positive up), a NetCDF variable by its CF ``positive`` attribute (or a ``standard_name`` of depth), and any
  other raster as elevation, GDAL's convention for elevation models; it refuses a raster whose valid values are
  all above zero (depths read as heights), naming the key.
- **Window.** Only the pixels within ``margin_m`` of the survey's plan path (waypoints, lawnmower rectangle,
  static position, objects placed by [x, y]) are read; a lawnmower that names no area reads the whole raster.
- **Refinement.** Nodes every ``s = min(cell) / k`` metres, ``k = ceil(min(cell) / resolution_m)``, heights by
  bilinear interpolation of the four pixel centres around the node; optional micro-relief (fractal, seeded)
  on top, reported as synthetic.
- **Nodata.** A nodata pixel's area is a gap: a node is valid when the pixel it lies in is, a height-field cell
  is seabed when its four nodes are; other cells have no triangles, gaps the rays pass through and coverage
  counts as no seabed data. Heights next to a gap interpolate the nearest valid pixel's value in its place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from scanner_sim.config import ConfigError, reflectance_of
from scanner_sim.config.crs import horizontal_crs as horizontal_of
from scanner_sim.config.geometry import MAX_SEABED_TRIANGLES
from scanner_sim.config.raster_seabed import RasterGrid, check_grid, open_raster, read_pixels
from scanner_sim.config.sections import MAX_DEPTH_M
from scanner_sim.world.terrain import HeightField, fractal_relief


@dataclass(frozen=True)
class RasterSeabed:
    """A raster's seabed: the refined :class:`HeightField` (with its gaps), per-cell reflectance ((ny-1, nx-1)
    float, or None for the section's one material) and what the outputs report about it (``info``)."""

    heightfield: HeightField
    cell_reflectance: np.ndarray | None
    info: dict = field(default_factory=dict)


def vertical_sign(ds, band: int, given: str) -> tuple[str, str]:
    """(sign, reason): 'elevation_up' or 'depth_down' for band ``band`` of ``ds``, the ``vertical`` key's value
    ``given`` winning over the file (the rule in the module docstring)."""
    if given != "auto":
        return given, "the scene's vertical key"
    if ds.driver == "BAG":
        return "elevation_up", "BAG band 1 is elevation, positive up, by the format's specification"
    tags = {k.rpartition("#")[2].lower(): str(v).lower() for k, v in {**ds.tags(), **ds.tags(band)}.items()}
    if tags.get("positive") in ("down", "up"):
        sign = "depth_down" if tags["positive"] == "down" else "elevation_up"
        return sign, f"the file's CF attribute positive = {tags['positive']}"
    if "depth" in tags.get("standard_name", ""):
        return "depth_down", f"the file's CF standard_name = {tags['standard_name']}"
    return "elevation_up", "no sign in the file: values read as elevation (GDAL's convention for elevation models)"


def vertical_datum(crs) -> str | None:
    """The vertical datum a (compound) CRS names, or None where it names none (or 'unknown')."""
    from pyproj import CRS

    c = CRS.from_user_input(crs.to_wkt() if hasattr(crs, "to_wkt") else crs)
    for sub in c.sub_crs_list if c.is_compound else [c]:
        if sub.is_vertical:
            name = sub.datum.name if sub.datum is not None else sub.name
            return None if not name or name.lower() in ("unknown", "//") else name
    return None


def horizontal_crs(crs):
    """The horizontal part of a CRS (rasterio's, pyproj's, or anything pyproj reads) as a pyproj CRS."""
    from pyproj import CRS

    return horizontal_of(CRS.from_user_input(crs.to_wkt() if hasattr(crs, "to_wkt") else crs))


#: [m] Two CRSs are the same frame when a point near the raster's centre moves less than this between them.
SAME_FRAME_M = 1e-3


def check_same_frame(raster_crs, scene_crs, x_m: float, y_m: float, key: str, source: str) -> None:
    """Refuse a raster whose CRS is not the scene's ``crs`` (a point at (x, y) [m] of the raster moving by
    :data:`SAME_FRAME_M` or more between them): its map coordinates would not be the world's."""
    from pyproj import Transformer

    if scene_crs is None:
        return
    a, b = horizontal_crs(raster_crs), horizontal_crs(scene_crs)
    x, y = Transformer.from_crs(a, b, always_xy=True).transform(x_m, y_m)
    if not math.hypot(x - x_m, y - y_m) < SAME_FRAME_M:
        raise ConfigError(f"{key} = {source!r}: its CRS ({a.name}) is not the scene's crs ({b.name}); a point of the "
                          f"raster moves {math.hypot(x - x_m, y - y_m):,.1f} m between them: give the raster's CRS as "
                          "crs, or reproject the raster (gdalwarp -t_srs)")


def plan_bounds(config) -> tuple[float, float, float, float] | None:
    """(x_min, x_max, y_min, y_max) [m] of everything the survey's plan names (track, static position, objects
    placed by [x, y]), or None when the track is decided by the seabed itself (a lawnmower with no area)."""
    p = config.platform
    pts = []
    if p.mode == "lawnmower":
        lm = p.lawnmower
        if lm.size_m is None:
            return None
        yaw = math.radians(90.0 - lm.heading_deg)
        along, left = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
        pts += [np.asarray(lm.center_m) + 0.5 * (a * lm.size_m[0] * along + b * lm.size_m[1] * left)
                for a in (-1, 1) for b in (-1, 1)]
    elif p.mode == "static":
        pts.append(p.position_m[:2])
    else:
        pts += [w[:2] for w in p.waypoints_m]
    for obj in config.objects:
        for name in ("position_m", "translate_m", "center_m"):
            if hasattr(obj, name):
                pts.append(getattr(obj, name)[:2])
        pts += [q[:2] for q in getattr(obj, "points_m", ())]
    a = np.asarray(pts, float)
    return float(a[:, 0].min()), float(a[:, 0].max()), float(a[:, 1].min()), float(a[:, 1].max())


def seabed_plan_size_m(config) -> tuple[float, float] | None:
    """(x, y) extent [m] of a scene's seabed section's plan before it is built: a procedural seabed's size, the
    window of a raster the survey reads (``margin_m`` around its plan, from the raster's metadata: what coverage
    and the height field span), None for no seabed section."""
    section = config.seabed
    if section is None:
        return None
    if not hasattr(section, "raster"):
        return tuple(section.size_m)
    grid = section.raster
    if isinstance(grid, RasterGrid):
        (height, width), t = np.shape(grid.heights), grid.transform
    else:
        with open_raster(section.resolved_raster, "seabed.raster", section.band) as ds:
            (height, width), t = (ds.height, ds.width), ds.transform
    rows, cols = _window(t, width, height, plan_bounds(config), section.margin_m, "seabed.raster")
    return abs(t.a) * (cols.stop - cols.start), abs(t.e) * (rows.stop - rows.start)


def lawnmower_area(lawnmower, section) -> tuple[tuple[float, float], tuple[float, float]]:
    """(center_m, size_m) of a lawnmower: its own, or where it names no area, the rectangle along its heading
    around the centres of the raster's valid pixels (a raster seabed ``section``), so the lines cover them."""
    if lawnmower.size_m is not None:
        return tuple(lawnmower.center_m), tuple(lawnmower.size_m)
    grid = section.raster
    if isinstance(grid, RasterGrid):
        values, transform, nodata = np.asarray(grid.heights), grid.transform, grid.nodata
    else:
        with open_raster(section.resolved_raster, "seabed.raster", section.band) as ds:
            node_grid(ds.height, ds.width, ds.transform.a, ds.transform.e, section.resolution_m, "seabed.raster")
            values = read_pixels(ds, section.band, "seabed.raster", grid)  # the whole raster: refused above if too big
            transform, nodata = ds.transform, ds.nodatavals[section.band - 1]
    nodata = section.nodata if section.nodata is not None else nodata
    valid = np.isfinite(values) & ((values != nodata) if nodata is not None else True)
    if not valid.any():
        raise ConfigError(f"seabed.raster = {getattr(grid, 'source', grid)!r}: all {values.size:,} cells are nodata"
                          f"{f' ({nodata:g})' if nodata is not None else ''}")
    row, col = np.nonzero(valid)
    x, y = transform @ (col + 0.5, row + 0.5)
    yaw = math.radians(90.0 - lawnmower.heading_deg)
    along = x * math.cos(yaw) + y * math.sin(yaw)
    left = -x * math.sin(yaw) + y * math.cos(yaw)
    a0, a1, l0, l1 = along.min(), along.max(), left.min(), left.max()
    ca, cl = 0.5 * (a0 + a1), 0.5 * (l0 + l1)
    center = (ca * math.cos(yaw) - cl * math.sin(yaw), ca * math.sin(yaw) + cl * math.cos(yaw))
    inset = 1e-6  # [m] off the line length, so that rounding keeps the line ends over the seabed, not a hair off it
    return (float(center[0]), float(center[1])), (float(max(a1 - a0 - inset, 1e-3)), float(max(l1 - l0, 1e-3)))


def load_raster_seabed(section, bounds, scene_crs=None, key: str = "seabed.raster") -> RasterSeabed:
    """The :class:`RasterSeabed` of a raster seabed section (``scanner_sim.config.RasterSeabedConfig``) over
    ``bounds`` (x_min, x_max, y_min, y_max) [m] widened by its ``margin_m``, or the whole raster (None); its CRS
    must be the scene's ``scene_crs`` (the ``crs`` key's value) where the scene has one."""
    grid = section.raster
    if isinstance(grid, RasterGrid):
        heights = np.asarray(grid.heights, float)
        problem = check_grid(grid.transform, heights.shape[1], heights.shape[0], grid.crs)
        if problem:
            raise ConfigError(f"{key} = {grid.source!r}: {problem}")
        nodata = section.nodata if section.nodata is not None else grid.nodata
        sign, reason = (section.vertical, "the scene's vertical key") if section.vertical != "auto" else (
            grid.vertical, "the grid's own vertical sign")
        rows, cols = _window(grid.transform, heights.shape[1], heights.shape[0], bounds, section.margin_m, key)
        node_grid(rows.stop - rows.start, cols.stop - cols.start, grid.transform.a, grid.transform.e,
                  section.resolution_m, key)
        values = heights[rows, cols]
        transform, crs, source, driver = grid.transform, grid.crs, grid.source, "in memory"
    else:
        from rasterio.windows import Window

        with open_raster(section.resolved_raster, key, section.band) as ds:
            rows, cols = _window(ds.transform, ds.width, ds.height, bounds, section.margin_m, key)
            node_grid(rows.stop - rows.start, cols.stop - cols.start, ds.transform.a, ds.transform.e,
                      section.resolution_m, key)  # refused before the pixels are read
            window = Window(cols.start, rows.start, cols.stop - cols.start, rows.stop - rows.start)
            values = read_pixels(ds, section.band, key, section.raster, window).astype(float)
            nodata = section.nodata if section.nodata is not None else ds.nodatavals[section.band - 1]
            sign, reason = vertical_sign(ds, section.band, section.vertical)
            transform, crs, source, driver = ds.transform, ds.crs, section.raster, ds.driver
    check_same_frame(crs, scene_crs, *_window_centre(transform, rows, cols), key, str(source))
    valid = np.isfinite(values)
    if nodata is not None:
        valid &= values != nodata
    where = "within margin_m of the survey's plan" if bounds is not None else "anywhere"
    if not valid.any():
        raise ConfigError(f"{key} = {source!r}: all {values.size:,} cells {where} are nodata"
                          f"{f' ({nodata:g})' if nodata is not None else ''}")
    if sign == "depth_down":
        values = -values
    elif section.vertical == "auto" and (values[valid] > 0).all():
        raise ConfigError(f"{key.rpartition('.')[0]}.vertical = 'auto': the raster's values are all above 0 "
                          f"({reason}), which puts the seabed above the water surface (z = 0); if they are depths, "
                          "set vertical: depth_down")
    refuse_voids(values, valid, -1.0 if sign == "depth_down" else 1.0, key, source)
    hf, node_valid = _refine(values, valid, transform, rows, cols, section, key)
    code = horizontal_crs(crs).to_authority()
    info = {"source": str(source), "driver": driver,
            "crs": f"{code[0]}:{code[1]}" if code else horizontal_crs(crs).name,
            "vertical": sign, "vertical_rule": reason, "vertical_datum": vertical_datum(crs),
            "cell_m": [abs(transform.a), abs(transform.e)], "nodata": nodata,
            "window": {"col_off": cols.start, "row_off": rows.start, "width": cols.stop - cols.start,
                       "height": rows.stop - rows.start},
            "node_spacing_m": hf.spacing_m, "refinement": "bilinear",
            "valid_cell_fraction": float(hf.valid.mean()) if hf.valid is not None else 1.0,
            "synthetic_relief_rms_m": section.micro_relief.rms_m,
            "synthetic_relief_seed": section.micro_relief.seed if section.micro_relief.rms_m > 0 else None}
    reflectance = None
    if section.classes is not None:
        reflectance = _cell_reflectance(section.classes, hf, crs, key.rpartition(".")[0] + ".classes",
                                        reflectance_of(section))
    return RasterSeabed(hf, reflectance, info)


def check_raster_frame(section, bounds, scene_crs, key: str = "seabed.raster") -> None:
    """:func:`load_raster_seabed`'s check that the raster's CRS is the scene's, from the raster's header alone (no
    pixel read): the same window, the same point, so the same one-line error."""
    grid = section.raster
    if isinstance(grid, RasterGrid):
        rows, cols = _window(grid.transform, grid.heights.shape[1], grid.heights.shape[0], bounds, section.margin_m,
                             key)
        transform, crs, source = grid.transform, grid.crs, grid.source
    else:
        with open_raster(section.resolved_raster, key, section.band) as ds:
            rows, cols = _window(ds.transform, ds.width, ds.height, bounds, section.margin_m, key)
            transform, crs, source = ds.transform, ds.crs, section.raster
    check_same_frame(crs, scene_crs, *_window_centre(transform, rows, cols), key, str(source))


def _window_centre(transform, rows: slice, cols: slice) -> tuple[float, float]:
    """Map coordinates [m] of the centre of a raster window."""
    return transform @ (cols.start + 0.5 * (cols.stop - cols.start), rows.start + 0.5 * (rows.stop - rows.start))


#: [m] Higher than any land (Everest is about 8,849 m): a raster value above it is no height but a void.
MAX_ELEVATION_M = 9_000.0


def refuse_voids(z: np.ndarray, valid: np.ndarray, sign: float, key: str, source) -> None:
    """Refuse a raster whose ``valid`` pixels hold heights ``z`` [m] (up) no seabed has: deeper than any ocean
    (:data:`~scanner_sim.config.sections.MAX_DEPTH_M`) or higher than any land (:data:`MAX_ELEVATION_M`), void
    values (-32767, 3.4e38 ...) the file does not tag as nodata. The message gives the value as the file holds it
    (``sign`` z), which the scene's nodata key then takes."""
    impossible = valid & ((z < -MAX_DEPTH_M) | (z > MAX_ELEVATION_M))
    if impossible.any():
        first = np.flatnonzero(impossible.ravel())[0]
        z0, value = float(z.ravel()[first]), float(sign * z.ravel()[first])
        raise ConfigError(f"{key} = {source!r}: {np.count_nonzero(impossible):,} of the {np.count_nonzero(valid):,} "
                          f"pixels read hold values such as {value:g}, which put the seabed "
                          f"{'deeper than any ocean' if z0 < 0 else 'higher than any land'} ({MAX_DEPTH_M:,.0f} m deep, "
                          f"{MAX_ELEVATION_M:,.0f} m high at most): a void value the file does not tag as nodata; set "
                          f"{key.rpartition('.')[0]}.nodata: {value:g}")


def _window(transform, width: int, height: int, bounds, margin_m: float, key: str) -> tuple[slice, slice]:
    """Rows and columns of the raster within ``margin_m`` of ``bounds`` (one pixel more each side, for the
    bilinear stencil), or all of them (bounds None)."""
    if bounds is None:
        return slice(0, height), slice(0, width)
    x0, x1, y0, y1 = bounds[0] - margin_m, bounds[1] + margin_m, bounds[2] - margin_m, bounds[3] + margin_m
    inverse = ~transform
    c, r = zip(*(inverse @ (x, y) for x in (x0, x1) for y in (y0, y1)))
    c0, c1 = max(0, math.floor(min(c)) - 1), min(width, math.ceil(max(c)) + 1)
    r0, r1 = max(0, math.floor(min(r)) - 1), min(height, math.ceil(max(r)) + 1)
    if c1 - c0 < 2 or r1 - r0 < 2:
        left, top = transform @ (0, 0)
        right, bottom = transform @ (width, height)
        raise ConfigError(f"{key}: the survey's plan (x {bounds[0]:.1f} to {bounds[1]:.1f}, y {bounds[2]:.1f} to "
                          f"{bounds[3]:.1f} m) lies off the raster (x {min(left, right):.1f} to {max(left, right):.1f},"
                          f" y {min(top, bottom):.1f} to {max(top, bottom):.1f} m, its CRS's map coordinates)")
    return slice(r0, r1), slice(c0, c1)


def node_grid(nr: int, nc: int, dx: float, dy: float, resolution_m: float, key: str) -> tuple[float, int, int]:
    """(spacing s [m], nx, ny) of the refined nodes over ``nr`` x ``nc`` pixels of ``dx`` x ``dy`` [m]: s = c / k,
    c = min(dx, dy), k = ceil(c / resolution_m); refused beyond the seabed's triangle budget (before any read)."""
    dx, dy = abs(dx), abs(dy)
    cell = min(dx, dy)
    s = cell / max(1, math.ceil(cell / resolution_m - 1e-9))
    nx, ny = int((nc - 1) * dx / s + 1e-9) + 1, int((nr - 1) * dy / s + 1e-9) + 1
    triangles = 2 * (nx - 1) * (ny - 1)
    if triangles > MAX_SEABED_TRIANGLES:  # the procedural seabed's limit: a large window is tiled alike
        raise ConfigError(f"{key.rpartition('.')[0]}.resolution_m = {resolution_m!r}: refines the raster's "
                          f"{nc} x {nr} window to {triangles:,} triangles, more than the {MAX_SEABED_TRIANGLES:,} "
                          "allowed; use a coarser resolution_m or a smaller margin_m")
    if nx < 2 or ny < 2:
        raise ConfigError(f"{key}: the window read holds a single row or column of pixels; widen margin_m")
    return s, nx, ny


def _refine(values, valid, transform, rows: slice, cols: slice, section, key: str):
    """The refined :class:`HeightField` of a window's ``values`` (rows, cols) with their ``valid`` mask."""
    from scipy import ndimage

    dx, dy = transform.a, transform.e
    if dx < 0:  # columns run west: flip them so that x ascends
        values, valid, dx = values[:, ::-1], valid[:, ::-1], -dx
        col0 = cols.stop - 1
    else:
        col0 = cols.start
    if dy < 0:  # rows run south (north-up): flip them so that y ascends
        values, valid, dy = values[::-1], valid[::-1], -dy
        row0 = rows.stop - 1
    else:
        row0 = rows.start
    xc0, yc0 = transform @ (col0 + 0.5, row0 + 0.5)  # the first pixel's centre after the flips
    nr, nc = values.shape
    s, nx, ny = node_grid(nr, nc, dx, dy, section.resolution_m, key)
    nearest = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    filled = values[tuple(nearest)]
    fx, fy = np.arange(nx) * s / dx, np.arange(ny) * s / dy
    j0, i0 = np.minimum(fx.astype(np.int64), nc - 2), np.minimum(fy.astype(np.int64), nr - 2)
    u, v = (fx - j0)[None, :], (fy - i0)[:, None]
    ii, jj = i0[:, None], j0[None, :]
    z = ((1 - u) * (1 - v) * filled[ii, jj] + u * (1 - v) * filled[ii, jj + 1]
         + (1 - u) * v * filled[ii + 1, jj] + u * v * filled[ii + 1, jj + 1])
    node_valid = valid[np.minimum((fy + 0.5).astype(np.int64), nr - 1)[:, None],
                       np.minimum((fx + 0.5).astype(np.int64), nc - 1)[None, :]]  # the pixel the node lies in
    relief = section.micro_relief
    if relief.rms_m > 0:
        z = z + fractal_relief((ny, nx), s, relief.rms_m, relief.wavelength_m, relief.hurst,
                               np.random.default_rng(relief.seed))
    cells = node_valid[:-1, :-1] & node_valid[:-1, 1:] & node_valid[1:, :-1] & node_valid[1:, 1:]
    if not cells.any():
        raise ConfigError(f"{key}: no 2 x 2 block of valid pixels in the window read: nothing to triangulate")
    return HeightField(float(xc0), float(yc0), float(s), z, None if cells.all() else cells), node_valid


def _cell_reflectance(classes, hf: HeightField, crs, key: str, default: float) -> np.ndarray:
    """(ny-1, nx-1) reflectance of each height-field cell: the class raster's pixel under the cell's centre,
    through the section's ``materials`` table (a pixel of a code not in the table is refused), ``default`` where
    the class raster has no pixel or its nodata."""
    ny, nx = hf.shape
    xc = hf.x0_m + hf.spacing_m * (np.arange(nx - 1) + 0.5)
    yc = hf.y0_m + hf.spacing_m * (np.arange(ny - 1) + 0.5)
    gx, gy = np.meshgrid(xc, yc)
    with open_raster(classes.resolved_raster, f"{key}.raster", classes.band) as ds:
        check_same_frame(ds.crs, crs, float(gx.mean()), float(gy.mean()), f"{key}.raster", classes.raster)
        from rasterio.windows import Window

        col, row = (~ds.transform) @ (gx, gy)
        col, row = np.floor(col).astype(np.int64), np.floor(row).astype(np.int64)
        inside = (col >= 0) & (col < ds.width) & (row >= 0) & (row < ds.height)
        c0, r0 = (int(np.clip(a.min(), 0, n - 1)) for a, n in ((col, ds.width), (row, ds.height)))
        c1, r1 = (int(np.clip(a.max(), 0, n - 1)) + 1 for a, n in ((col, ds.width), (row, ds.height)))
        codes = read_pixels(ds, classes.band, f"{key}.raster", classes.raster,
                            Window(c0, r0, c1 - c0, r1 - r0))  # only the pixels under the seabed's cells
        code = np.where(inside, codes[np.clip(row, r0, r1 - 1) - r0, np.clip(col, c0, c1 - 1) - c0], -1)
    table = {int(c): reflectance_of(m) for c, m in classes.materials.items()}
    seen = set(np.unique(code[inside & (hf.valid if hf.valid is not None else True)]).tolist())
    missing = sorted(seen - set(table) - ({int(ds.nodata)} if ds.nodata is not None else set()))
    if missing:
        raise ConfigError(f"{key}.materials: the class raster holds code(s) {missing[:8]} under the seabed, which "
                          f"the table ({sorted(table)}) does not name")
    out = np.full(code.shape, default)
    for c, r in table.items():
        out[code == c] = r
    return out
