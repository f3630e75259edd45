"""Where a pass's chunks go, and the files written once it is done.

Each chunk sink has ``add(chunk)``: :class:`LasSink` and :class:`DropoutSink` stream to disk (atomically: a
file appears under its final name only when complete), :class:`PassStats` keeps the summary's running
figures, :class:`CoverageSink` tallies coverage. After the chunks, :func:`pass_summary` assembles the summary
and :func:`write_pass_files`, :func:`render_pass` and :func:`render_coverage_map` write the rest.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from muls.ranging import DROPOUT_CAUSES
from scanner_sim import io
from scanner_sim.metrics.coverage import BACKGROUND_KINDS, GAP_CAUSES, CoverageAccumulator
from scanner_sim.render import viz
from scanner_sim.survey.point_records import DropoutRecords, PointRecords
from scanner_sim.version import __version__

#: Resolution and extent of the streaming |range error| histogram behind the summary's quantiles [m].
ERROR_BIN_M = 5e-4
ERROR_MAX_M = 20.0

#: Trajectory output rate [Hz].
TRAJECTORY_RATE_HZ = 10.0


class LasSink(io.LasWriter):
    """points.las or points.laz (by the suffix), streamed chunk by chunk."""

    def __init__(self, path: Path, local_origin: np.ndarray, metadata: dict | None = None, file_source_id: int = 0):
        super().__init__(path, offset_m=local_origin, metadata=metadata, file_source_id=file_source_id)

    def add(self, chunk) -> None:
        self.write(chunk.points)


class LegLasSink:
    """One LAS/LAZ file per survey leg (``leg007_points.laz``...), like a HELIOS++ leg, each opened when its
    leg's first point arrives and carrying the leg as its file source id."""

    def __init__(self, out: Path, suffix: str, local_origin: np.ndarray, metadata: dict | None = None):
        self.out, self.suffix, self.local_origin, self.metadata = out, suffix, local_origin, metadata
        self.writers: dict[int, LasSink] = {}

    def path(self, leg: int) -> Path:
        return self.out / f"leg{leg:03d}_points{self.suffix}"

    def add(self, chunk) -> None:
        points = chunk.points
        for leg in np.unique(points.leg):
            if leg not in self.writers:
                self.writers[leg] = LasSink(self.path(int(leg)), self.local_origin, self.metadata, int(leg))
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
        io.write_coverage_grid_npz(path, self.grid, self.cell_states(), self.cells.reaching, self.cells.valid)
        return self.figures()


class PassStats:
    """Pulses, points per channel and a streaming histogram of |range error| [m] (median and 95th percentile)."""

    def __init__(self, n_channels: int):
        self.pulses = 0
        self.points = 0
        self.channels = np.zeros(n_channels + 1, np.int64)
        self.error_counts = np.zeros(int(ERROR_MAX_M / ERROR_BIN_M) + 1, np.int64)

    def add(self, chunk) -> None:
        self.pulses += chunk.slots.size
        self.points += len(chunk.points)
        self.channels += np.bincount(chunk.points.channel, minlength=self.channels.size)
        e = np.abs(chunk.points.range_error_m)
        e = e[np.isfinite(e)]
        np.add.at(self.error_counts, np.minimum((e / ERROR_BIN_M).astype(np.int64), self.error_counts.size - 1), 1)

    def error_quantile_m(self, q: float) -> float | None:
        total = self.error_counts.sum()
        if total == 0:
            return None
        k = int(np.searchsorted(np.cumsum(self.error_counts), q * total))
        return round((k + 0.5) * ERROR_BIN_M, 7)  # the bin's centre, without float noise in summary.json


def pass_summary(setup, stats: PassStats, n_points: int, dropout_counts: dict, wall_s: float, setup_s: float) -> dict:
    """The summary of a pass: counts, speed, range error quantiles and the settings that made it."""
    config, channels = setup.config, setup.model.instrument.channels
    return {
        "scene": config.name,
        "water": setup.water_name,
        "seed": setup.seed,
        "fidelity": setup.level.name,
        "pulses": stats.pulses,
        "points": n_points,
        "dropouts": {cause: int(dropout_counts.get(cause, 0)) for cause in DROPOUT_CAUSES},
        "channels": {ch.name: int(stats.channels[i + 1]) for i, ch in enumerate(channels)},
        "wall_s": round(wall_s, 3),
        "setup_s": round(setup_s, 3),
        "pulses_per_s": round(stats.pulses / wall_s, 1) if wall_s > 0 else None,
        "range_error_m": {"median": stats.error_quantile_m(0.5), "p95": stats.error_quantile_m(0.95)},
        "settings": {
            "instrument": setup.model.instrument.name,
            "record_mode": setup.level.record_mode,
            "subrays": setup.pattern.count,
            "shadow_rays": setup.level.shadow_rays,
            "chunk_pulses": setup.chunk_slots,
            "max_pulses": setup.max_pulses,
            "scene_file": str(config.source_path) if config.source_path else None,
        },
    }


def pass_metadata(setup) -> dict:
    """What made a pass, for the LAS metadata VLR: scene, water, instrument, fidelity, seed, package version."""
    return {"scene": setup.config.name, "water": setup.water_name, "instrument": setup.model.instrument.name,
            "fidelity": setup.level.name, "seed": setup.seed, "muls_scanner_version": __version__,
            "scene_file": str(setup.config.source_path) if setup.config.source_path else None}


