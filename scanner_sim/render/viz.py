"""Pictures of a pass: rendered point clouds (pyvista, off-screen or in a window), waveform and overlap plots.

This is the only module of ``scanner_sim`` that imports plotting or rendering libraries, and it
imports them inside the functions, so ``import scanner_sim`` stays light and works without a
display. Every picture is written atomically (:func:`scanner_sim.io.atomic_path`). It is longer than the
other modules on purpose: the lint rule that keeps plotting libraries out of the rest of the package makes
it the one home of every picture.

Class colours (:data:`CLASS_COLOURS`) are keyed by the scene's label *names*; the codes come from
the class table (``scanner_sim.world.materials.CLASS_NAMES``: the scene labels of ``docs/scene-format.md``, and
noise):

=================  =========================  ==========
label name         colour                     RGB
=================  =========================  ==========
seabed, sand, mud  sand                       214 189 133
rock               grey                       128 128 128
cable              orange                     255 140   0
pipeline           yellow                     240 215  30
mine               red                        230  25  25
tether             dark pink                  170  40 110
panel, target      white                      245 245 245
wreck              brown                      140  85  40
object             light blue                 110 180 230
debris             olive                      150 140  90
vegetation, algae  green                       60 160  60
unlabelled, none   dark grey                   70  70  70
noise (LAS 7)      magenta                    255   0 255
=================  =========================  ==========

Other names take a colour from a fixed qualitative cycle indexed by their code.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np

from scanner_sim.io import atomic_path
from scanner_sim.world.materials import CLASS_NAMES

__all__ = [
    "CLASS_COLOURS",
    "COVERAGE_COLOURS",
    "SCALAR_COLOUR_MAPS",
    "WATER_COLOURS",
    "check_window_size",
    "class_table",
    "plot_coverage_map",
    "plot_coverage_vs_altitude",
    "plot_overlap",
    "plot_waveforms",
    "render_point_cloud",
    "show_point_cloud",
]

#: Largest side of a point-cloud picture or window [px]: the largest framebuffer side GPU OpenGL drivers commonly
#: render (GL_MAX_RENDERBUFFER_SIZE and the viewport are 16384 on most; Mesa's llvmpipe renders more).
MAX_WINDOW_SIDE_PX = 16384
#: Bytes VTK and the screenshot hold per pixel: 88 measured (peak RSS of scanner-sim view between 2000 x 2000 and
#: 4000 x 4000, off-screen), rounded up. Past the memory VTK aborts (std::bad_alloc) and takes the process with it.
WINDOW_BYTES_PER_PIXEL = 100


def check_window_size(key: str, window_size: Sequence[int], available_bytes: int | None = None) -> None:
    """Refuse, before VTK allocates it, a (width, height) [px] with a side beyond :data:`MAX_WINDOW_SIDE_PX` or a
    picture needing more memory than a command may plan on (:func:`muls.memory.check_memory`): a ValueError
    naming ``key``."""
    from muls.memory import check_memory

    w, h = (int(v) for v in window_size)
    shown = f"{w} {h}"
    if max(w, h) > MAX_WINDOW_SIDE_PX:
        raise ValueError(f"{key} = {shown}: at most {MAX_WINDOW_SIDE_PX} px a side (the largest framebuffer OpenGL "
                         "drivers commonly render)")
    per = WINDOW_BYTES_PER_PIXEL
    check_memory(key, shown, w * h * per, f"a {w:,} x {h:,} px picture",
                 lambda budget: f"at most {int(budget // per):,} pixels (width x height) on this machine",
                 available_bytes)


#: Label name -> RGB colour (0..255).
CLASS_COLOURS: dict[str, tuple[int, int, int]] = {
    "seabed": (214, 189, 133),
    "ground": (214, 189, 133),
    "sand": (214, 189, 133),
    "mud": (150, 120, 80),
    "rock": (128, 128, 128),
    "cable": (255, 140, 0),
    "pipeline": (240, 215, 30),
    "mine": (230, 25, 25),
    "tether": (170, 40, 110),
    "panel": (245, 245, 245),
    "target": (245, 245, 245),
    "wreck": (140, 85, 40),
    "object": (110, 180, 230),
    "debris": (150, 140, 90),
    "vegetation": (60, 160, 60),
    "algae": (60, 160, 60),
    "unlabelled": (70, 70, 70),
    "none": (70, 70, 70),
    "noise": (255, 0, 255),
}

_CYCLE = [(31, 119, 180), (44, 160, 44), (148, 103, 189), (23, 190, 207), (188, 189, 34),
          (227, 119, 194), (255, 187, 120), (152, 223, 138), (197, 176, 213), (158, 218, 229)]

#: Fallback code -> name table, used only when ``scanner_sim.world.scene.LABELS`` cannot be read.

#: ``color_by`` value -> (matplotlib colour map, scalar bar title, symmetric limits?).
SCALAR_COLOUR_MAPS: dict[str, tuple[str, str, bool]] = {
    "intensity": ("viridis", "intensity", False),
    "range_error": ("coolwarm", "range error [m]", True),
    "snr": ("magma", "SNR", False),
    "amplitude": ("viridis", "amplitude [LSB]", False),
    "incidence": ("plasma", "incidence [deg]", False),
}

#: Detection channels 1, 2, 3... (RGB), the colours of the waveform plots: blue, orange, red, then green, purple.
CHANNEL_COLOURS: tuple[tuple[int, int, int], ...] = ((31, 119, 180), (255, 127, 14), (214, 39, 40), (44, 160, 44),
                                                     (148, 103, 189))

_BACKGROUND = "#0b1a2a"  # deep-water navy: white panels and the grey truth mesh stay visible


def class_table(class_names: Mapping[int, str] | None = None) -> dict[int, str]:
    """Class code -> name: ``class_names`` when given, else the scene labels and noise
    (:data:`scanner_sim.world.materials.CLASS_NAMES`)."""
    if class_names is not None:
        return {int(k): str(v) for k, v in class_names.items()}
    return dict(CLASS_NAMES)


def _class_colour(code: int, name: str | None) -> tuple[int, int, int]:
    if name is not None and name.lower() in CLASS_COLOURS:
        return CLASS_COLOURS[name.lower()]
    return _CYCLE[code % len(_CYCLE)]


def _write_png(path_png, rgb: np.ndarray) -> None:
    from matplotlib import image as mpimg

    with atomic_path(path_png) as tmp:
        with open(tmp, "wb") as fh:
            mpimg.imsave(fh, rgb, format="png")


def text_width_px(text: str, font_size: int) -> int:
    """Width [px] that VTK's default font (Arial) takes for ``text`` at ``font_size``, rounded up: measured at 13,
    "seabed, class 40" takes 217 px (13.6 px a character); 1.1 font sizes a character keeps wide letters in."""
    return int(math.ceil(1.1 * font_size * len(text)))


def _figure_to_png(fig, path_png) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    with atomic_path(path_png) as tmp:
        with open(tmp, "wb") as fh:
            fig.savefig(fh, format="png", dpi=fig.dpi, bbox_inches="tight", pad_inches=0.15)  # no label cut off


def _prefer_headless_vtk() -> None:
    """Without a display, render through EGL straight away instead of failing over from X11 with a warning."""
    import os

    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def points_polydata(points):
    """A pyvista ``PolyData`` of :class:`scanner_sim.survey.point_records.PointRecords`: one vertex per point, every other
    field as point data (by its field name)."""
    import pyvista as pv

    cloud = pv.PolyData(np.asarray(points.xyz, float))
    for name, values in points.as_dict().items():
        if name != "xyz":
            cloud.point_data[name] = values
    return cloud


def categorical_rgb(values, color_by: str, class_names: Mapping[int, str] | None = None):
    """Colours of categories: ``color_by`` "class" (the class table's colours) or "channel" (CH1 blue, CH2
    orange, CH3 red...). Returns ((n, 3) uint8 RGB, {code: (RGB, legend label)})."""
    codes = np.asarray(values).astype(np.int64)
    if color_by == "class":
        table = class_table(class_names)
        lut = {int(c): (_class_colour(int(c), table.get(int(c))), f"{table.get(int(c), 'class')}, class {c}")
               for c in np.unique(codes)}
    else:
        lut = {int(c): (CHANNEL_COLOURS[(int(c) - 1) % len(CHANNEL_COLOURS)], f"CH{c}") for c in np.unique(codes)}
    rgb = np.zeros((len(codes), 3), dtype=np.uint8)
    for c, (col, _) in lut.items():
        rgb[codes == c] = col
    return rgb, lut


def point_rgb(values, color_by: str, class_names: Mapping[int, str] | None = None) -> np.ndarray:
    """(n, 3) float RGB in [0, 1] of points coloured by ``color_by``: categories as :func:`categorical_rgb`,
    other fields through their colour map (:data:`SCALAR_COLOUR_MAPS`) between their 1st and 99th
    percentiles (symmetric about 0 for the range error)."""
    if color_by in ("class", "channel"):
        return categorical_rgb(values, color_by, class_names)[0] / 255.0
    from matplotlib import colormaps

    cmap, _, symmetric = SCALAR_COLOUR_MAPS.get(color_by, ("viridis", color_by, False))
    v = np.asarray(values, float)
    good = v[np.isfinite(v)]
    if symmetric:
        m = float(np.percentile(np.abs(good), 99)) if good.size else 1.0
        lo, hi = -m, m
    else:
        lo, hi = np.percentile(good, [1, 99]) if good.size else (0.0, 1.0)
    level = np.clip((v - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    return np.where(np.isfinite(v)[:, None], colormaps[cmap](level)[:, :3], [1.0, 0.0, 1.0])


def show_open3d(xyz, rgb, *, truth_vertices=None, truth_faces=None, title: str = "muls-scanner") -> None:
    """An interactive open3d window (the ``open3d`` extra): the points (n, 3) [m] in colours ``rgb`` (n, 3)
    in [0, 1], over the grey truth mesh."""
    from scanner_sim.metrics.swath import open3d

    o3d = open3d()
    centre = np.asarray(xyz, float).mean(axis=0) if len(xyz) else np.zeros(3)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(xyz, float) - centre))
    cloud.colors = o3d.utility.Vector3dVector(np.asarray(rgb, float))
    shown = [cloud]
    if truth_vertices is not None and len(truth_faces):
        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(truth_vertices, float) - centre),
                                         o3d.utility.Vector3iVector(np.asarray(truth_faces, np.int32)))
        mesh.compute_vertex_normals()
        mesh.paint_uniform_color([0.55, 0.58, 0.62])
        shown.append(mesh)
    o3d.visualization.draw_geometries(shown, window_name=title)


def render_point_cloud(
    path_png,
    xyz,
    classification=None,
    *,
    truth_vertices=None,
    truth_faces=None,
    title: str | None = None,
    color_by: str = "class",
    scalars=None,
    class_names: Mapping[int, str] | None = None,
    window_size: Sequence[int] = (1600, 1000),
    point_size: float = 3.0,
    max_points: int = 2_000_000,
) -> None:
    """Render a point cloud off-screen to a PNG, over the faded truth mesh.

    Parameters
    ----------
    path_png : str or PathLike
        Output picture (written atomically).
    xyz : (n, 3) float [m]
        Points in the world frame.
    classification : (n,) int or None
        Class codes; required for ``color_by="class"``.
    truth_vertices : (n_vertices, 3) float [m], truth_faces : (n_faces, 3) int, optional
        Truth meshes, drawn light grey at opacity 0.25.
    title : str, optional
        Text at the top left.
    color_by : str
        ``"class"`` (colours of :data:`CLASS_COLOURS`, legend of the classes present), or a scalar
        colouring with a scalar bar: ``"intensity"``, ``"channel"``, ``"range_error"`` (diverging,
        symmetric about 0), ``"snr"``, ``"amplitude"``, ``"incidence"``, or any other name (viridis);
        then ``scalars`` (n,) gives the values.
    class_names : dict code -> name, optional
        Overrides the scene label table for names and colours.
    window_size : (width, height) pixels
    point_size : float [pixels]
    max_points : int
        Larger clouds are thinned by a fixed stride (deterministic) before rendering.

    The camera looks at the points' bounding box obliquely from the south-west and above (z up),
    fitted to the points, not to the (usually larger) truth mesh. Coordinates are shifted to the
    points' centre before they reach VTK, so large world coordinates render without float32 jitter.
    """
    plotter = _point_cloud_plotter(
        xyz, classification, off_screen=True, truth_vertices=truth_vertices, truth_faces=truth_faces,
        title=title, color_by=color_by, scalars=scalars, class_names=class_names, window_size=window_size,
        point_size=point_size, max_points=max_points,
    )
    try:
        img = plotter.screenshot(return_img=True)
    finally:
        plotter.close()
    _write_png(path_png, np.ascontiguousarray(img[..., :3]))


def show_point_cloud(
    xyz,
    classification=None,
    *,
    truth_vertices=None,
    truth_faces=None,
    title: str | None = None,
    color_by: str = "class",
    scalars=None,
    class_names: Mapping[int, str] | None = None,
    window_size: Sequence[int] = (1600, 1000),
    point_size: float = 3.0,
    max_points: int = 2_000_000,
) -> None:
    """The picture of :func:`render_point_cloud` in an interactive pyvista window; returns when it is closed.

    Same parameters as :func:`render_point_cloud`, without ``path_png``. Needs a display.
    """
    plotter = _point_cloud_plotter(
        xyz, classification, off_screen=False, truth_vertices=truth_vertices, truth_faces=truth_faces,
        title=title, color_by=color_by, scalars=scalars, class_names=class_names, window_size=window_size,
        point_size=point_size, max_points=max_points,
    )
    try:
        plotter.show(title=title or "scanner-sim")
    finally:
        plotter.close()


def _point_cloud_plotter(
    xyz,
    classification,
    *,
    off_screen: bool,
    truth_vertices,
    truth_faces,
    title: str | None,
    color_by: str,
    scalars,
    class_names: Mapping[int, str] | None,
    window_size: Sequence[int],
    point_size: float,
    max_points: int,
):
    """A ``pv.Plotter`` holding the points, their colouring and legend or scalar bar, the truth mesh,
    the title and the camera (parameters as :func:`render_point_cloud`). The caller closes it.
    """
    pts = np.asarray(xyz, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"xyz: shape {pts.shape} is not allowed; expected (n, 3)")
    n = pts.shape[0]
    if color_by == "class":
        if classification is None:
            raise ValueError("classification: required when color_by='class'")
        values = np.asarray(classification)
        name = "classification"
    else:
        if scalars is None:
            raise ValueError(f"scalars: required when color_by={color_by!r} (one value per point)")
        values = np.asarray(scalars, dtype=np.float64)
        name = "scalars"
    if values.shape != (n,):
        raise ValueError(f"{name}: shape {values.shape} is not allowed; expected ({n},)")
    if (truth_vertices is None) != (truth_faces is None):
        raise ValueError("truth_vertices and truth_faces: give both or neither")
    if len(window_size) != 2 or min(window_size) < 16:
        raise ValueError(f"window_size: {window_size!r} is not allowed; expected (width, height) >= 16 pixels")
    check_window_size("window_size", window_size)
    if max_points < 1:
        raise ValueError(f"max_points: {max_points!r} is not allowed; expected >= 1")
    if not point_size > 0:
        raise ValueError(f"point_size: {point_size!r} is not allowed; expected > 0 pixels")

    if off_screen:
        _prefer_headless_vtk()
    import pyvista as pv

    if n > max_points:
        stride = int(np.ceil(n / max_points))
        pts, values = pts[::stride], values[::stride]
    finite = np.all(np.isfinite(pts), axis=1)
    pts, values = pts[finite], values[finite]
    if len(pts):
        lo, hi = pts.min(axis=0), pts.max(axis=0)
    elif truth_vertices is not None and len(truth_vertices):
        tv = np.asarray(truth_vertices, dtype=np.float64)
        lo, hi = tv.min(axis=0), tv.max(axis=0)
    else:
        lo, hi = np.zeros(3), np.ones(3)
    centre = (lo + hi) / 2.0
    half = np.maximum((hi - lo) / 2.0, 0.5)

    plotter = pv.Plotter(off_screen=off_screen, window_size=[int(window_size[0]), int(window_size[1])])
    try:
        plotter.set_background(_BACKGROUND)
        if truth_vertices is not None:
            tv = np.asarray(truth_vertices, dtype=np.float64) - centre
            tf = np.asarray(truth_faces, dtype=np.int64)
            if tv.ndim != 2 or tv.shape[1] != 3 or tf.ndim != 2 or tf.shape[1] != 3:
                raise ValueError(
                    f"truth_vertices {tv.shape} / truth_faces {tf.shape}: expected (n_vertices, 3) and (n_faces, 3)"
                )
            if len(tf):
                cells = np.column_stack([np.full(len(tf), 3, dtype=np.int64), tf]).ravel()
                plotter.add_mesh(pv.PolyData(tv, cells), color="lightgrey", opacity=0.25,
                                 smooth_shading=False, show_edges=False)
        if len(pts):
            cloud = pv.PolyData(pts - centre)
            if color_by in ("class", "channel"):  # categories: one colour each, named in a legend
                rgb, lut = categorical_rgb(values, color_by, class_names)
                cloud["rgb"] = rgb
                plotter.add_mesh(cloud, scalars="rgb", rgb=True, point_size=point_size,
                                 render_points_as_spheres=False)
                # One coloured line per category at the upper right (VTK's legend box clips long labels), its
                # left edge far enough in for the longest label (text_width_px) to end inside the window.
                w, h = int(window_size[0]), int(window_size[1])
                size = 13 if w >= 1200 else 11
                left = max(8, w - 12 - max((text_width_px(label, size) for _, label in lut.values()), default=0))
                for i, (col, label) in enumerate(lut.values()):
                    plotter.add_text(label, position=(left, int(h - 40 - 2.3 * size * i)), font_size=size,
                                     color=tuple(np.array(col) / 255.0))
            else:
                cmap, bar_title, symmetric = SCALAR_COLOUR_MAPS.get(color_by, ("viridis", color_by, False))
                good = values[np.isfinite(values)]
                if good.size == 0:
                    clim = (0.0, 1.0)
                elif symmetric:
                    m = float(np.percentile(np.abs(good), 99)) or 1.0
                    clim = (-m, m)
                else:
                    a, b = np.percentile(good, [1, 99])
                    clim = (float(a), float(b) if b > a else float(a) + 1.0)
                cloud[bar_title] = values
                plotter.add_mesh(cloud, scalars=bar_title, cmap=cmap, clim=clim, point_size=point_size,
                                 render_points_as_spheres=False, nan_color="magenta",
                                 scalar_bar_args={"title": bar_title, "vertical": True, "color": "white"})
        if title:
            plotter.add_text(title, position="upper_left", font_size=14, color="white")

        view = np.array([-0.55, -1.0, 0.85])
        view /= np.linalg.norm(view)
        radius = float(np.linalg.norm(half))
        plotter.camera.focal_point = (0.0, 0.0, 0.0)
        plotter.camera.position = tuple(view * radius * 3.0)
        plotter.camera.up = (0.0, 0.0, 1.0)
        plotter.reset_camera(bounds=(-half[0], half[0], -half[1], half[1], -half[2], half[2]))
        plotter.camera.zoom(1.15)
    except BaseException:
        plotter.close()
        raise
    return plotter


def plot_waveforms(
    path_png,
    time_ns,
    channels: Mapping[str, np.ndarray],
    noise_free: Mapping[str, np.ndarray] | None = None,
    title: str | None = None,
    *,
    adc_max_lsb: float | None = None,
) -> None:
    """Digitised records of one pulse, one panel per channel, over their noise-free curves.

    Like the MULS paper's Figures 7 and 8: amplitude [LSB] against time [ns] for CH0..CH3.

    Parameters
    ----------
    time_ns : (n_samples,) float [ns]
        Sample times from emission.
    channels : dict name -> (n_samples,) array [LSB]
        Noisy digitised records, drawn as steps; panels in the dict's order.
    noise_free : dict name -> (n_samples,) array [LSB], optional
        The same channels without noise (and without quantisation), drawn dashed.
    adc_max_lsb : float, optional
        Full-scale code (e.g. 1023 for 10 bits), drawn as a dotted saturation line.
    """
    t = np.asarray(time_ns, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"time_ns: shape {t.shape} is not allowed; expected (n_samples,)")
    if not isinstance(channels, Mapping) or not channels:
        raise ValueError("channels: expected a non-empty dict of name -> (n_samples,) array")
    for label, group in (("channels", channels), ("noise_free", noise_free or {})):
        for name, data in group.items():
            if np.shape(data) != t.shape:
                raise ValueError(f"{label}[{name!r}]: shape {np.shape(data)} is not allowed; expected {t.shape}")
    unknown = set(noise_free or {}) - set(channels)
    if unknown:
        raise ValueError(f"noise_free: channels {sorted(unknown)} are not in channels ({list(channels)})")

    from matplotlib.figure import Figure

    n = len(channels)
    fig = Figure(figsize=(9.0, 1.9 * n + 0.8), dpi=110, layout="constrained")
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    for ax, (name, data) in zip(axes, channels.items()):
        ax.plot(t, np.asarray(data, dtype=np.float64), drawstyle="steps-mid", lw=0.9, color="tab:blue",
                label="digitised")
        if noise_free is not None and name in noise_free:
            ax.plot(t, np.asarray(noise_free[name], dtype=np.float64), "--", lw=1.2, color="k", label="noise-free")
        if adc_max_lsb is not None:
            ax.axhline(adc_max_lsb, ls=":", color="tab:red", lw=1.0, label="full scale")
        ax.set_ylabel(f"{name} [LSB]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time from emission [ns]")
    if title:
        fig.suptitle(title)
    _figure_to_png(fig, path_png)


def plot_overlap(
    path_png,
    distance_m,
    raycast,
    analytic,
    *,
    title: str | None = None,
    raycast_label: str = "ray-cast (sub-rays in FOV and visible)",
    analytic_label: str = "MULS Eq. 11",
    dense_distance_m=None,
    dense_analytic=None,
) -> None:
    """Overlap factor against distance: the ray-cast estimate over the analytic Eq. 11 curve.

    Parameters
    ----------
    distance_m : (n,) float [m]
        Distance to the flat target.
    raycast : (n,) float [1]
        Fraction of beam energy passing the receiver check (markers); NaN entries are skipped.
    analytic : (n,) float [1]
        Eq. 11 overlap at the same distances (line).
    dense_distance_m, dense_analytic : (m,) float, optional
        A finer Eq. 11 curve to draw instead of ``analytic`` (which then only checks shapes).
    """
    d = np.asarray(distance_m, dtype=np.float64)
    if d.ndim != 1:
        raise ValueError(f"distance_m: shape {d.shape} is not allowed; expected (n,)")
    r = np.asarray(raycast, dtype=np.float64)
    a = np.asarray(analytic, dtype=np.float64)
    for name, arr in (("raycast", r), ("analytic", a)):
        if arr.shape != d.shape:
            raise ValueError(f"{name}: shape {arr.shape} is not allowed; expected {d.shape}")
    if (dense_distance_m is None) != (dense_analytic is None):
        raise ValueError("dense_distance_m and dense_analytic: give both or neither")
    if dense_distance_m is not None:
        curve_d = np.asarray(dense_distance_m, dtype=np.float64)
        curve_a = np.asarray(dense_analytic, dtype=np.float64)
        if curve_d.ndim != 1 or curve_a.shape != curve_d.shape:
            raise ValueError(
                f"dense_distance_m {curve_d.shape} / dense_analytic {curve_a.shape}: expected two (m,) arrays"
            )
    else:
        curve_d, curve_a = d, a

    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 4.5), dpi=110, layout="constrained")
    ax = fig.subplots()
    ax.plot(curve_d, curve_a, "-", color="k", lw=1.5, label=analytic_label)
    ax.plot(d, r, "o", ms=4, color="tab:orange", label=raycast_label)
    ax.set_xlabel("distance to target [m]")
    ax.set_ylabel("overlap factor O(z)")
    ax.set_ylim(-0.02, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    if title:
        ax.set_title(title)
    _figure_to_png(fig, path_png)


#: Colours of the coverage map: not reached, covered, then one per gap cause (scanner_sim.metrics.coverage.GAP_CAUSES).
COVERAGE_COLOURS: dict[str, str] = {
    "not_reached": "#f0f0f0",
    "covered": "#2a9d8f",
    "no_hit": "#9e9e9e",
    "blind_zone": "#7b2cbf",
    "below_threshold": "#d62828",
    "saturated": "#f4d35e",
    "masked_by_backscatter": "#f77f00",
    "outside_gate": "#277da1",
    "out_of_tolerance": "#e56b9f",
    "other_surface": "#495057",
}
#: Plan cells with no seabed (a raster's nodata, where a mesh seabed does not reach) on a coverage map.
NO_SEABED_COLOUR = "#1d3557"

#: Curve colour per water preset in coverage charts (others take the matplotlib cycle).
WATER_COLOURS: dict[str, str] = {"clean_ocean": "#1f77b4", "coastal_ocean": "#2ca02c", "turbid_harbor": "#8c564b",
                                 "pool": "#17becf", "pond": "#bcbd22"}
_INSTRUMENT_STYLES = {"mul2023": ("-", "o"), "single_channel": ("--", "s"), "coaxial": (":", "^")}


def plot_coverage_map(path_png, state, extent_m, gap_causes: Sequence[str], *, lines=(), markers=(),
                      title: str | None = None, no_seabed=None) -> None:
    """Plan map of coverage cells to a PNG.

    state : (ny, nx) int, row = y: -2 not reached, -1 covered, k >= 0 missed for ``gap_causes[k]``.
    extent_m : (x_min, x_max, y_min, y_max) [m] of the grid.
    lines : [(name, (n, 2) xy [m])] drawn over the cells (cable centrelines).
    markers : [(name, (2,) xy [m])] marked and named (mines, objects).
    no_seabed : (ny, nx) bool or None: cells with no seabed data, drawn in :data:`NO_SEABED_COLOUR` over the rest.
    The legend lists covered and every cause present, with its area share of the reached cells.
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    state = np.asarray(state)
    if state.ndim != 2:
        raise ValueError(f"state: shape {state.shape} is not allowed; expected (ny, nx)")
    names = ["not_reached", "covered", *gap_causes]
    unknown = [n for n in names if n not in COVERAGE_COLOURS]
    if unknown:
        raise ValueError(f"gap_causes: {unknown} have no colour; known: {sorted(COVERAGE_COLOURS)}")
    codes = state.astype(np.int64) + 2
    x0, x1, y0, y1 = (float(v) for v in extent_m)
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    fig = Figure(figsize=(10.0, float(np.clip(7.0 * aspect + 1.4, 3.0, 12.0))), dpi=110)  # the legend takes ~3 in
    ax = fig.add_subplot()
    ax.imshow(codes, origin="lower", extent=(x0, x1, y0, y1), cmap=ListedColormap([COVERAGE_COLOURS[n] for n in names]),
              vmin=-0.5, vmax=len(names) - 0.5, interpolation="nearest")
    gaps = np.asarray(no_seabed, bool) if no_seabed is not None else np.zeros(state.shape, bool)
    if gaps.any():
        ax.imshow(np.ma.masked_where(~gaps, np.ones(state.shape)), origin="lower", extent=(x0, x1, y0, y1),
                  cmap=ListedColormap([NO_SEABED_COLOUR]), interpolation="nearest")
    for name, xy in lines:
        xy = np.asarray(xy, float)
        ax.plot(xy[:, 0], xy[:, 1], color="black", lw=0.8, alpha=0.8)
        ax.annotate(name, xy[0], fontsize=8, xytext=(3, 3), textcoords="offset points")
    for name, xy in markers:
        ax.plot(*xy, marker="x", color="black", ms=7, mew=1.5)
        ax.annotate(name, xy, fontsize=8, xytext=(5, 5), textcoords="offset points")
    reached = max(int((codes >= 1).sum()), 1)
    counts = np.bincount(codes.ravel(), minlength=len(names))
    handles = [Patch(facecolor=COVERAGE_COLOURS[n], edgecolor="grey", label=f"{n.replace('_', ' ')} "
                     f"{counts[k] / reached:.1%}") for k, n in enumerate(names) if k == 1 or (k >= 2 and counts[k])]
    handles.append(Patch(facecolor=COVERAGE_COLOURS["not_reached"], edgecolor="grey", label="not reached by the scan"))
    if gaps.any():
        handles.append(Patch(facecolor=NO_SEABED_COLOUR, edgecolor="grey", label="no seabed data"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    finish_plan_map(fig, ax, path_png, title)


def finish_plan_map(fig, ax, path_png, title: str | None, x_label: str = "x east [m]") -> None:
    """A plan map's axes (x east, y north, equal scale), its title, written to ``path_png``."""
    ax.set_xlabel(x_label)
    ax.set_ylabel("y north [m]")
    ax.set_aspect("equal")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    _figure_to_png(fig, path_png)


def curve_layout(keys: Sequence[tuple], span: float) -> dict[tuple, tuple[float, float, float, int]]:
    """Per curve key, in drawing order: (x offset, line width, marker size, z-order). Every curve is drawn a little
    apart along x (2 % of ``span``, at least 0.02, between neighbours) and thinner, with smaller markers, than
    the one before, on top of it: curves of equal values (two instruments both at 100 %) all stay visible."""
    step = 0.02 * max(span, 1.0)
    n = len(keys)
    return {key: ((j - 0.5 * (n - 1)) * step, max(3.6 - 0.5 * j, 1.0), max(10.0 - 1.2 * j, 4.0), 2 + j)
            for j, key in enumerate(keys)}


def plot_coverage_vs_altitude(path_png, records: Sequence[Mapping], *, title: str | None = None) -> None:
    """Covered fraction [%] against altitude [m], one curve per water type and instrument.

    records: mappings with ``water``, ``instrument``, ``altitude_m`` and ``covered_fraction`` (0..1 or None).
    Colour tells the water, line style and marker the instrument. Where curves give equal coverage (clean and
    coastal at 100 %, or both instruments of one water), they stay visible (:func:`curve_layout`).
    """
    from matplotlib.figure import Figure

    curves: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for r in records:
        if r["covered_fraction"] is not None:
            curves.setdefault((r["water"], r["instrument"]), []).append((r["altitude_m"], 100.0 * r["covered_fraction"]))
    fig = Figure(figsize=(8.0, 5.0), dpi=110)
    ax = fig.add_subplot()
    cycle = iter(f"C{i}" for i in range(3, 100))
    colours: dict[str, str] = {}
    altitudes = [a for pts in curves.values() for a, _ in pts]
    layout = curve_layout(list(curves), max(altitudes) - min(altitudes) if altitudes else 0.0)
    for (water, instrument), pts in curves.items():
        colour = colours.setdefault(water, WATER_COLOURS.get(water) or next(cycle))
        line, marker = _INSTRUMENT_STYLES.get(instrument, ("-.", "D"))
        alt, frac = np.array(sorted(pts)).T
        dx, lw, ms, z = layout[(water, instrument)]
        ax.plot(alt + dx, frac, line, marker=marker, color=colour, lw=lw, ms=ms, zorder=z,
                label=f"{water}, {instrument}")
    ax.set_xlabel("altitude [m]")
    ax.set_ylabel("covered fraction of the reached area [%]")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    if curves:
        ax.legend(fontsize=8, loc="lower left")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    _figure_to_png(fig, path_png)


def plot_sweep(path_png, records: Sequence[Mapping], x: str, y: str, *, lines: Sequence[str] = (),
               title: str | None = None, y_label: str | None = None) -> None:
    """A figure ``y`` against sweep axis ``x``, one curve per combination of the ``lines`` axes' values.

    records: mappings with keys ``x``, ``y`` and every name in ``lines`` (a campaign's passes); a record
    whose ``y`` is None is left out. Numeric ``x`` values are placed by value, others in first-seen order.
    Colour tells the value of ``lines[0]`` (a water preset's own colour when it is one), line style and
    marker the values of the other ``lines`` axes (an instrument's own style when it is one).
    """
    from matplotlib.figure import Figure

    def label(value):
        return f"{value:g}" if isinstance(value, float) else str(value)

    xs = [r[x] for r in records if r[y] is not None]
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xs)
    places = {v: float(v) for v in xs} if numeric else {v: float(i) for i, v in enumerate(dict.fromkeys(map(str, xs)))}
    curves: dict[tuple, list[tuple[float, float]]] = {}
    for r in records:
        if r[y] is not None:
            key = tuple(r[name] for name in lines)
            curves.setdefault(key, []).append((places[r[x] if numeric else str(r[x])], float(r[y])))
    fig = Figure(figsize=(8.0, 5.0), dpi=110)
    ax = fig.add_subplot()
    colour_cycle, style_cycle = iter(f"C{i}" for i in range(100)), itertools.cycle(
        [("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"), ("-", "v"), ("--", "P")])
    colours: dict[tuple, str] = {}
    styles: dict[tuple, tuple[str, str]] = {}
    for key, pts in curves.items():
        if key[:1] not in colours:
            colours[key[:1]] = (WATER_COLOURS.get(str(key[0])) if key else None) or next(colour_cycle)
        if key[1:] not in styles:
            styles[key[1:]] = (_INSTRUMENT_STYLES.get(str(key[1])) if len(key) > 1 else None) or next(style_cycle)
        (line, marker), px_py = styles[key[1:]], np.array(sorted(pts)).T
        ax.plot(*px_py, line, marker=marker, color=colours[key[:1]],
                label=", ".join(f"{name}={label(v)}" for name, v in zip(lines, key)) or None)
    if not numeric:
        ax.set_xticks(list(places.values()), list(places))
    ax.set_xlabel(x)
    ax.set_ylabel(y_label or y)
    ax.grid(alpha=0.3)
    if lines and curves:
        ax.legend(fontsize=8, loc="best")
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    _figure_to_png(fig, path_png)


#: Panels of the speed-against-accuracy chart: (section, key, axis label).
TRADEOFF_PANELS = (
    ("vs_truth", "median_abs_range_error_m", "median |range error| vs truth [m]"),
    ("vs_truth", "p95_abs_range_error_m", "95th pct |range error| vs truth [m]"),
    ("vs_truth", "false_alarms_per_pulse", "false alarms per pulse"),
    ("vs_truth", "hidden_points_per_pulse", "points on hidden surfaces per pulse"),
    ("vs_reference", "missing_per_pulse", "returns missing vs reference per pulse"),
    ("vs_reference", "extra_per_pulse", "returns extra vs reference per pulse"),
    ("vs_reference", "p95_position_diff_m", "95th pct position diff vs reference [m]"),
    ("vs_reference", "coverage_diff", "coverage minus reference's"),
    ("vs_reference", "waveform_r2", "1 - waveform R² vs reference"),
)


def plot_tradeoff(path_png, result: Mapping) -> None:
    """Pulses/s (log axis) against each error metric of a ``scanner-sim tradeoff`` result, one panel per metric
    (:data:`TRADEOFF_PANELS`): the levels as large labelled markers joined in order, the single knobs of
    ``balanced`` as small grey labelled markers. A metric a run lacks (None) is left out of its panel."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig = Figure(figsize=(13.0, 11.0), dpi=100)
    axes = fig.subplots(3, 3).ravel()
    groups = (("levels", dict(color="C0", ms=9, marker="o", ls="-"), 9),
              ("knobs", dict(color="0.45", ms=5, marker="s", ls="none"), 7))
    for ax, (section, key, label) in zip(axes, TRADEOFF_PANELS):
        for group, style, size in groups:
            names, xs, ys = [], [], []
            for name, entry in sorted(result[group].items(), key=lambda item: item[1]["pulses_per_s"]):
                value = entry[section][key]
                if value is None:
                    continue
                names.append(name)
                xs.append(entry["pulses_per_s"])
                ys.append(1.0 - value if key == "waveform_r2" else value)
            ax.plot(xs, ys, **style)
            for name, x, y in zip(names, xs, ys):
                ax.annotate(name, (x, y), textcoords="offset points", xytext=(4, 3), fontsize=size,
                            color=style["color"])
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 3.0)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / 1000:g}k" if v >= 1000 else f"{v:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        lo, hi = ax.get_xlim()
        ax.set_xlim(lo, hi * 1.8)  # room for the labels of the fastest runs
        ax.set_xlabel("pulses/s")
        ax.set_ylabel(label, fontsize=9)
        ax.grid(alpha=0.3, which="both")
    fig.suptitle(f"speed against accuracy: {result['scene']}, {result['pulses']:,} pulses per run, "
                 f"reference = {result['reference']}", fontsize=11)
    fig.tight_layout()
    _figure_to_png(fig, path_png)
