"""A pass as one self-contained HTML page a person turns in a browser (``scanner-sim view RUN_DIR --html``).

The page carries three.js (package data in ``web/``, its README says the version and how it was built), the viewer
(``web/viewer.js``) and the pass's data, base64 in a JSON block, so it opens from a file with no network. It shows
the points coloured by class, depth, intensity, channel, range error, TVU or SNR (switchable, with a colour bar or
a legend), the scene mesh faded, the trajectory and the dropouts at their beam's nominal footprint.

Budgets, each with a stated, deterministic rule, keep the page small enough to open:

- points: when the pass holds more than ``max_points``, every k-th point in file order, k = ceil(n / max_points);
- dropouts: the same rule and budget;
- mesh: above :data:`MESH_MAX_TRIANGLES` triangles, vertex clustering on a square plan grid (each grid cell's
  vertices merge into their mean, triangles that collapse are dropped), the cell grown until the mesh fits.
"""

from __future__ import annotations

import base64
import html
import json
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import NamedTuple

import numpy as np

from muls.infra.atomic import atomic_path
from scanner_sim.render.point_colours import CHANNEL_COLOURS, categorical_rgb

#: Points a page shows at most by default: 500,000 points make a page of about 21 MB that Chromium opens in seconds.
DEFAULT_MAX_POINTS = 500_000
#: Triangles of the faded scene mesh at most (context, not measurement): about 2 MB of page.
MESH_MAX_TRIANGLES = 60_000
#: Colourings: name -> (label on the page, matplotlib colour map or None for categories, symmetric about 0?).
COLOURINGS: dict[str, tuple[str, str | None, bool]] = {
    "depth": ("depth [m] (-z)", "viridis_r", False),
    "class": ("class", None, False),
    "intensity": ("intensity", "viridis", False),
    "channel": ("channel", None, False),
    "range_error": ("range error [m]", "coolwarm", True),
    "tvu": ("TVU 95 % [m]", "plasma", False),
    "snr": ("SNR", "magma", False),
}
#: Colour of each dropout cause (muls.ranging.returns.DROPOUT_CAUSES order), as the coverage map's gap colours.
DROPOUT_COLOURS = ((120, 120, 120), (255, 127, 14), (214, 39, 40), (255, 255, 255), (148, 103, 189), (23, 190, 207))
BACKGROUND = "#0b1a2a"  # the deep-water navy of the PNG renders
WEB = "web"  # package data folder of the viewer and three.js


@dataclass(frozen=True)
class PassFiles:
    """The files of a run folder the view reads: the point cloud(s), and scene.ply, trajectory.csv, dropouts.npz,
    summary.json when present (None otherwise)."""

    clouds: tuple[Path, ...]
    scene_ply: Path | None
    trajectory: Path | None
    dropouts: Path | None
    summary: Path | None

    @classmethod
    def of(cls, path: Path) -> PassFiles:
        """The files of run folder ``path``, or of the folder of point cloud ``path``; ValueError without a cloud."""
        folder = path if path.is_dir() else path.parent
        clouds = ((path,) if path.is_file() else
                  tuple(sorted(folder.glob("points.la[sz]"))[:1] or sorted(folder.glob("leg*_points.las"))
                        or sorted(folder.glob("leg*_points.laz")) or sorted(folder.glob("points.copc.laz"))))
        if not clouds:
            raise ValueError(f"RUN_DIR = {str(path)!r}: no points.las/laz, leg*_points.las/laz nor points.copc.laz "
                             "there; give a run folder of scanner-sim run or a LAS file")

        def found(name: str, up: bool = False) -> Path | None:
            places = (folder, folder.parent) if up else (folder,)  # a study writes scene.ply once, one folder up
            return next((d / name for d in places if (d / name).is_file()), None)

        return cls(clouds, found("scene.ply", up=True), found("trajectory.csv"), found("dropouts.npz"),
                   found("summary.json"))


def stride_for(n: int, budget: int) -> int:
    """The k of "every k-th in file order" that keeps at most ``budget`` of ``n`` items (1: all of them)."""
    return max(1, math.ceil(n / max(budget, 1)))


