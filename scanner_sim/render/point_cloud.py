"""Point clouds rendered with pyvista over the faded truth mesh: off-screen to a PNG, or in a window (pyvista or
open3d). Colours come from :mod:`scanner_sim.render.point_colours`."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from muls.infra.atomic import atomic_path
from scanner_sim.config.materials import LABELS
from scanner_sim.render.point_colours import (
    HEIGHT_COLOUR_MAP,
    SCALAR_COLOUR_MAPS,
    categorical_rgb,
    shaded_height_rgb,
)

#: Largest side of a point-cloud picture or window [px]: the largest framebuffer side GPU OpenGL drivers commonly
#: render (GL_MAX_RENDERBUFFER_SIZE and the viewport are 16384 on most; Mesa's llvmpipe renders more).
MAX_WINDOW_SIDE_PX = 16384
#: Bytes VTK and the screenshot hold per pixel: 88 measured (peak RSS of scanner-sim view between 2000 x 2000 and
#: 4000 x 4000, off-screen), rounded up. Past the memory VTK aborts (std::bad_alloc) and takes the process with it.
WINDOW_BYTES_PER_PIXEL = 100


def check_window_size(key: str, window_size: Sequence[int], available_bytes: int | None = None) -> None:
    """Refuse, before VTK allocates it, a (width, height) [px] with a side beyond :data:`MAX_WINDOW_SIDE_PX` or a
    picture needing more memory than a command may plan on (:func:`muls.infra.memory.check_memory`): a ValueError
    naming ``key``."""
    from muls.infra.memory import check_memory

    w, h = (int(v) for v in window_size)
    shown = f"{w} {h}"
    if max(w, h) > MAX_WINDOW_SIDE_PX:
        raise ValueError(f"{key} = {shown}: at most {MAX_WINDOW_SIDE_PX} px a side (the largest framebuffer OpenGL "
                         "drivers commonly render)")
    per = WINDOW_BYTES_PER_PIXEL
    check_memory(key, shown, w * h * per, f"a {w:,} x {h:,} px picture",
                 lambda budget: f"at most {int(budget // per):,} pixels (width x height) on this machine",
                 available_bytes)


#: Class code of the seabed, whose points ``color_by="height"`` colours by their height.
SEABED_CODE = LABELS["seabed"]
#: Title of the colour bar of heights: z in the world frame, up, so a seabed below the surface reads negative.
HEIGHT_BAR_TITLE = "height z [m]"

_BACKGROUND = "#0b1a2a"  # deep-water navy: white panels and the grey truth mesh stay visible


#: zlib level of the point-cloud PNGs: level 1 encodes a 1600 x 1000 render 3 to 4 times faster than matplotlib's
#: ``imsave`` (RGBA at zlib's default 6, the PNG's last 0.2 to 0.9 s after a pass) for a file of the same size
#: (a picture of points compresses poorly at any level: 891 against 904 KiB).
PNG_COMPRESS_LEVEL = 1


def _write_png(path_png, rgb: np.ndarray) -> None:
    """``rgb`` (height, width, 3) uint8 to an RGB PNG, atomically."""
    from PIL import Image

    with atomic_path(path_png) as tmp:
        with open(tmp, "wb") as fh:
            Image.fromarray(rgb).save(fh, format="png", compress_level=PNG_COMPRESS_LEVEL)


def text_width_px(text: str, font_size: int) -> int:
    """Width [px] that VTK's default font (Arial) takes for ``text`` at ``font_size``, rounded up: measured at 13,
    "seabed, class 40" takes 217 px (13.6 px a character); 1.1 font sizes a character keeps wide letters in."""
    return int(math.ceil(1.1 * font_size * len(text)))


def _prefer_headless_vtk() -> None:
    """Without a display, render through EGL straight away instead of failing over from X11 with a warning."""
    import os

    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def points_polydata(points):
    """A pyvista ``PolyData`` of :class:`scanner_sim.records.point_records.PointRecords`: one vertex per point, every other
    field as point data (by its field name)."""
    import pyvista as pv

    cloud = pv.PolyData(np.asarray(points.xyz, float))
    for name, values in points.as_dict().items():
        if name != "xyz":
            cloud.point_data[name] = values
    return cloud


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
    normals=None,
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
        Class codes; required for ``color_by="class"``. With ``color_by="height"``, the points of a class other
        than the seabed keep their class colours (named in a legend).
    normals : (n, 3) float or None
        Unit normals of the surface under each point, which hill-shade it; required for ``color_by="height"``.
    truth_vertices : (n_vertices, 3) float [m], truth_faces : (n_faces, 3) int, optional
        Truth meshes, drawn light grey at opacity 0.25.
    title : str, optional
        Text at the top left.
    color_by : str
        ``"class"`` (colours of :data:`CLASS_COLOURS`, legend of the classes present), ``"height"`` (z through
        :data:`~scanner_sim.render.point_colours.HEIGHT_COLOUR_MAP` between its 1st and 99th percentiles,
        hill-shaded by ``normals``, with a colour bar of z and a scale bar along the south edge), or a scalar
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
        xyz, classification, normals=normals, off_screen=True, truth_vertices=truth_vertices, truth_faces=truth_faces,
        title=title, color_by=color_by, scalars=scalars, class_names=class_names, window_size=window_size,
        point_size=point_size, max_points=max_points,
    )
    _screenshot_png(plotter, path_png)


def _screenshot_png(plotter, path_png) -> None:
    """Render ``plotter`` once, close it and write the picture to ``path_png``."""
    try:
        img = plotter.screenshot(return_img=True)
    finally:
        plotter.close()
    _write_png(path_png, np.ascontiguousarray(img[..., :3]))


class PointCloudStage:
    """The part of a point-cloud picture known before its points: an off-screen or on-screen ``pv.Plotter`` of
    ``window_size`` (width, height) [px] with its background, and the truth mesh (``truth_vertices`` (n, 3) [m],
    ``truth_faces`` (m, 3), or both None) added light grey at opacity 0.25, its points shifted to the picture's
    centre once the points give it (:meth:`add_truth`). Built ahead, it leaves a picture's end only its points and its
    render; :func:`render_prepared_point_cloud` draws on one."""

    def __init__(self, truth_vertices, truth_faces, *, off_screen: bool, window_size: Sequence[int]):
        if (truth_vertices is None) != (truth_faces is None):
            raise ValueError("truth_vertices and truth_faces: give both or neither")
        if len(window_size) != 2 or min(window_size) < 16:
            raise ValueError(f"window_size: {window_size!r} is not allowed; expected (width, height) >= 16 pixels")
        check_window_size("window_size", window_size)
        if off_screen:
            _prefer_headless_vtk()
        import pyvista as pv

        self.window_size = (int(window_size[0]), int(window_size[1]))
        self.truth_vertices, self.truth = None, None
        self.plotter = pv.Plotter(off_screen=off_screen, window_size=list(self.window_size))
        try:
            self.plotter.set_background(_BACKGROUND)
            if truth_vertices is not None:
                tv = np.asarray(truth_vertices, dtype=np.float64)
                tf = np.asarray(truth_faces, dtype=np.int64)
                if tv.ndim != 2 or tv.shape[1] != 3 or tf.ndim != 2 or tf.shape[1] != 3:
                    raise ValueError(
                        f"truth_vertices {tv.shape} / truth_faces {tf.shape}: expected (n_vertices, 3) and (n_faces, 3)"
                    )
                self.truth_vertices = tv
                if len(tf):
                    cells = np.column_stack([np.full(len(tf), 3, dtype=np.int64), tf]).ravel()
                    self.truth = pv.PolyData(tv, cells)
                    self.plotter.add_mesh(self.truth, color="lightgrey", opacity=0.25, smooth_shading=False,
                                          show_edges=False)
        except BaseException:
            self.plotter.close()
            raise

    def add_truth(self, centre: np.ndarray) -> None:
        """Shift the truth mesh's points by ``-centre`` (3,) [m]: VTK then gets coordinates near 0."""
        if self.truth is not None:
            self.truth.points = self.truth_vertices - centre


