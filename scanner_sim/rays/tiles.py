"""The ray stage over a site-scale scene (:class:`scanner_sim.world.site.SiteScene`): each chunk's rays are cast
into a window of the site's tiles that holds everything they can meet, built when the pass first needs it and
released when the pass has moved on (a few windows are kept, :data:`KEPT_WINDOWS`).

Exactness. A window holds the whole scene's faces over its tiles, each as the whole scene has it, and every other
object whole. A chunk's window holds, for each pulse, the disc within which any of its sub-rays can meet anything
(:func:`reach_boxes`: from the beam's origin down to the lowest geometry near it, at the steepest angle off the
vertical any sub-ray has, plus the beam's radius) and its receiver, so each first hit, and each shadow ray (from a
hit to the receiver), is the whole scene's. The seabed's proof grid of a window is the whole scene's grid cut out at
whole super cells; a proof looks only within a box around the pulse's hits (:func:`proof_box`, a bound on the one
:func:`scanner_sim.rays.seabed_kernels._bundle_clear` walks), and a chunk whose boxes leave its window is cast again
in a window that holds them. So the hits are those of the whole scene's mesh, bit for bit.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from muls.infra.runtime import kernel, release_free_heap
from scanner_sim.rays.auto import cast_auto
from scanner_sim.rays.cast import BeamCast, CastScene, cast_beams
from scanner_sim.rays.caster import RayCaster
from scanner_sim.rays.hits import Hits
from scanner_sim.rays.seabed_grid import seabed_grid

#: Windows a pass keeps built at once (the chunks in flight share them; the least recently used goes first). One is
#: enough: a chunk still casting into a window let go holds it until it is done, and the chunks that follow are in
#: the new one (a window reaches on along the line and a chunk behind).
KEPT_WINDOWS = 1
#: Chunks that give the free heap back to the system as they finish, after a window is let go (one per worker: the
#: window is freed when the last chunk casting into it is done). glibc otherwise keeps up to 512 MB of freed memory
#: for reuse (muls.infra.runtime), which the windows' arrays, freed as the pass moves on, would fill.
TRIMS_AFTER_RELEASE = 2
#: Tiles a window reaches past what it is built for, on every side (:meth:`TiledTarget.window_for`).
WINDOW_PAD_TILES = 1
#: [m] How much further a chunk's new window reaches along the way the pass goes: the pass keeps it until it has
#: gone about this far (a window's BVH is built once per this much of the line, not once per tile).
WINDOW_AHEAD_M = 120.0
#: [m] Added around a pulse's hits for the box its proofs read (:func:`proof_box`).
FOOTPRINT_SLACK_M = 0.5
#: Most tiles of one window for :meth:`TiledTarget.first_hits` (rays spread over a pass are cast in groups).
FIRST_HITS_TILES = 4


class TiledTarget:
    """What the ray stage casts into over a :class:`~scanner_sim.world.site.SiteScene`: windows of its tiles as
    :class:`~scanner_sim.rays.cast.CastScene` s, built on demand and kept :data:`KEPT_WINDOWS` at a time (thread-safe),
    and ``caster``: first hits of any rays (:meth:`first_hits`) with their faces numbered as in the whole scene."""

    def __init__(self, site, backend: str = "auto"):
        self.scene, self.backend = site, backend
        self.seabed_grid = True  # the proof grid exists, per window
        self._windows: OrderedDict[tuple, CastScene] = OrderedDict()
        self._lock, self._building = threading.Lock(), threading.Lock()
        self._trims_due = 0
        self.windows_built = 0
        self.caster = self

    def window_for(self, box: np.ndarray, build_box: np.ndarray | None = None, pad_tiles: int = WINDOW_PAD_TILES
                   ) -> CastScene:
        """A window holding ``box`` (x_min, x_max, y_min, y_max) local [m]: a kept one if one holds it, else one
        built over ``build_box`` (default ``box``; it holds ``box``) padded by ``pad_tiles`` tiles."""
        need = self._cells(box, 0)
        kept = self._kept(need)
        if kept is not None:
            return kept
        with self._building:  # one build at a time; chunks whose window is kept go on meanwhile
            kept = self._kept(need)
            if kept is not None:
                return kept
            key = self._cells(box if build_box is None else build_box, pad_tiles)
            window = self.scene.window(*key)
            caster = RayCaster.for_scene(window, self.backend)
            grid = seabed_grid(window, caster, self.scene.z_top_local)
            target = CastScene(window.without_mesh(), caster, grid)  # the caster holds the mesh from here on
            with self._lock:
                self._windows[key] = target
                self.windows_built += 1
                while len(self._windows) > KEPT_WINDOWS:
                    self._windows.popitem(last=False)
                    self._trims_due = TRIMS_AFTER_RELEASE
            return target

    def chunk_done(self) -> None:
        """A chunk has finished with its window: after a window was let go, the next chunks to finish (by then no
        chunk casts into it, and its arrays are freed) give the free heap back to the system."""
        with self._lock:
            due, self._trims_due = self._trims_due, max(0, self._trims_due - 1)
        if due:
            release_free_heap()

    def _kept(self, need) -> CastScene | None:
        """A kept window holding the cells ``need`` (j0, j1, i0, i1), the most recent first; None if none does."""
        with self._lock:
            for key, target in reversed(self._windows.items()):
                if key[0] <= need[0] and need[1] <= key[1] and key[2] <= need[2] and need[3] <= key[3]:
                    self._windows.move_to_end(key)
                    return target
        return None

    def _cells(self, box, pad_tiles: int) -> tuple[int, int, int, int]:
        """(j0, j1, i0, i1): cell columns and rows of the site covering ``box`` local [m] (plus one cell), snapped
        out to whole tiles and ``pad_tiles`` more (never past the site)."""
        hf, t = self.scene.heightfield, self.scene.tile_cells
        ny, nx = hf.shape
        x0, y0 = hf.x0_m - self.scene.local_origin[0], hf.y0_m - self.scene.local_origin[1]
        s = hf.spacing_m
        box = np.clip(box, [x0, x0, y0, y0], [x0 + (nx - 1) * s] * 2 + [y0 + (ny - 1) * s] * 2)  # nothing beyond
        j0 = (math.floor((box[0] - x0) / s) - 1) // t - pad_tiles
        j1 = -(-(math.floor((box[1] - x0) / s) + 2) // t) + pad_tiles
        i0 = (math.floor((box[2] - y0) / s) - 1) // t - pad_tiles
        i1 = -(-(math.floor((box[3] - y0) / s) + 2) // t) + pad_tiles
        return (max(0, j0 * t), min(nx - 1, max(1, j1) * t), max(0, i0 * t), min(ny - 1, max(1, i1) * t))

    def holds(self, target: CastScene, boxes: np.ndarray) -> np.ndarray:
        """(n,) bool: which ``boxes`` (n, 4) local [m] lie inside ``target``'s window with a cell to spare, or reach
        past it only where the window's edge is the site's (where the whole scene ends too)."""
        j0, j1, i0, i1 = target.scene.cells
        hf, s = self.scene.heightfield, self.scene.heightfield.spacing_m
        ny, nx = hf.shape
        x0, y0 = hf.x0_m - self.scene.local_origin[0], hf.y0_m - self.scene.local_origin[1]
        return (((boxes[:, 0] >= x0 + (j0 + 1) * s) | (j0 == 0)) & ((boxes[:, 1] <= x0 + (j1 - 1) * s) | (j1 == nx - 1))
                & ((boxes[:, 2] >= y0 + (i0 + 1) * s) | (i0 == 0)) & ((boxes[:, 3] <= y0 + (i1 - 1) * s) | (i1 == ny - 1)))

    def floor_under(self, box) -> float:
        """[m] local: below it, nothing over ``box`` (the lowest seabed node of the tiles under it, or of anything
        else anywhere)."""
        t = self.scene.tile_cells
        j0, j1, i0, i1 = self._cells(box, 0)
        low = self.scene.tile_low[i0 // t:max(i0 // t + 1, -(-i1 // t)), j0 // t:max(j0 // t + 1, -(-j1 // t))]
        parts_low = self.scene.z_low_local if self.scene.parts is not None else np.inf
        return float(min(low.min(), parts_low)) - 1e-3

    def first_hits(self, origins: np.ndarray, directions: np.ndarray):
        """First hit of each ray, as :meth:`scanner_sim.rays.caster.RayCaster.first_hits` gives it over the whole
        scene: (ray_index (k,), tri_index (k,) numbered as in the whole scene, distance (k,) float32). The rays are
        cast in groups of neighbours, each into a window of at most :data:`FIRST_HITS_TILES` tiles that holds their
        reach (or of its single ray's)."""
        origins = np.ascontiguousarray(origins, np.float32)
        directions = np.ascontiguousarray(directions, np.float32)
        boxes = reach_boxes(self, origins.astype(np.float64), directions.astype(np.float64), origins, 0.0, 0.0)
        found = [(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float32))]
        todo = [np.arange(origins.shape[0])]
        while todo:
            rays = todo.pop()
            if not rays.size:
                continue
            box = union(boxes[rays])
            j0, j1, i0, i1 = self._cells(box, 0)
            tiles = ((j1 - j0) / self.scene.tile_cells) * ((i1 - i0) / self.scene.tile_cells)
            if tiles > FIRST_HITS_TILES and rays.size > 1:
                todo += np.array_split(rays, 2)
                continue
            target = self.window_for(box, pad_tiles=0)
            ray, tri, dist = target.caster.first_hits(origins[rays], directions[rays])
            found.append((rays[ray], self.scene.site_faces(target.scene, tri), dist))
        ray, tri, dist = (np.concatenate(column) for column in zip(*found))
        order = np.argsort(ray, kind="stable")
        return ray[order], tri[order], dist[order]


