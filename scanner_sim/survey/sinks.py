"""Where a pass's chunks go, and the files written once it is done. Each sink receives what it writes and
nothing else: no sink reads the pass's set-up or calls back into the pipeline.

Chunk sinks have ``add(chunk)`` (a :class:`scanner_sim.survey.setup.Chunk`): :class:`LasSink`, :class:`LegLasSink`,
:class:`DropoutSink` and :class:`RosbagSink` (a ROS 2 bag, line by line) stream to disk (atomically: a file appears
under its final name only when complete),
:class:`PassStats` keeps the summary's running figures, :class:`CoverageSink` tallies coverage,
:class:`WaveformSink` keeps the whole records of the pulses the pass keeps. After the chunks, :func:`pass_summary`
assembles the summary from :class:`PassFacts`, and the writers below put the rest in files. The pictures, and the
decimated copy of the points one of them shows, are :mod:`scanner_sim.survey.pictures`'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from muls.infra.runtime import kernel
from muls.ranging.returns import DROPOUT_CAUSES
from scanner_sim import io
from scanner_sim.io.copc import CopcWriter
from scanner_sim.io.rosbag import RosbagWriter
from scanner_sim.metrics.coverage import CoverageAccumulator
from scanner_sim.records.point_records import DropoutRecords, PointRecords
from scanner_sim.survey.provenance import point_cloud_provenance
from scanner_sim.version import __version__

NO_HIT = DROPOUT_CAUSES.index("no_hit")

#: Resolution and extent of the streaming |range error| histogram behind the summary's quantiles [m].
ERROR_BIN_M = 5e-4
ERROR_MAX_M = 20.0


@dataclass(frozen=True)
class PassFacts:
    """What made a pass, as its summary and its files' metadata state it: scene name, water, seed, fidelity level
    and its settings, instrument and channel names, chunk size and pulse limit, the scene file, the altitude
    (None when the platform holds a depth), the provenance block (:func:`scanner_sim.survey.provenance.pass_provenance`),
    and the far channel's gate [ns] as the pass used it (None: no gated channel)."""

    scene: str
    water: str
    seed: int
    fidelity: str
    instrument: str
    channels: tuple[str, ...]
    record_mode: str
    subrays: int
    shadow_rays: bool
    attenuation_model: str
    multiple_scattering: str
    chunk_pulses: int
    max_pulses: int | None
    scene_file: str | None
    altitude_m: float | None
    provenance: dict
    gate_delay_ns: float | None = None
    gate_width_ns: float | None = None
    crs: str | None = None  # the scene's CRS by its code ('EPSG:32631'), None for a local frame
    seabed: dict | None = None  # a raster's or a mesh's seabed: source, CRS, sign, datum, synthetic relief

    def metadata(self) -> dict:
        """For the LAS metadata VLR: scene, water, instrument, fidelity, seed, package version, scene file, and the
        pass's provenance as point clouds carry it (:func:`~scanner_sim.survey.provenance.point_cloud_provenance`)."""
        return {"scene": self.scene, "water": self.water, "instrument": self.instrument, "fidelity": self.fidelity,
                "seed": self.seed, "muls_scanner_version": __version__, "scene_file": self.scene_file,
                "provenance": point_cloud_provenance(self.provenance),
                **({"seabed": self.seabed} if self.seabed is not None else {})}

    @property
    def label(self) -> str:
        """'scene, water, instrument[, altitude]' for picture titles."""
        return (f"{self.scene}, {self.water}, {self.instrument}"
                + (f", {self.altitude_m:g} m altitude" if self.altitude_m is not None else ""))


class LasSink(io.LasWriter):
    """points.las or points.laz (by the suffix), streamed chunk by chunk."""

    def __init__(self, path: Path, local_origin: np.ndarray, metadata: dict | None = None, file_source_id: int = 0,
                 crs_wkt: str | None = None):
        super().__init__(path, offset_m=local_origin, metadata=metadata, file_source_id=file_source_id,
                         crs_wkt=crs_wkt)

    def add(self, chunk) -> None:
        self.write(chunk.points)


class CopcSink(CopcWriter):
    """points.copc.laz: the pass's points spilled chunk by chunk, organised into a COPC octree at the end."""

    def __init__(self, path: Path, local_origin: np.ndarray, metadata: dict | None = None, crs_wkt: str | None = None):
        super().__init__(path, offset_m=local_origin, metadata=metadata, crs_wkt=crs_wkt)

    def add(self, chunk) -> None:
        self.write(chunk.points)