#: The stage :func:`prepare_point_cloud` built in this process, for the next :func:`render_prepared_point_cloud`.
_prepared: list[PointCloudStage] = []


def prepare_point_cloud(truth_vertices=None, truth_faces=None, *, window_size: Sequence[int] = (1600, 1000)) -> None:
    """Build, in this process, the :class:`PointCloudStage` (off-screen) of the next
    :func:`render_prepared_point_cloud`: what a picture process does while the pass runs."""
    while _prepared:
        _prepared.pop().plotter.close()
    _prepared.append(PointCloudStage(truth_vertices, truth_faces, off_screen=True, window_size=window_size))


def render_prepared_point_cloud(path_png, xyz, classification=None, **options) -> None:
    """:func:`render_point_cloud` on the stage :func:`prepare_point_cloud` built (its truth mesh and window size);
    ``options``: the other keywords of :func:`render_point_cloud`. The same picture, to the byte."""
    if not _prepared:
        raise RuntimeError("render_prepared_point_cloud: no stage prepared in this process (prepare_point_cloud)")
    stage = _prepared.pop()
    try:
        plotter = _point_cloud_plotter(xyz, classification, off_screen=True, truth_vertices=stage.truth_vertices,
                                       truth_faces=None, window_size=stage.window_size, stage=stage, **options)
    except BaseException:
        stage.plotter.close()
        raise
    _screenshot_png(plotter, path_png)


