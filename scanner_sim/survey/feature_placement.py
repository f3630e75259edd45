"""Where feature cubes go (docs/coverage.md, *Feature detection*): seeded positions inside the swath a pass will
fly, where its beams reach the actual seabed, apart from each other and out of each other's shadow. It casts a
sample of the pass's own beams into the scene, so it needs the pass's set-up.
"""

from __future__ import annotations

import math

import numpy as np

from muls.infra.errors import ParameterError
from scanner_sim.config import SceneConfig
from scanner_sim.metrics.feature_cubes import cube_name
from scanner_sim.metrics.planned_swath import planned_swath

#: Gap kept between two cubes' bounding circles [m].
CUBE_GAP_M = 0.25  # assumption: cubes apart (docs/assumptions.md)
#: Beam axes sampled, evenly over the pass, to map where the scan reaches the seabed before placing cubes.
REACH_BEAMS = 50_000
#: Plan cell of that map [m]: half the smallest feature S-44 names (Exclusive's 0.5 m cube).
REACH_CELL_M = 0.25
#: Share of the sampled beams through a cube's box that must not enter another placed cube first: a cube stands
#: mostly in view, not in another's shadow.
IN_VIEW = 0.5  # assumption: half its beams in view (docs/assumptions.md)


def cube_positions(config: SceneConfig, sizes_m, count: int, seed: int, max_pulses: int | None = None,
                   count_key: str = "count") -> list[dict]:
    """Seeded random placements (name, size_m, x_m, y_m, heading_deg) of ``count`` cubes of each size [m] inside the
    swath a pass of ``config`` flies (its first ``max_pulses``), whole inside it, where the scan's beams reach the
    actual seabed (:class:`SeabedReach`), apart from each other and out of each other's shadow; ``count_key``: the
    option's name in messages."""
    import shapely

    sizes = sorted(float(s) for s in sizes_m)
    if not sizes or len(set(sizes)) != len(sizes) or any(not (math.isfinite(s) and s > 0) for s in sizes):
        raise ParameterError(f"cubes_m = {list(sizes_m)}: give distinct finite sizes > 0 [m]")
    if not (isinstance(count, int) and count >= 1):
        raise ParameterError(f"{count_key} = {count!r}: must be an integer >= 1")
    reach = SeabedReach.of(config, max_pulses)
    rate = reach.setup.scanner.pulse_rate_hz
    swath = planned_swath(config, reach.setup.trajectory, rate)
    if swath is None:
        raise ParameterError(f"scene '{config.name}': its plan has no swath to place cubes across (a moving platform "
                             "with cross-track scan lines is needed); use --scene-objects to count its own objects")
    start = config.survey.start_s
    stop = start + (max_pulses / rate if max_pulses else reach.setup.trajectory.duration_s)
    x0, x1, y0, y1 = reach.heightfield.extent_m
    area = swath.polygon(start, stop).intersection(shapely.box(x0, y0, x1, y1))
    rng = np.random.default_rng(seed)
    placed: list[dict] = []
    boxes: list[CubeBeams] = []  # per placed cube, the sampled beams through its box
    for size in reversed(sizes):  # the largest first, while there is room
        radius = size / math.sqrt(2.0)
        inner = area.buffer(-radius)
        reached = reach.reached_within(radius)
        if inner.is_empty or not reached.any():
            raise ParameterError(f"cubes_m: a {size:g} m cube does not fit inside the swath flown where the scan "
                                 f"reaches the seabed ({area.area:.1f} m² planned); give smaller cubes or a longer pass")
        bx0, by0, bx1, by1 = inner.bounds
        for k in range(count):
            for _ in range(2000):
                x, y = rng.uniform(bx0, bx1), rng.uniform(by0, by1)
                if not (shapely.contains_xy(inner, x, y) and reach.at(reached, x, y)) or any(
                        math.hypot(x - p["x_m"], y - p["y_m"]) <= radius + p["size_m"] / math.sqrt(2.0) + CUBE_GAP_M
                        for p in placed):
                    continue
                candidate = reach.beams_through(x, y, radius, size)
                if candidate.stays_in_view(boxes):  # neither it nor an earlier cube mostly in the other's shadow
                    break
            else:
                raise ParameterError(f"{count_key} = {count}: {count} cubes of each size do not fit apart inside the swath "
                                     f"flown where the scan reaches the seabed ({area.area:.1f} m² planned); give fewer "
                                     "or a longer pass")
            candidate.hide(boxes)
            boxes.append(candidate)
            placed.append({"name": cube_name(size, k), "size_m": size, "x_m": float(x), "y_m": float(y),
                           "heading_deg": float(rng.uniform(0.0, 90.0))})
    return placed