class LegLasSink:
    """One LAS/LAZ file per survey leg (``leg007_points.laz``...), like a HELIOS++ leg, each opened when its
    leg's first point arrives and carrying the leg as its file source id."""

    def __init__(self, out: Path, suffix: str, local_origin: np.ndarray, metadata: dict | None = None,
                 crs_wkt: str | None = None):
        self.out, self.suffix, self.local_origin, self.metadata = out, suffix, local_origin, metadata
        self.crs_wkt = crs_wkt
        self.writers: dict[int, LasSink] = {}

    def path(self, leg: int) -> Path:
        return self.out / f"leg{leg:03d}_points{self.suffix}"

    def add(self, chunk) -> None:
        points = chunk.points
        for leg in np.unique(points.leg):
            if leg not in self.writers:
                self.writers[leg] = LasSink(self.path(int(leg)), self.local_origin, self.metadata, int(leg),
                                            self.crs_wkt)
                self.writers[leg].open()
            self.writers[leg].write(points.select(points.leg == leg))

    @property
    def point_count(self) -> int:
        return sum(w.point_count for w in self.writers.values())

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        for writer in self.writers.values():
            writer.__exit__(exc_type, exc, tb)


def point_cloud_sinks(output, out: Path, local_origin: np.ndarray, metadata: dict, crs=None) -> list:
    """The point-cloud writers a scene's ``output`` section asks for: points.las and/or points.laz, or one file per
    leg of each, and points.copc.laz (always the whole pass), every one carrying ``metadata`` and placing points off
    ``local_origin`` (3,) [m], in the map coordinates of ``crs`` (a :class:`pyproj.CRS`, its WKT in the LAS CRS
    record) or, with None, the local frame."""
    suffixes = [s for s, on in ((".las", output.las), (".laz", output.laz)) if on]
    wkt = None if crs is None else crs.to_wkt("WKT1_GDAL")  # LAS 1.4 R15: OGC WKT 1 (01-009)
    copc = [CopcSink(out / "points.copc.laz", local_origin, metadata, crs_wkt=wkt)] if output.copc else []
    if output.split_legs:
        return [LegLasSink(out, s, local_origin, metadata, wkt) for s in suffixes] + copc
    return [LasSink(out / f"points{s}", local_origin, metadata, crs_wkt=wkt) for s in suffixes] + copc


#: Rate of the bag's odometry and transforms [Hz] (the trajectory table's).
ODOMETRY_RATE_HZ = 10.0