def union(boxes: np.ndarray) -> np.ndarray:
    """The box (4,) holding every box of ``boxes`` (n, 4): (x_min, x_max, y_min, y_max)."""
    return np.array([boxes[:, 0].min(), boxes[:, 1].max(), boxes[:, 2].min(), boxes[:, 3].max()])


def reach_boxes(target: TiledTarget, beam_origin, beam_dir, rx_origin, beam_radius_m: float, tan_half_divergence: float
                ) -> np.ndarray:
    """(n, 4) local [m]: for each pulse, a box holding every point where one of its sub-rays (origins within
    ``beam_radius_m`` of ``beam_origin`` (n, 3) local, directions within the half divergence of ``beam_dir`` (n, 3))
    can meet anything, and its receiver ``rx_origin`` (n, 3) local.

    Below the floor of everything near the chunk (:meth:`TiledTarget.floor_under` of the box the whole site's floor
    gives) a ray meets nothing, so a sub-ray descending at up to angle a off the vertical meets anything within
    r + (z - floor) tan a of the beam's origin horizontally; a sub-ray that can run level or climb can reach the
    whole site."""
    site = target.scene
    hf = site.heightfield
    x_lo, x_hi, y_lo, y_hi = hf.extent_m
    site_box = np.array([x_lo, x_hi, y_lo, y_hi]) - site.local_origin[[0, 0, 1, 1]]
    if site.parts is not None:
        v = site.parts.vertices - site.local_origin
        site_box = np.array([min(site_box[0], v[:, 0].min()), max(site_box[1], v[:, 0].max()),
                             min(site_box[2], v[:, 1].min()), max(site_box[3], v[:, 1].max())])
    off_vertical = np.arccos(np.clip(-beam_dir[:, 2], -1.0, 1.0)) + math.atan(tan_half_divergence)
    floor = site.z_low_local - 1e-3
    for _ in range(2):  # the whole site's floor, then the floor under the box that one gives
        drop = np.maximum(beam_origin[:, 2] - floor, 0.0) + beam_radius_m
        reach = np.where(off_vertical < math.radians(89.9), beam_radius_m + drop * np.tan(np.minimum(
            off_vertical, math.radians(89.9))), np.inf)
        boxes = np.c_[beam_origin[:, 0] - reach, beam_origin[:, 0] + reach, beam_origin[:, 1] - reach,
                      beam_origin[:, 1] + reach]
        boxes = np.c_[np.minimum(boxes[:, 0], rx_origin[:, 0]), np.maximum(boxes[:, 1], rx_origin[:, 0]),
                      np.minimum(boxes[:, 2], rx_origin[:, 1]), np.maximum(boxes[:, 3], rx_origin[:, 1])]
        boxes = np.c_[np.maximum(boxes[:, 0], site_box[0]), np.minimum(boxes[:, 1], site_box[1]),
                      np.maximum(boxes[:, 2], site_box[2]), np.minimum(boxes[:, 3], site_box[3])]
        boxes[:, 1] = np.maximum(boxes[:, 1], boxes[:, 0])  # a pulse beside the site: an empty box at its edge
        boxes[:, 3] = np.maximum(boxes[:, 3], boxes[:, 2])
        if not boxes.size:
            return boxes
        floor = target.floor_under(union(boxes))
    return boxes