class SeabedReach:
    """Where a pass's beams reach the actual seabed, from an even sample of at most :data:`REACH_BEAMS` of its beam
    axes cast into the scene as it stands: plan cells of :data:`REACH_CELL_M` whose seabed a sampled axis meets
    first (not an object, not beyond a rise), and each sampled beam's segment from the lidar to its first hit."""

    def __init__(self, setup, origin: np.ndarray, direction: np.ndarray, footprint):
        from scipy import ndimage

        from scanner_sim.metrics.coverage import PlanGrid

        self.setup, self.heightfield = setup, setup.scene.heightfield
        x0, x1, y0, y1 = self.heightfield.extent_m
        self.grid = PlanGrid.over((x0, x1), (y0, y1), REACH_CELL_M)
        seabed = np.array([o.kind == "seabed" for o in setup.scene.objects])
        on_seabed = (footprint.object_id >= 0) & seabed[np.maximum(footprint.object_id, 0)]
        cells = np.zeros(self.grid.size, bool)
        cell = self.grid.index(footprint.xyz[on_seabed])
        cells[cell[cell >= 0]] = True
        # a sample leaves a few cells between its beams empty: closed by one cell
        self.reached = ndimage.binary_closing(cells.reshape(self.grid.shape), np.ones((3, 3), bool))
        self.origin, self.direction = origin, direction
        self.length = np.linalg.norm(footprint.xyz - origin, axis=1)  # NaN: no hit, the beam runs on
        self.length[~np.isfinite(self.length)] = np.inf

    @classmethod
    def of(cls, config: SceneConfig, max_pulses: int | None) -> SeabedReach:
        """The reach of a pass of ``config`` (its first ``max_pulses``)."""
        from scanner_sim.metrics.coverage import Footprint, nominal_footprint
        from scanner_sim.survey.setup import PassOptions, PassSetup

        setup = PassSetup.build(config, PassOptions(max_pulses=max_pulses, progress=False, render=False))
        stride = max(1, math.ceil(setup.expected_pulses() / REACH_BEAMS))
        origins, directions, parts, seen = [], [], [], 0
        rate = setup.scanner.pulse_rate_hz
        for slots in setup.slot_chunks():
            pick = slots[(seen + np.arange(slots.size)) % stride == 0]
            seen += slots.size
            if not pick.size:
                continue
            beam_o, beam_d, shaft, rx_o, rx_d = setup.scanner.world_rays(setup.trajectory.poses(pick / rate))
            parts.append(nominal_footprint(setup.rays(beam_o, beam_d, shaft, rx_o, rx_d), beam_d))
            origins.append(beam_o)
            directions.append(beam_d)
        footprint = Footprint(np.concatenate([f.xyz for f in parts]), np.concatenate([f.object_id for f in parts]))
        return cls(setup, np.concatenate(origins), np.concatenate(directions), footprint)

    def reached_within(self, radius_m: float) -> np.ndarray:
        """(ny, nx) bool: cells whose every cell within ``radius_m`` [m] the beams reach."""
        from scipy import ndimage

        r = math.ceil(radius_m / REACH_CELL_M)
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        return ndimage.binary_erosion(self.reached, (xx ** 2 + yy ** 2) <= r * r, border_value=0)

    def at(self, cells: np.ndarray, x: float, y: float) -> bool:
        flat = int(self.grid.index(np.array([[x, y]]))[0])
        return flat >= 0 and bool(cells.ravel()[flat])

    def beams_through(self, x: float, y: float, radius_m: float, size_m: float) -> CubeBeams:
        """The sampled beams whose segment up to their first hit passes through the box of a cube of ``size_m`` [m]
        standing at (x, y) (its plan circle of ``radius_m``, from the seabed's lowest point under it to its highest
        plus the size), and how far along each they enter it."""
        ring = np.array([[x, y], [x - radius_m, y], [x + radius_m, y], [x, y - radius_m], [x, y + radius_m]])
        z = self.heightfield.height(ring[:, 0], ring[:, 1])
        lo = np.array([x - radius_m, y - radius_m, z.min()])
        hi = np.array([x + radius_m, y + radius_m, z.max() + size_m])
        with np.errstate(divide="ignore", invalid="ignore"):
            inverse = 1.0 / self.direction
            t0, t1 = (lo - self.origin) * inverse, (hi - self.origin) * inverse
            enter = np.nanmax(np.minimum(t0, t1), axis=1)
            leave = np.nanmin(np.maximum(t0, t1), axis=1)
        through = (leave >= np.maximum(enter, 0.0)) & (enter <= self.length)
        return CubeBeams(np.nonzero(through)[0], enter[through])


class CubeBeams:
    """The sampled beams through one cube's box: their indices (k,) and where along each it is entered [m] (k,),
    and how many of them an other cube, entered first, hides."""

    def __init__(self, beams: np.ndarray, enter_m: np.ndarray):
        self.beams, self.enter_m, self.hidden = beams, enter_m, np.zeros(beams.size, bool)

    def _shared(self, other: CubeBeams) -> tuple[np.ndarray, np.ndarray]:
        """Positions in self and in other of the beams through both boxes."""
        _, mine, theirs = np.intersect1d(self.beams, other.beams, assume_unique=True, return_indices=True)
        return mine, theirs

    def _in_view(self, hidden: np.ndarray) -> bool:
        return self.beams.size > 0 and np.count_nonzero(~hidden) >= IN_VIEW * self.beams.size

    def stays_in_view(self, placed: list[CubeBeams]) -> bool:
        """Whether this cube, added to ``placed``, keeps itself and each of them in view: at least :data:`IN_VIEW` of
        each one's beams not entering another cube first."""
        hidden = np.zeros(self.beams.size, bool)
        for other in placed:
            mine, theirs = self._shared(other)
            hidden[mine[other.enter_m[theirs] < self.enter_m[mine]]] = True
            hides = other.hidden.copy()
            hides[theirs[self.enter_m[mine] < other.enter_m[theirs]]] = True
            if not other._in_view(hides):
                return False
        return self._in_view(hidden)

    def hide(self, placed: list[CubeBeams]) -> None:
        """Mark, in this cube and in ``placed``, the beams that enter another of them first."""
        for other in placed:
            mine, theirs = self._shared(other)
            first = other.enter_m[theirs] < self.enter_m[mine]
            self.hidden[mine[first]] = True
            other.hidden[theirs[~first]] = True