class RosbagSink(RosbagWriter):
    """The pass as a ROS 2 bag (:class:`~scanner_sim.io.rosbag.RosbagWriter`): each scan line's points as one
    message once the chunks have passed the line's end, and the navigation's and the true poses on a
    :data:`ODOMETRY_RATE_HZ` grid from the first pulse up to the tick after the last.

    line_of: times (n,) [s] -> scan line (n,) int; poses_at: times (n,) [s] -> (true, estimated)
    :class:`~scanner_sim.motion.trajectory.Poses`, on the track from ``track_s`` (start, end) [s]; pulse_rate_hz:
    slot k fires at k / pulse_rate_hz."""

    #: Fed on the thread that opened it (:class:`~scanner_sim.survey.fan_out.SinkThreads`): a bag's sqlite3 storage
    #: serves only the thread that made its connection.
    thread_bound = True

    def __init__(self, path: Path, settings, local_origin: np.ndarray, line_of, poses_at, track_s: tuple,
                 pulse_rate_hz: float, lidar_offset_m, metadata: dict | None = None):
        super().__init__(path, frame=settings.frame, storage=settings.storage, offset_m=local_origin,
                         lidar_offset_m=lidar_offset_m, metadata=metadata)
        self.line_of, self.poses_at, self.track_s, self.pulse_rate_hz = line_of, poses_at, track_s, pulse_rate_hz
        self._pending = PointRecords.empty()
        self._next_tick: int | None = None
        self._last_s: float | None = None

    def add(self, chunk) -> None:
        times = chunk.slots / self.pulse_rate_hz
        if times.size == 0:
            return
        points = PointRecords.concatenate([self._pending, chunk.points])
        done = self.line_of(points.gps_time_s) < self.line_of(times[-1:])[0]  # later pulses start a later line
        self._write_lines(points.select(done))
        self._pending = points.select(~done)
        if self._next_tick is None:
            self._next_tick = int(np.floor(times[0] * ODOMETRY_RATE_HZ))
        self._last_s = float(times[-1])
        self._write_ticks(int(np.floor(times[-1] * ODOMETRY_RATE_HZ)))

    def _write_lines(self, points: PointRecords) -> None:
        lines = self.line_of(points.gps_time_s)
        for line in np.unique(lines):
            self.write_line(points.select(lines == line), int(line))

    def _write_ticks(self, last_tick: int) -> None:
        """Poses at ticks ``_next_tick`` .. ``last_tick``; the twist from the poses half a tick either side (one side
        at the track's ends, where the vehicle stands still)."""
        ticks = np.arange(self._next_tick, last_tick + 1)
        if ticks.size == 0:
            return
        t, h = ticks / ODOMETRY_RATE_HZ, 0.5 / ODOMETRY_RATE_HZ
        t0, t1 = np.clip(t - h, *self.track_s), np.clip(t + h, *self.track_s)
        dt = np.where(t1 > t0, t1 - t0, np.inf)[:, None]  # no time on the track: no motion
        for truth, (now, before, after) in zip((True, False), zip(self.poses_at(t), self.poses_at(t0),
                                                                   self.poses_at(t1))):
            velocity = (after.position - before.position) / dt
            # R^T dR/dt is the skew matrix of the angular rate in the vehicle frame
            spin = np.einsum("nji,njk->nik", now.rotation, (after.rotation - before.rotation) / dt[:, :, None])
            angular = 0.5 * np.c_[spin[:, 2, 1] - spin[:, 1, 2], spin[:, 0, 2] - spin[:, 2, 0],
                                  spin[:, 1, 0] - spin[:, 0, 1]]
            self.write_poses(t, now.position, now.rotation, velocity, angular, truth)
        self._next_tick = last_tick + 1

    def close(self) -> None:
        if self._last_s is not None:
            self._write_lines(self._pending)
            self._write_ticks(int(np.ceil(self._last_s * ODOMETRY_RATE_HZ)))
        super().close()


class DropoutSink(io.DropoutWriter):
    """dropouts.npz, streamed chunk by chunk."""

    def add(self, chunk) -> None:
        self.write(chunk.dropouts)


class MemorySink:
    """Keeps every chunk's points and dropouts in memory (the Python API's pass without files)."""

    def __init__(self):
        self._points, self._dropouts = [], []

    def add(self, chunk) -> None:
        self._points.append(chunk.points)
        self._dropouts.append(chunk.dropouts)

    def points(self) -> PointRecords:
        return PointRecords.concatenate(self._points)

    def dropouts(self) -> DropoutRecords:
        return DropoutRecords.concatenate(self._dropouts)


class CoverageSink(CoverageAccumulator):
    """Coverage tallied chunk by chunk; :meth:`write` saves coverage_grid.npz and returns the figures."""

    def add(self, chunk) -> None:
        super().add(chunk.slots, chunk.footprint, chunk.points, chunk.dropouts)

    def write(self, path: Path) -> dict:
        io.write_coverage_grid_npz(path, self.grid, self.cell_states(), self.cells.reaching, self.cells.valid,
                                   s44_order=self.strictest_orders(), planned=self.planned_cells())
        return self.figures()


