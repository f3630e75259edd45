"""The pictures of a pass: render.png (:func:`render_points`, from the :class:`CloudSample` taken as the pass goes),
coverage_map.png and s44_map.png. Each function here gathers in this process what its picture shows (plain arrays
and text) and hands it to ``draw``, which calls the drawing function of :mod:`scanner_sim.render`: :func:`draw_here`
in this process, or :meth:`scanner_sim.render.worker.PictureWorker.draw` in a child process beside the pass."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scanner_sim.metrics.coverage import BACKGROUND_KINDS, GAP_CAUSES, CoverageAccumulator
from scanner_sim.metrics.s44 import ORDER_NAMES
from scanner_sim.render.coverage_map import plot_coverage_map
from scanner_sim.render.point_cloud import prepare_point_cloud, render_point_cloud, render_prepared_point_cloud
from scanner_sim.render.s44_map import plot_order_map


def draw_here(function, *args, **kwargs) -> None:
    """Draw a picture in this process: ``function(*args, **kwargs)``."""
    function(*args, **kwargs)


#: Points the picture of a pass shows at most (decimated evenly as the pass goes).
RENDER_MAX_POINTS = 1_500_000


class CloudSample:
    """An even sample of the pass's points, at most ``max_points`` (every k-th point, k doubling as the pass
    grows): positions (n, 3) [m] and classes for the picture of the pass."""

    def __init__(self, max_points: int = RENDER_MAX_POINTS):
        self.max_points, self.stride, self._seen = max_points, 1, 0
        self._xyz, self._classes = [], []

    def add(self, chunk) -> None:
        points = chunk.points
        keep = (self._seen + np.arange(len(points))) % self.stride == 0
        self._seen += len(points)
        self._xyz.append(points.xyz[keep])
        self._classes.append(points.classification[keep])
        if sum(len(c) for c in self._classes) > self.max_points:
            self.stride *= 2
            first = 0
            for i, part in enumerate(self._classes):  # keep every other kept point, in pass order
                pick = (first + np.arange(len(part))) % 2 == 0
                first += len(part)
                self._xyz[i], self._classes[i] = self._xyz[i][pick], part[pick]

    @property
    def xyz(self) -> np.ndarray:
        return np.concatenate(self._xyz) if self._xyz else np.zeros((0, 3))

    @property
    def classification(self) -> np.ndarray:
        return np.concatenate(self._classes) if self._classes else np.zeros(0, np.uint8)


def prepare_render(scene, window_size, draw) -> None:
    """Build render.png's plotter and the truth mesh of ``scene`` ahead, in the process ``draw`` draws in (while
    the pass runs), for :func:`render_points` with ``prepared``."""
    draw(prepare_point_cloud, scene.vertices, scene.faces, window_size=window_size)


def render_points(path: Path, sample: CloudSample, scene, facts, window_size=(1600, 1000), draw=draw_here,
                  prepared: bool = False) -> None:
    """render.png: the sampled points over the faded truth mesh of ``scene``; over a seabed, its points coloured by
    height and hill-shaded by the seabed's normals under them, with a colour bar and a scale bar, the other classes'
    points in their class colours; without one, every point by class. ``facts``: the pass's
    :class:`~scanner_sim.survey.sinks.PassFacts`; ``prepared``: :func:`prepare_render` built the plotter and mesh
    in the drawing process (``window_size`` was given there)."""
    xyz = sample.xyz
    shading = ({"color_by": "height", "normals": seabed_normals(scene.heightfield, xyz[:, 0], xyz[:, 1])}
               if scene.heightfield is not None else {})
    title = f"{facts.label}: {len(xyz):,} points ({facts.fidelity})"
    if prepared:
        draw(render_prepared_point_cloud, path, xyz, sample.classification, title=title, **shading)
    else:
        draw(render_point_cloud, path, xyz, sample.classification, truth_vertices=scene.vertices,
             truth_faces=scene.faces, title=title, window_size=window_size, **shading)


def seabed_normals(heightfield, x_m, y_m) -> np.ndarray:
    """(n, 3) unit upward normals of ``heightfield`` at (x, y) (n,) [m]: its slope by central differences one node
    spacing either side (the relief the grid resolves, not one triangle's facet)."""
    h = heightfield.spacing_m
    gx = (heightfield.height(x_m + h, y_m) - heightfield.height(x_m - h, y_m)) / (2.0 * h)
    gy = (heightfield.height(x_m, y_m + h) - heightfield.height(x_m, y_m - h)) / (2.0 * h)
    normal = np.c_[-gx, -gy, np.ones_like(gx)]
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def render_coverage_map(path: Path, coverage: CoverageAccumulator, scene, facts, figures: dict, draw=draw_here) -> None:
    """coverage_map.png: plan cells covered or missed by cause, cables drawn along, objects marked; ``figures``:
    the coverage figures of the summary."""
    lines = [(o.name, o.centreline[:, :2]) for o in scene.objects if o.centreline is not None]
    markers = []
    for o in scene.objects:
        if o.kind not in BACKGROUND_KINDS and o.centreline is None:
            corners = np.unique(scene.faces[o.face_start:o.face_stop].ravel())
            markers.append((o.name, scene.vertices[corners, :2].mean(axis=0)))
    fraction = figures["covered_fraction"]
    title = (f"{facts.label}\ncovered {fraction:.1%} of {figures['reached_area_m2']:.0f} m² reached"
             if fraction is not None else f"{facts.label}\nthe scan reaches no seabed cell")
    draw(plot_coverage_map, path, coverage.cell_states(), coverage.grid.extent_m, GAP_CAUSES, lines=lines,
         markers=markers, title=title, no_seabed=coverage.no_seabed)


def render_order_map(path: Path, coverage: CoverageAccumulator, facts, figures: dict, draw=draw_here) -> None:
    """s44_map.png: the strictest S-44 order each plan cell complies with, the planned swath outlined."""
    planned = coverage.planned_cells()
    draw(plot_order_map, path, coverage.strictest_orders(), coverage.cell_states(),
         None if planned is None else planned.reshape(coverage.grid.shape), coverage.grid.extent_m, ORDER_NAMES,
         figures, title=f"{facts.label}\nIHO S-44 orders (Ed. 6.0.0), each judged on cells of its own size (legend): "
         "95 % of a cell's soundings within the order's TVU and THU")