def proof_box(hits: Hits, local_origin, beam_origin, beam_dir, rx_origin, beam_radius_m: float,
              tan_half_divergence: float, floor: float, top: float) -> np.ndarray | None:
    """(4,) local [m]: a box holding the coarse cells the seabed grid's proofs of the chunk's hits can read
    (:func:`scanner_sim.rays.seabed_kernels._bundle_clear`), None without hits. A proof reads around a pulse's first
    hit as far as the farthest other (its footprint), and further by the run of the least steep segment (sub-ray, or
    hit to receiver) from the floor ``floor`` local up to the beam or receiver, or to the top of the whole scene
    ``top`` local if lower. Bounded here over the chunk: the largest footprint and the longest run around every hit.
    A footprint is its hits' box widened by the beam's radius at their range and :data:`FOOTPRINT_SLACK_M` (a pulse
    the ``auto`` level collapsed keeps three of its hits, all within an echo bin of range)."""
    if not hits.pulse_index.size:
        return None
    extent = np.empty(7)
    _proof_extent(hits.pulse_index, hits.point, hits.range_m, beam_origin, beam_dir, rx_origin, local_origin,
                  beam_radius_m, math.atan(tan_half_divergence), floor, top + 2e-3, extent)
    x_min, x_max, y_min, y_max, footprint, run, range_max = extent
    spread = beam_radius_m + range_max * tan_half_divergence + FOOTPRINT_SLACK_M
    grow = spread + 1.5 * (footprint + 2.0 * spread) + run  # the farthest hit from the first: under sqrt(2) sides
    return np.array([x_min - grow, x_max + grow, y_min - grow, y_max + grow])