class PassStats:
    """Pulses, points per channel and streaming histograms of the range error [m]: of |error| (median and 95th
    percentile) and of the signed error (its median, the bias, and the share of points ranged short)."""

    def __init__(self, n_channels: int, heightfield=None):
        """heightfield: the scene's seabed (:class:`scanner_sim.world.terrain.HeightField`), to count the ``no_hit``
        dropouts aimed where it holds no seabed (a raster's nodata, or beyond its edge); None: not counted."""
        self.heightfield = heightfield
        self.no_hit_over_no_seabed = 0
        self.pulses = 0
        self.points = 0
        self.channels = np.zeros(n_channels + 1, np.int64)
        self.error_counts = np.zeros(int(ERROR_MAX_M / ERROR_BIN_M) + 1, np.int64)
        self.signed_counts = np.zeros(2 * self.error_counts.size, np.int64)  # bins of ERROR_BIN_M from -ERROR_MAX_M
        self.short = 0

    def add(self, chunk) -> None:
        self.pulses += chunk.slots.size
        self.points += len(chunk.points)
        self.channels += np.bincount(chunk.points.channel, minlength=self.channels.size)
        signed = chunk.points.range_error_m[np.isfinite(chunk.points.range_error_m)].astype(np.float64)
        e = np.abs(signed)
        size = self.error_counts.size
        self.error_counts += np.bincount(np.minimum((e / ERROR_BIN_M).astype(np.int64), size - 1), minlength=size)
        k = np.clip(np.floor(signed / ERROR_BIN_M).astype(np.int64) + size, 0, self.signed_counts.size - 1)
        self.signed_counts += np.bincount(k, minlength=self.signed_counts.size)
        self.short += int((signed < 0).sum())
        if self.heightfield is not None:
            self.no_hit_over_no_seabed += self._aimed_at_no_seabed(chunk.dropouts)

    def _aimed_at_no_seabed(self, dropouts) -> int:
        """``no_hit`` dropouts whose beam, followed down in steps of the seabed's node spacing (to its lowest height,
        at most across its whole plan), first crosses the seabed's level where the seabed has no data (a gap, within
        a node of one, or beyond the edge): the beams a raster's nodata leaves with nothing to meet."""
        hf = self.heightfield
        no_hit = np.asarray(dropouts.cause) == NO_HIT
        origin, direction = np.asarray(dropouts.origin)[no_hit], np.asarray(dropouts.direction)[no_hit]
        down = direction[:, 2] < 0
        origin, direction = origin[down], direction[down]
        if not origin.shape[0]:
            return 0
        x0, x1, y0, y1 = hf.extent_m
        reach = min(float(np.max((hf.lowest_m - origin[:, 2]) / direction[:, 2])), math.hypot(x1 - x0, y1 - y0))
        t = np.arange(0.0, reach + hf.spacing_m, hf.spacing_m)  # (steps,) [m] along each beam
        return _count_over_no_data(origin, direction, t, hf.x0_m, hf.y0_m, hf.spacing_m, hf.heights_m, hf.inner_cells)

    def error_quantile_m(self, q: float) -> float | None:
        total = self.error_counts.sum()
        if total == 0:
            return None
        k = int(np.searchsorted(np.cumsum(self.error_counts), q * total))
        return round((k + 0.5) * ERROR_BIN_M, 7)  # the bin's centre, without float noise in summary.json

    def signed_median_m(self) -> float | None:
        """Median signed range error [m] (negative: ranged short), to the histogram's bin."""
        total = self.signed_counts.sum()
        if total == 0:
            return None
        k = int(np.searchsorted(np.cumsum(self.signed_counts), 0.5 * total))
        return round((k - self.error_counts.size + 0.5) * ERROR_BIN_M, 7)

    def share_short(self) -> float | None:
        """Share of the points with a truth whose range error is negative (ranged short)."""
        total = self.error_counts.sum()
        return round(float(self.short / total), 6) if total else None


class WaveformSink:
    """waveforms.npz: the whole records of the pulses a pass keeps (``Chunk.kept_waveforms``), gathered in slot
    order and written by :meth:`write`. digitizer: the instrument's (sample times); channel_names: its signal
    channels, in record order."""

    def __init__(self, digitizer, channel_names):
        self.digitizer, self.channel_names = digitizer, tuple(channel_names)
        self._slots, self._time_ns, self._reference, self._codes = [], [], [], []

    def add(self, chunk) -> None:
        if chunk.kept_waveforms is None:
            return
        slots, records = chunk.kept_waveforms
        dig = self.digitizer
        k = np.arange(records.reference.shape[1])[None, :]  # full records: the reference spans the record
        self._slots.append(slots)
        self._time_ns.append((-dig.pretrigger_s + k * dig.sample_interval_s + records.phase_s[:, None]) * 1e9)
        self._reference.append(records.reference)
        self._codes.append(records.codes)

    def write(self, path: Path) -> None:
        codes = np.concatenate(self._codes)
        channels = {"ch0": np.concatenate(self._reference)}
        channels.update({name: codes[:, i, :] for i, name in enumerate(self.channel_names)})
        io.write_waveforms_npz(path, np.concatenate(self._slots), np.concatenate(self._time_ns), channels)