def cluster_mesh(vertices: np.ndarray, faces: np.ndarray, max_triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """``vertices`` (n, 3) [m] and ``faces`` (m, 3) cut to at most ``max_triangles`` by vertex clustering on a plan
    grid (the module's rule); returned as they are when they fit."""
    if len(faces) <= max_triangles:
        return vertices, faces
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    area = max(float((hi[0] - lo[0]) * (hi[1] - lo[1])), 1e-6)
    cell = math.sqrt(2.0 * area / max_triangles)  # a grid of two triangles a cell holds max_triangles
    while True:
        grid = np.floor((vertices[:, :2] - lo[:2]) / cell).astype(np.int64)
        _, merged = np.unique(grid, axis=0, return_inverse=True)
        merged = merged.ravel()
        weight = np.bincount(merged)
        kept = np.column_stack([np.bincount(merged, vertices[:, i]) / weight for i in range(3)])
        tri = merged[faces]
        tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])]
        tri = tri[np.unique(np.sort(tri, axis=1), axis=0, return_index=True)[1]]
        if len(tri) <= max_triangles:
            return kept, tri
        cell *= 1.25


def _b64(array: np.ndarray, dtype: str) -> dict:
    numpy_type = {"u1": "<u1", "u2": "<u2", "i4": "<i4", "u4": "<u4", "f4": "<f4"}[dtype]
    data = np.ascontiguousarray(array, dtype=numpy_type).tobytes()
    return {"dtype": dtype, "b64": base64.b64encode(data).decode("ascii")}


def _lut(cmap: str) -> dict:
    from matplotlib import colormaps

    rgb = np.rint(colormaps[cmap](np.linspace(0.0, 1.0, 256))[:, :3] * 255)
    return _b64(rgb.astype(np.uint8).ravel(), "u1")


def _field(name: str, values: np.ndarray) -> dict:
    """One colouring of the page: the values, and their colour map between the 1st and 99th percentiles
    (symmetric about 0 for the range error), or their categories' colours and labels."""
    label, cmap, symmetric = COLOURINGS[name]
    if cmap is None:
        codes = values.astype(np.int64)
        if name == "class":
            _, table = categorical_rgb(codes, "class")
        else:
            table = {int(c): (CHANNEL_COLOURS[(int(c) - 1) % len(CHANNEL_COLOURS)], f"CH{c}") for c in np.unique(codes)}
        return {"label": label, "values": _b64(codes, "u1"),
                "categories": {str(c): {"rgb": list(rgb), "label": text} for c, (rgb, text) in table.items()}}
    v = values.astype(np.float32)
    good = v[np.isfinite(v)].astype(np.float64)
    if good.size == 0:
        lo, hi = 0.0, 1.0
    elif symmetric:
        m = float(np.percentile(np.abs(good), 99)) or 1.0
        lo, hi = -m, m
    else:
        lo, hi = (float(x) for x in np.percentile(good, [1, 99]))
        hi = hi if hi > lo else lo + 1.0
    field = {"label": label, "values": _b64(v, "f4"), "lut": _lut(cmap), "lo": lo, "hi": hi,
             "limits": "±99th percentile of |value|" if symmetric else "1st to 99th percentile"}
    if name == "depth":  # contour lines show the relief's shape where the colour alone shows only a slope
        field["contour_m"] = contour_interval(hi - lo)
    return field


def contour_interval(span_m: float, lines: int = 20) -> float:
    """A round interval [m] (1, 2, 2.5 or 5 times a power of ten) giving about ``lines`` contours over ``span_m``."""
    raw = max(span_m, 1e-3) / lines
    power = 10.0 ** math.floor(math.log10(raw))
    return next(k * power for k in (1.0, 2.0, 2.5, 5.0, 10.0) if k * power >= raw)