@kernel(nogil=True, error_model="numpy")
def _proof_extent(pulse, point, range_m, beam_origin, beam_dir, rx, local_origin, beam_radius, half_divergence,
                  floor, top, out):
    """For :func:`proof_box`, over hit rows in scan order (``pulse`` (r,), ``point`` (r, 3) world, ``range_m`` (r,);
    per pulse (n, 3) local: ``beam_origin``, ``beam_dir``, receiver ``rx``): out = (x_min, x_max, y_min, y_max) local of
    the hits, the widest side of a pulse's hits' box, the longest run of a pulse's least steep segment (module doc of
    :func:`proof_box`; inf where one runs level), the longest range."""
    x_min, x_max, y_min, y_max, footprint, run, range_max = np.inf, -np.inf, np.inf, -np.inf, 0.0, 0.0, 0.0
    c = 0
    while c < pulse.shape[0]:
        p = pulse[c]
        off_vertical = math.acos(min(1.0, max(-1.0, -beam_dir[p, 2]))) + half_divergence
        slope = 1.0 / math.tan(off_vertical) if off_vertical < math.radians(89.9) else 0.0
        high = max(0.0, min(max(beam_origin[p, 2], rx[p, 2]) + beam_radius, top) - floor)
        px0, px1, py0, py1 = np.inf, -np.inf, np.inf, -np.inf
        while c < pulse.shape[0] and pulse[c] == p:
            x, y = point[c, 0] - local_origin[0], point[c, 1] - local_origin[1]
            px0, px1, py0, py1 = min(px0, x), max(px1, x), min(py0, y), max(py1, y)
            range_max = max(range_max, range_m[c])
            up = rx[p, 2] - (point[c, 2] - local_origin[2])
            if up > 0.0:  # a segment to the receiver that does not rise fails the proof anyway
                across = math.sqrt((rx[p, 0] - x) ** 2 + (rx[p, 1] - y) ** 2)
                if across > 0.0:
                    slope = min(slope, up / across)
            c += 1
        x_min, x_max, y_min, y_max = min(x_min, px0), max(x_max, px1), min(y_min, py0), max(y_max, py1)
        footprint = max(footprint, px1 - px0, py1 - py0)
        run = max(run, high / slope if slope > 0.0 else np.inf)
    out[0], out[1], out[2], out[3], out[4], out[5], out[6] = x_min, x_max, y_min, y_max, footprint, run, range_max


