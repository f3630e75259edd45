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

from . import io, viz
from .coverage import BACKGROUND_KINDS, GAP_CAUSES, CoverageAccumulator

#: Resolution and extent of the streaming |range error| histogram behind the summary's quantiles [m].
ERROR_BIN_M = 5e-4
ERROR_MAX_M = 20.0

#: Trajectory output rate [Hz].
TRAJECTORY_RATE_HZ = 10.0


class LasSink(io.LasWriter):
    """points.las, streamed chunk by chunk."""

    def __init__(self, path: Path, local_origin: np.ndarray):
        super().__init__(path, offset_m=local_origin)

    def add(self, chunk) -> None:
        self.write(chunk.points)


class DropoutSink(io.DropoutWriter):
    """dropouts.npz, streamed chunk by chunk."""

    def add(self, chunk) -> None:
        self.write(chunk.dropouts)


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
        self.channels = np.zeros(n_channels + 1, np.int64)
        self.error_counts = np.zeros(int(ERROR_MAX_M / ERROR_BIN_M) + 1, np.int64)

    def add(self, chunk) -> None:
        self.pulses += chunk.slots.size
        self.channels += np.bincount(chunk.points.channel, minlength=self.channels.size)
        e = np.abs(chunk.points.range_error_m)
        e = e[np.isfinite(e)]
        np.add.at(self.error_counts, np.minimum((e / ERROR_BIN_M).astype(np.int64), self.error_counts.size - 1), 1)

    def error_quantile_m(self, q: float) -> float | None:
        total = self.error_counts.sum()
        if total == 0:
            return None
        k = int(np.searchsorted(np.cumsum(self.error_counts), q * total))
        return (k + 0.5) * ERROR_BIN_M


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


def write_pass_files(setup, out: Path, options) -> None:
    """trajectory.csv, scene.ply (unless ``options.write_scene`` is False) and waveforms.npz (when
    ``options.waveforms`` asks for some)."""
    write_truth_and_trajectory(setup, out, options.write_scene)
    if options.waveforms:
        write_waveforms(setup, out / "waveforms.npz", options.waveforms)


def write_truth_and_trajectory(setup, out: Path, write_scene: bool = True) -> None:
    """scene.ply (labelled truth meshes; unless ``write_scene`` is False) and trajectory.csv (true and
    estimated poses at 10 Hz)."""
    scene = setup.scene
    if write_scene:
        io.write_scene_ply(out / "scene.ply", scene.vertices, scene.faces, scene.face_label, scene.face_object)
    t0 = setup.first_slot / setup.scanner.pulse_rate_hz
    t1 = setup.end_slot / setup.scanner.pulse_rate_hz
    t = np.arange(t0, t1, 1.0 / TRAJECTORY_RATE_HZ)
    true, est = setup.trajectory.poses(t), setup.trajectory.poses(t, estimated=True)

    def rpy(p):
        return np.degrees(np.c_[p.roll_rad, p.pitch_rad, p.yaw_rad])

    io.write_trajectory_csv(out / "trajectory.csv", t, true.position, rpy(true),
                            estimated_position_m=est.position, estimated_attitude=rpy(est))


def write_waveforms(setup, path: Path, count: int) -> None:
    """Full records of ``count`` pulses spread evenly over the pass (same noise as in the pass itself)."""
    slots = np.concatenate(list(setup.slot_chunks()))
    pick = slots[np.unique(np.linspace(0, slots.size - 1, min(count, slots.size)).astype(np.int64))]
    records = setup.simulate_chunk(pick, record_mode="full").records
    time_ns = records.reference_times_s(setup.model) * 1e9  # full mode: the reference spans the record
    channels = {"ch0": records.reference}
    channels.update({ch.name: records.codes[:, i, :] for i, ch in enumerate(setup.model.instrument.channels)})
    io.write_waveforms_npz(path, pick, time_ns, channels)


def render_pass(setup, out: Path, window_size=(1600, 1000), max_points: int = 1_500_000) -> None:
    """render.png: the point cloud coloured by class over the faded truth mesh (decimated read-back)."""
    import laspy

    with laspy.open(out / "points.las") as reader:
        stride = max(1, math.ceil(reader.header.point_count / max_points))
        xyz, cls = [], []
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