@kernel(nogil=True)
def _count_over_no_data(origin, direction, t, x0, y0, spacing, heights, inner):
    """How many beams (``origin``, ``direction`` (n, 3) [m], descending) first reach the seabed's level, stepping
    ``t`` (steps,) [m] along each, where the seabed holds no data: beyond the height field, or in a cell that has
    no data or a neighbour without (``inner`` (ny - 1, nx - 1) bool: the mesh's edge along a gap is ragged within a
    node of it); a beam that never reaches it counts too. The level at a step is the ``heights`` of its cell's
    lower-left node (the node spacing's precision is enough to tell where a beam crosses it; a gap's heights are
    its nearest data's, a surface without holes)."""
    ny, nx = inner.shape
    count = 0
    for b in range(origin.shape[0]):
        counted = True  # until the beam reaches the level over data
        for s in range(t.shape[0]):
            x = origin[b, 0] + t[s] * direction[b, 0]
            y = origin[b, 1] + t[s] * direction[b, 1]
            z = origin[b, 2] + t[s] * direction[b, 2]
            i, j = math.floor((y - y0) / spacing), math.floor((x - x0) / spacing)
            ok = 0 <= i < ny and 0 <= j < nx
            i, j = min(max(i, 0), ny - 1), min(max(j, 0), nx - 1)
            if z <= heights[i, j]:
                counted = not (ok and inner[i, j])
                break
        count += counted
    return count


def pass_summary(facts: PassFacts, stats: PassStats, n_points: int, dropout_counts: dict, wall_s: float,
                 setup_s: float, compile_s: float = 0.0) -> dict:
    """The summary of a pass: counts, speed, range error quantiles and the settings that made it. ``wall_s`` [s]
    times the chunk loop, so ``pulses_per_s`` leaves out ``setup_s`` and ``compile_s`` (compiling the kernels, or
    loading them from the cache, before the loop)."""
    return {
        "scene": facts.scene,
        "water": facts.water,
        "seed": facts.seed,
        "fidelity": facts.fidelity,
        "pulses": stats.pulses,
        "points": n_points,
        "dropouts": {cause: int(dropout_counts.get(cause, 0)) for cause in DROPOUT_CAUSES},
        "no_hit_over_no_seabed": stats.no_hit_over_no_seabed if stats.heightfield is not None else None,
        "channels": {name: int(stats.channels[i + 1]) for i, name in enumerate(facts.channels)},
        "wall_s": round(wall_s, 3),
        "setup_s": round(setup_s, 3),
        "compile_s": round(compile_s, 3),
        "pulses_per_s": round(stats.pulses / wall_s, 1) if wall_s > 0 else None,
        "range_error_m": {"median": stats.error_quantile_m(0.5), "p95": stats.error_quantile_m(0.95),
                          "median_signed": stats.signed_median_m(), "share_short": stats.share_short()},
        "settings": {
            "instrument": facts.instrument,
            "record_mode": facts.record_mode,
            "subrays": facts.subrays,
            "shadow_rays": facts.shadow_rays,
            "attenuation_model": facts.attenuation_model,
            "multiple_scattering": facts.multiple_scattering,
            "chunk_pulses": facts.chunk_pulses,
            "max_pulses": facts.max_pulses,
            "scene_file": facts.scene_file,
            "gate_delay_ns": facts.gate_delay_ns,
            "gate_width_ns": facts.gate_width_ns,
            "crs": facts.crs,
        },
        "provenance": facts.provenance,
        **({"seabed": facts.seabed} if facts.seabed is not None else {}),
    }


def write_trajectory(out: Path, table: dict[str, np.ndarray], split_legs: bool) -> None:
    """trajectory.csv, or one ``legNNN_trajectory.csv`` per leg, from a trajectory table
    (:meth:`scanner_sim.motion.trajectory.Trajectory.table`)."""
    legs = np.unique(table["leg"]) if split_legs else [None]
    for leg in legs:
        rows = slice(None) if leg is None else table["leg"] == leg
        name = "trajectory.csv" if leg is None else f"leg{leg:03d}_trajectory.csv"
        io.write_trajectory_csv(out / name, table["time_s"][rows], table["position_m"][rows],
                                table["attitude_deg"][rows], estimated_position_m=table["est_position_m"][rows],
                                estimated_attitude=table["est_attitude_deg"][rows])