@dataclass(frozen=True)
class TiledCast(BeamCast):
    """A level's ray stage over a site (``target``: a :class:`TiledTarget`): each chunk cast into a window holding
    its reach (:func:`reach_boxes`) and its proofs (:func:`proof_box`), by the level's own cast (``adaptive``:
    :func:`scanner_sim.rays.auto.cast_auto`, else :func:`scanner_sim.rays.cast.cast_beams`)."""

    adaptive: bool = False

    def __call__(self, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir) -> Hits:
        tiled: TiledTarget = self.target
        site = tiled.scene
        o_local, rx_local = beam_origin - site.local_origin, rx_origin - site.local_origin
        r_t = 0.5 * self.geometry.beam_diameter_m
        tan_h = math.tan(0.5 * self.geometry.beam_divergence_full_rad)
        reach = reach_boxes(tiled, o_local, beam_dir, rx_local, r_t, tan_h)
        box = union(reach)
        # What the proofs of the hits will read (proof_box), foreseen: up from the floor to the top of the site at
        # the least steep sub-ray's slope, from the reach of each pulse.
        floor = tiled.floor_under(box)
        steepest = float(np.arccos(np.clip(-beam_dir[:, 2], -1.0, 1.0)).max()) + math.atan(tan_h)
        if steepest < math.radians(89.9):
            run = (site.z_top_local - floor) * math.tan(steepest) + FOOTPRINT_SLACK_M
            box = box + np.array([-run, run, -run, run])
        cast = cast_auto if self.adaptive else cast_beams
        motion = o_local[-1, :2] - o_local[0, :2]  # a new window reaches on along the way the pass goes
        step = motion * (WINDOW_AHEAD_M / max(float(np.hypot(*motion)), 1e-9))
        ahead = union(np.array([box - motion[[0, 0, 1, 1]], box + step[[0, 0, 1, 1]]]))  # and a chunk behind
        while True:
            target = tiled.window_for(box, ahead, pad_tiles=0)
            hits = cast(target, beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir, self.pattern, self.geometry,
                        self.shadow_rays)
            if target.seabed_grid is None:
                tiled.chunk_done()
                return hits
            proofs = proof_box(hits, site.local_origin, o_local, beam_dir, rx_local, r_t, tan_h, floor,
                               site.z_top_local)
            if proofs is None or tiled.holds(target, proofs[None, :])[0]:
                tiled.chunk_done()
                return hits
            box = union(np.array([box, proofs]))
            ahead = union(np.array([ahead, box]))