def write_pass_files(setup, out: Path, options) -> None:
    """scene.ply (unless ``options.write_scene`` is False), the trajectory (per the scene's
    ``output.trajectory_csv``, one file per leg under ``output.split_legs``) and waveforms.npz (the
    ``options.waveforms`` pulses spread over the pass and every ``output.waveform_every_n_pulses``-th)."""
    scene, output = setup.scene, setup.config.output
    if options.write_scene:
        io.write_scene_ply(out / "scene.ply", scene.vertices, scene.faces, scene.face_label, scene.face_object)
    if output.trajectory_csv:
        table = trajectory_table(setup)
        legs = np.unique(table["leg"]) if output.split_legs else [None]
        for leg in legs:
            rows = slice(None) if leg is None else table["leg"] == leg
            name = "trajectory.csv" if leg is None else f"leg{leg:03d}_trajectory.csv"
            io.write_trajectory_csv(out / name, table["time_s"][rows], table["position_m"][rows],
                                    table["attitude_deg"][rows], estimated_position_m=table["est_position_m"][rows],
                                    estimated_attitude=table["est_attitude_deg"][rows])
    pick = waveform_slots(setup, options.waveforms, output.waveform_every_n_pulses)
    if pick.size:
        write_waveforms(setup, out / "waveforms.npz", pick)


def trajectory_table(setup, rate_hz: float = TRAJECTORY_RATE_HZ) -> dict[str, np.ndarray]:
    """True and estimated poses over the pass at ``rate_hz``: time_s (n,), position_m (n, 3), attitude_deg
    (n, 3) roll, pitch, yaw, est_position_m, est_attitude_deg, leg (n,)."""
    t0 = setup.first_slot / setup.scanner.pulse_rate_hz
    t1 = setup.end_slot / setup.scanner.pulse_rate_hz
    t = np.arange(t0, t1, 1.0 / rate_hz)
    true = setup.trajectory.poses(t)
    est = setup.trajectory.estimate_of(true)

    def rpy(p):
        return np.degrees(np.c_[p.roll_rad, p.pitch_rad, p.yaw_rad])

    return {"time_s": t, "position_m": true.position, "attitude_deg": rpy(true), "est_position_m": est.position,
            "est_attitude_deg": rpy(est), "leg": setup.trajectory.leg(t)}


def waveform_slots(setup, count: int, every_n: int) -> np.ndarray:
    """Slots of the pulses whose full records to keep: ``count`` spread evenly over the pass, and every
    ``every_n``-th fired pulse (0: none of either)."""
    if not count and not every_n:
        return np.zeros(0, np.int64)
    slots = np.concatenate(list(setup.slot_chunks()))
    picks = [slots[::every_n]] if every_n else []
    if count:
        picks.append(slots[np.unique(np.linspace(0, slots.size - 1, min(count, slots.size)).astype(np.int64))])
    return np.unique(np.concatenate(picks))


def write_waveforms(setup, path: Path, pick: np.ndarray) -> None:
    """Full records of the pulses in slots ``pick`` (same noise as in the pass itself)."""
    records = setup.simulate_chunk(pick, record_mode="full", every_channel=True).records
    time_ns = records.reference_times_s(setup.model) * 1e9  # full mode: the reference spans the record
    channels = {"ch0": records.reference}
    channels.update({ch.name: records.codes[:, i, :] for i, ch in enumerate(setup.model.instrument.channels)})
    io.write_waveforms_npz(path, pick, time_ns, channels)


def render_pass(setup, cloud, out: Path, window_size=(1600, 1000), max_points: int = 1_500_000) -> None:
    """render.png: the point cloud coloured by class over the faded truth mesh (decimated read-back of the
    ``cloud`` sink's file or files)."""
    import laspy

    paths = [w.path for w in cloud.writers.values()] if isinstance(cloud, LegLasSink) else [cloud.path]
    total = 0
    for path in paths:
        with laspy.open(path) as reader:
            total += reader.header.point_count
    stride = max(1, math.ceil(total / max_points))
    xyz, cls = [], []
    for path in paths:
        with laspy.open(path) as reader:
            for part in reader.chunk_iterator(1_000_000):
                xyz.append(np.c_[part.x, part.y, part.z][::stride])
                cls.append(np.asarray(part.classification)[::stride])
    xyz = np.concatenate(xyz) if xyz else np.zeros((0, 3))
    cls = np.concatenate(cls) if cls else np.zeros(0, np.uint8)
    scene = setup.scene
    viz.render_point_cloud(out / "render.png", xyz, cls, truth_vertices=scene.vertices, truth_faces=scene.faces,
                           title=f"{pass_label(setup)}: {xyz.shape[0]:,} points ({setup.level.name})",
                           window_size=window_size)


def pass_label(setup) -> str:
    """'scene, water, instrument[, altitude]' for picture titles."""
    altitude = setup.config.platform.altitude_m
    return (f"{setup.config.name}, {setup.water_name}, {setup.model.instrument.name}"
            + (f", {altitude:g} m altitude" if altitude is not None else ""))


def render_coverage_map(setup, coverage: CoverageAccumulator, path: Path, summary: dict) -> None:
    """coverage_map.png: plan cells covered or missed by cause, cables drawn along, objects marked."""
    scene = setup.scene
    lines = [(o.name, o.centreline[:, :2]) for o in scene.objects if o.centreline is not None]
    markers = []
    for o in scene.objects:
        if o.kind not in BACKGROUND_KINDS and o.centreline is None:
            corners = np.unique(scene.faces[o.face_start:o.face_stop].ravel())
            markers.append((o.name, scene.vertices[corners, :2].mean(axis=0)))
    figures = summary["coverage"]
    fraction = figures["covered_fraction"]
    title = (f"{pass_label(setup)}\ncovered {fraction:.1%} of {figures['reached_area_m2']:.0f} m² reached"
             if fraction is not None else f"{pass_label(setup)}\nthe scan reaches no seabed cell")
    viz.plot_coverage_map(path, coverage.cell_states(), coverage.grid.extent_m, GAP_CAUSES, lines=lines,
                          markers=markers, title=title)