def show_point_cloud(
    xyz,
    classification=None,
    *,
    normals=None,
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
        xyz, classification, normals=normals, off_screen=False, truth_vertices=truth_vertices, truth_faces=truth_faces,
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
    title: str | None = None,
    color_by: str = "class",
    scalars=None,
    class_names: Mapping[int, str] | None = None,
    window_size: Sequence[int],
    point_size: float = 3.0,
    max_points: int = 2_000_000,
    normals=None,
    stage: PointCloudStage | None = None,
):
    """A ``pv.Plotter`` holding the points, their colouring and legend or scalar bar, the truth mesh,
    the title and the camera (parameters as :func:`render_point_cloud`), on ``stage`` when one was built ahead
    (its plotter and truth mesh; ``truth_vertices`` then only frames an empty cloud). The caller closes it.
    """
    pts = np.asarray(xyz, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"xyz: shape {pts.shape} is not allowed; expected (n, 3)")
    n = pts.shape[0]
    shading = None
    if color_by == "class":
        if classification is None:
            raise ValueError("classification: required when color_by='class'")
        values = np.asarray(classification)
        name = "classification"
    elif color_by == "height":
        if normals is None:
            raise ValueError("normals: required when color_by='height' (the surface's unit normal under each point)")
        shading = np.asarray(normals, dtype=np.float64)
        if shading.shape != (n, 3):
            raise ValueError(f"normals: shape {shading.shape} is not allowed; expected ({n}, 3)")
        values = (np.full(n, SEABED_CODE) if classification is None else np.asarray(classification)).astype(np.int64)
        name = "classification"
    else:
        if scalars is None:
            raise ValueError(f"scalars: required when color_by={color_by!r} (one value per point)")
        values = np.asarray(scalars, dtype=np.float64)
        name = "scalars"
    if values.shape != (n,):
        raise ValueError(f"{name}: shape {values.shape} is not allowed; expected ({n},)")
    if max_points < 1:
        raise ValueError(f"max_points: {max_points!r} is not allowed; expected >= 1")
    if not point_size > 0:
        raise ValueError(f"point_size: {point_size!r} is not allowed; expected > 0 pixels")
    import pyvista as pv

    if n > max_points:
        stride = int(np.ceil(n / max_points))
        pts, values = pts[::stride], values[::stride]
        shading = None if shading is None else shading[::stride]
    finite = np.all(np.isfinite(pts), axis=1)
    pts, values = pts[finite], values[finite]
    shading = None if shading is None else shading[finite]
    if len(pts):
        lo, hi = pts.min(axis=0), pts.max(axis=0)
    elif truth_vertices is not None and len(truth_vertices):
        tv = np.asarray(truth_vertices, dtype=np.float64)
        lo, hi = tv.min(axis=0), tv.max(axis=0)
    else:
        lo, hi = np.zeros(3), np.ones(3)
    centre = (lo + hi) / 2.0
    half = np.maximum((hi - lo) / 2.0, 0.5)

    if stage is None:
        stage = PointCloudStage(truth_vertices, truth_faces, off_screen=off_screen, window_size=window_size)
    plotter = stage.plotter
    try:
        stage.add_truth(centre)
        if len(pts):
            cloud = pv.PolyData(pts - centre)
            if color_by in ("class", "channel", "height"):  # categories: one colour each, named in a legend
                rgb, lut = categorical_rgb(values, "channel" if color_by == "channel" else "class", class_names)
                if color_by == "height":
                    seabed = values == SEABED_CODE
                    lut.pop(SEABED_CODE, None)
                    clim = _height_limits(pts[seabed, 2])
                    rgb[seabed] = np.round(255.0 * shaded_height_rgb(pts[seabed, 2], shading[seabed], clim))
                    _add_height_bar(plotter, pts[:1] - centre, clim)
                    _add_scale_bar(plotter, lo - centre, hi - centre)
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