def _footprints(dropouts, vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each dropped beam's axis first meets the scene mesh: (hits (m, 3) [m], their rows in ``dropouts``)."""
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    where, rows, _ = mesh.ray.intersects_location(np.asarray(dropouts.origin, float),
                                                  np.asarray(dropouts.direction, float), multiple_hits=False)
    order = np.argsort(rows, kind="stable")
    return where[order], rows[order]


class PointSample(NamedTuple):
    """The points of a pass as a viewer shows them: ``n`` in the files, one in every ``stride`` kept (``shown``),
    their positions ``xyz`` (m, 3) [m], bounds ``lo``, ``hi`` and ``centre`` (3,) [m], and per colouring its values
    (m,)."""

    n: int
    stride: int
    shown: object
    xyz: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    centre: np.ndarray
    values: dict


def sampled_points(files: PassFiles, max_points: int) -> PointSample:
    """The points of ``files``, one in every :func:`stride_for` in file order, with what each colouring shows."""
    from scanner_sim.io import read_las
    from scanner_sim.records.point_records import PointRecords

    points = PointRecords.concatenate([read_las(f) for f in files.clouds])
    n = len(points)
    stride = stride_for(n, max_points)
    shown = points.select(np.arange(0, n, stride)) if stride > 1 else points
    xyz = np.asarray(shown.xyz, float)
    lo, hi = (xyz.min(axis=0), xyz.max(axis=0)) if len(xyz) else (np.zeros(3), np.ones(3))
    centre = (lo + hi) / 2.0
    values = {"depth": -xyz[:, 2], "class": shown.classification, "intensity": shown.intensity,
              "channel": shown.channel, "range_error": shown.range_error_m, "tvu": shown.tvu_m, "snr": shown.snr}
    return PointSample(n, stride, shown, xyz, lo, hi, centre, values)


def page_data(files: PassFiles, *, max_points: int = DEFAULT_MAX_POINTS, color: str | None = None,
              point_size_px: float = 2.0) -> dict:
    """The JSON the viewer reads, from the files of one pass; ``color``: the colouring shown first (default
    depth over a seabed, class otherwise)."""
    from muls.ranging.returns import DROPOUT_CAUSES
    from scanner_sim.config.materials import LABELS
    from scanner_sim.io import read_dropouts_npz, read_scene_ply, read_trajectory_csv

    n, stride, shown, xyz, lo, hi, centre, values = sampled_points(files, max_points)
    names = [f.name for f in files.clouds]
    rule = (f"all {n:,} points" if stride == 1 else
            f"one point in every {stride} in file order ({len(shown):,} of {n:,}; budget {max_points:,})")
    data = {
        "background": BACKGROUND, "point_size_px": point_size_px,
        "points": {"positions": _b64(xyz - centre, "f4"), "half_extent_m": ((hi - lo) / 2.0).tolist(),
                   "fields": {name: _field(name, values[name]) for name in COLOURINGS}},
        "count_in_files": n, "count_shown": len(shown), "stride": stride, "sampling": rule, "files": names,
        "centre_m": centre.tolist(), "extent_m": (hi - lo).tolist(), "mesh": None, "trajectory": None,
        "dropouts": None, "title": ", ".join(names),
    }
    mesh_note = "no scene.ply"
    scene = read_scene_ply(files.scene_ply) if files.scene_ply is not None else None
    if scene is not None and len(scene["faces"]):
        v, f = cluster_mesh(scene["vertices"], scene["faces"], MESH_MAX_TRIANGLES)
        data["mesh"] = {"positions": _b64(v - centre, "f4"), "faces": _b64(f, "u4")}
        mesh_note = (f"scene mesh: all {len(f):,} triangles" if len(f) == len(scene["faces"]) else
                     f"scene mesh: {len(f):,} of {len(scene['faces']):,} triangles (vertex clustering)")
    seabed = scene is not None and bool(np.any(scene["face_label"] == LABELS["seabed"]))
    data["default_color"] = color or ("depth" if seabed else "class")
    if files.trajectory is not None:
        table = read_trajectory_csv(files.trajectory)
        track = np.column_stack([table["x_m"], table["y_m"], table["z_m"]])
        data["trajectory"] = {"positions": _b64(track - centre, "f4")}
    drop_note = "no dropouts.npz"
    if files.dropouts is not None:
        dropouts = read_dropouts_npz(files.dropouts)
        k = stride_for(len(dropouts), max_points)
        sample = dropouts.select(np.arange(0, len(dropouts), k)) if k > 1 else dropouts
        drop_note = f"{len(dropouts):,} dropouts"
        if len(sample) and scene is not None:
            where, rows = _footprints(sample, scene["vertices"], scene["faces"])
            counts = np.bincount(sample.cause[rows], minlength=len(DROPOUT_CAUSES))
            data["dropouts"] = {"positions": _b64(where - centre, "f4"), "cause": _b64(sample.cause[rows], "u1"),
                                "causes": list(DROPOUT_CAUSES), "colours": [list(c) for c in DROPOUT_COLOURS],
                                "drawn": {c: int(counts[i]) for i, c in enumerate(DROPOUT_CAUSES) if counts[i]}}
            drop_note += (f", {len(rows):,} drawn at their beam's footprint" + (f" (one in every {k})" if k > 1 else "")
                          + (f"; {len(sample) - len(rows):,} whose beam meets no surface are not drawn"
                             if len(rows) < len(sample) else ""))
    data["notes"] = [mesh_note, drop_note]
    if files.summary is not None:
        summary = json.loads(files.summary.read_text(encoding="utf-8"))
        data["title"] = (f"{summary.get('scene')}, {summary.get('water')}, "
                         f"{summary.get('settings', {}).get('instrument')}, {summary.get('fidelity')}")
    return data


def _asset(name: str) -> str:
    return resources.files("scanner_sim.render").joinpath(WEB, name).read_text(encoding="utf-8")


def _script(text: str) -> str:
    return text.replace("</script", "<\\/script")  # nothing inside may end the script element


def page_html(data: dict) -> str:
    """The whole page: styles, panel, three.js, the data and the viewer, nothing fetched."""
    dropout_legend = ""
    if data["dropouts"]:
        dropout_legend = "".join(
            f'<div class="swatch"><span style="background:rgb{tuple(data["dropouts"]["colours"][i])}"></span>'
            f'{html.escape(c.replace("_", " "))}: {data["dropouts"]["drawn"][c]:,}</div>'
            for i, c in enumerate(data["dropouts"]["causes"]) if c in data["dropouts"]["drawn"])
    extent = " × ".join(f"{e:.1f}" for e in data["extent_m"])
    panel = f"""<div id="panel">
<h1>{html.escape(data["title"])}</h1>
<p><b><span id="count"></span></b> points drawn; {html.escape(data["sampling"])}.
<br>{html.escape("; ".join(data["notes"]))}. Points span {extent} m (x, y, z).</p>
<label>colour by <select id="colour"></select></label>
<label>vertical exaggeration <select id="zscale">{"".join(f'<option value="{k}">×{k}</option>'
                                                            for k in (1, 2, 5, 10, 20))}</select></label>
<div class="toggles"><label><input type="checkbox" id="show-mesh" checked> scene mesh</label>
<label><input type="checkbox" id="show-trajectory" checked> trajectory</label>
<label><input type="checkbox" id="show-dropouts" checked> dropouts</label>
<label><input type="checkbox" id="show-contours" checked> depth contours</label></div>
<div id="legend"></div>
<div id="dropout-legend">{dropout_legend}</div>
<p class="help">Drag to turn, right-drag to pan, wheel to zoom. Colouring <span id="shown-colour"></span>,
frames drawn <span id="frames">0</span>. State in the address: #color=depth&amp;zscale=5.</p>
</div>"""
    return ("<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width\"><title>{html.escape(data['title'])}</title>"
            f"<style>{_asset('viewer.css')}</style></head><body>"
            f"<canvas id=\"view\"></canvas>{panel}"
            f"<script>{_script(_asset('three-orbit.min.js'))}</script>"
            f"<script type=\"application/json\" id=\"muls-data\">{_script(json.dumps(data))}</script>"
            f"<script>{_script(_asset('viewer.js'))}</script></body></html>\n")


def write_view_html(path, files: PassFiles, **kwargs) -> dict:
    """Write the page of ``files`` to ``path`` atomically (keyword arguments as :func:`page_data`); returns the
    page's figures: points in the files and drawn, the stride, bytes."""
    data = page_data(files, **kwargs)
    text = page_html(data)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return {"points": data["count_in_files"], "shown": data["count_shown"], "stride": data["stride"],
            "bytes": len(text.encode("utf-8"))}