def _height_limits(z: np.ndarray) -> tuple[float, float]:
    """(lo, hi) [m] of the colour bar of heights ``z`` (n,): their 1st and 99th percentiles, 1 m apart at least
    apart when flatter (a flat seabed reads one colour, not noise stretched over the whole map)."""
    if not z.size:
        return 0.0, 1.0
    lo, hi = (float(v) for v in np.percentile(z, [1, 99]))
    mid, half = 0.5 * (lo + hi), max(0.5 * (hi - lo), 0.5)
    return mid - half, mid + half


def _add_height_bar(plotter, anchor: np.ndarray, clim: tuple[float, float]) -> None:
    """The colour bar of heights: VTK draws a bar from a mapped actor's lookup table, so an invisible point at
    ``anchor`` (1, 3) carries :data:`HEIGHT_COLOUR_MAP` over ``clim``."""
    import pyvista as pv

    plotter.add_mesh(pv.PolyData(np.repeat(anchor, 2, axis=0)), scalars=np.array(clim), cmap=HEIGHT_COLOUR_MAP,
                     clim=clim, opacity=0.0, point_size=1.0,
                     scalar_bar_args={"title": HEIGHT_BAR_TITLE, "vertical": True, "color": "white", "fmt": "%.1f"})


def _add_scale_bar(plotter, lo: np.ndarray, hi: np.ndarray) -> None:
    """A scale bar: a ruler from the south-west corner of the box ``lo``..``hi`` (3,) [m] eastwards, of the round
    length (:func:`scale_bar_m`) that fits its width, labelled in metres."""
    length, divisions = scale_bar_m(float(hi[0] - lo[0]))
    plotter.add_ruler((lo[0], lo[1], lo[2]), (lo[0] + length, lo[1], lo[2]), title="m", number_labels=divisions + 1,
                      label_format="%g", label_color="white", tick_color="white", font_size_factor=0.5)


def scale_bar_m(width_m: float) -> tuple[float, int]:
    """(length [m], divisions) of a scale bar across ``width_m`` [m]: the longest 1, 2 or 5 times a power of ten
    that fits, divided into 5, 4 or 5 steps (0.2, 0.5 or 1 of its power of ten: round labels)."""
    width = max(width_m, 1e-3)
    power = 10.0 ** math.floor(math.log10(width))
    lead = max(m for m in (1, 2, 5) if m * power <= width * (1 + 1e-9))
    return lead * power, {1: 5, 2: 4, 5: 5}[lead]
