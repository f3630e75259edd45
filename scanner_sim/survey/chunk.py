"""One chunk of pulse slots through the flow: its ray stage (poses, beam sub-rays and their hits, the muls input),
each pulse's line of sight as navigation estimates it with the truth along it, its physics (digitised records and
ranging), and the points and dropouts georeferenced from them with their uncertainty.

The stages themselves are chosen once per pass (:class:`~scanner_sim.survey.setup.PassSetup`); the functions here
call them on a chunk, and the chunk loop (:mod:`scanner_sim.survey.pipeline`) calls these, through
:meth:`PassSetup.simulate_chunk <scanner_sim.survey.setup.PassSetup.simulate_chunk>`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from muls.optics.optical_model import OpticalModel, PulseBatch
from muls.ranging.returns import Ranging
from muls.receiver.digitiser import Waveforms
from muls.simulate import simulate
from scanner_sim.metrics.coverage import Footprint, nominal_footprint
from scanner_sim.motion.trajectory import Poses
from scanner_sim.rays.hits import Hits
from scanner_sim.records.point_records import DropoutRecords, PointRecords
from scanner_sim.survey.georeference import LinesOfSight, dropout_records, georeference, ranged_normals
from scanner_sim.survey.tpu_calibration import CheckedErrors, checked_errors
from scanner_sim.survey.uncertainty import with_uncertainty

if TYPE_CHECKING:  # the set-up holds the stages a chunk goes through; it calls this module, not the reverse
    from scanner_sim.survey.setup import PassSetup


class CastChunk(NamedTuple):
    """A chunk after its ray stage: pulse slots (n,), the sub-ray hits, the muls input built from them, each
    pulse's estimated line of sight with the truth along it, and the nominal footprint (None unless the pass
    measures coverage)."""

    slots: np.ndarray
    hits: Hits
    batch: PulseBatch
    sight: LinesOfSight
    footprint: Footprint | None


class Chunk(NamedTuple):
    """One chunk through the flow: its pulse slots (n,), points, dropouts, the muls digitised records of its pulses
    (``waveforms``; as far as the ranging read them, None once dropped), the nominal beam footprint (None unless
    the pass measures coverage), and the whole records of the pulses among its slots that the pass keeps
    (``kept_waveforms``: slots (k,) and records; None when none), and its points' true errors against their THU and
    TVU (``errors``, :func:`~scanner_sim.survey.tpu_calibration.checked_errors`)."""

    slots: np.ndarray
    points: PointRecords
    dropouts: DropoutRecords
    waveforms: Waveforms | None
    footprint: Footprint | None
    kept_waveforms: tuple[np.ndarray, Waveforms] | None = None
    errors: CheckedErrors | None = None


@dataclass(frozen=True)
class Physics:
    """The MULS stage bound to its pass: a chunk's muls input -> digitised records and ranging
    (:func:`muls.simulate.simulate`, every draw keyed by ``seed`` and the pulse's slot)."""

    model: OpticalModel
    seed: int
    record_mode: str
    deciding_only: bool

    def __call__(self, batch: PulseBatch, record_mode: str | None = None, every_channel: bool = False,
                 whole_records: bool = False, explain_dropouts: bool = True) -> tuple[Waveforms, Ranging]:
        """``record_mode`` and ``every_channel`` override the level's record mode and its ``deciding_only`` (for
        records kept whole, as waveforms.npz keeps them). Unless ``every_channel`` or ``whole_records``, only the
        samples the ranging reads are synthesised (the same points, :func:`muls.receiver.digitiser.digitise`'s
        ``ranging_only``): of each CH0 record the span of its peak, and of a full record the samples the peak
        search may read. ``explain_dropouts``: as :func:`muls.simulate.simulate`."""
        return simulate(self.model, batch, self.seed, record_mode or self.record_mode,
                        deciding_only=self.deciding_only and not every_channel,
                        ranging_only=not (every_channel or whole_records), explain_dropouts=explain_dropouts)


def cast_chunk(setup: PassSetup, slots: np.ndarray) -> CastChunk:
    """The ray stage of one chunk of pulse slots (n,): poses, mirror directions, beam sub-rays and their hits,
    the muls input, each pulse's estimated line of sight with the truth along it, and (when the pass measures
    coverage) the nominal beam footprint."""
    poses = setup.trajectory.poses(slots / setup.scanner.pulse_rate_hz)
    beam_o, beam_d, shaft, rx_o, rx_d = setup.scanner.world_rays(poses)
    hits = setup.rays(beam_o, beam_d, shaft, rx_o, rx_d)
    return CastChunk(slots, hits, setup.handoff(hits, slots), lines_of_sight(setup, slots, poses, hits, (beam_o, beam_d)),
                     nominal_footprint(hits, beam_d) if setup.plan.measures_coverage else None)


def finish_chunk(setup: PassSetup, cast: CastChunk, record_mode: str | None = None, every_channel: bool = False,
                 whole_records: bool = False) -> Chunk:
    """The physics of a chunk after its ray stage: MULS waveforms and ranging, georeferencing, dropouts
    (``record_mode``, ``every_channel``, ``whole_records``: as :class:`Physics`)."""
    records, ranging = setup.physics(cast.batch, record_mode, every_channel, whole_records)
    sight = cast.sight
    dropouts = dropout_records(ranging, sight)
    points = georeference(ranging, cast.hits, sight)
    mean, var = setup.tpu.predict(points, sight, ranged_normals(ranging, cast.hits))
    points = with_uncertainty(points, mean, var)
    return Chunk(cast.slots, points, dropouts, records, cast.footprint,
                 errors=checked_errors(points, sight, mean, var, setup.scene))


def simulate_chunk(setup: PassSetup, slots: np.ndarray, record_mode: str | None = None, every_channel: bool = False,
                   whole_records: bool = False) -> Chunk:
    """One chunk of pulse slots (n,) through the whole flow (``record_mode``, ``every_channel``,
    ``whole_records``: as :class:`Physics`)."""
    return finish_chunk(setup, cast_chunk(setup, slots), record_mode, every_channel, whole_records)


def lines_of_sight(setup: PassSetup, slots: np.ndarray, poses: Poses, hits: Hits,
                   true_beam: tuple[np.ndarray, np.ndarray]) -> LinesOfSight:
    """Each pulse's estimated beam, with the first truth surface along it. Without navigation noise the
    estimated beam is the true beam axis (``true_beam``: its origins and directions (n, 3), as the ray stage
    cast them from the true ``poses``), whose first hit the beam cast already holds (sub-ray 0 of every pattern is
    the axis), so only a noisy navigation needs its estimated poses, its beam and a cast of its own."""
    trajectory, scanner, scene = setup.trajectory, setup.scanner, setup.scene
    noisy, times = trajectory.has_navigation_noise, poses.time_s
    estimate = trajectory.estimate_of(poses)
    if noisy:
        origin, direction = scanner.beam_rays(estimate)
    else:
        origin, direction = true_beam
    axis = hits.subray_index == 0
    axis_range, axis_surface = np.full(slots.size, np.nan), np.full(slots.size, -1)
    axis_range[hits.pulse_index[axis]] = hits.range_m[axis]
    axis_surface[hits.pulse_index[axis]] = hits.surface_id[axis]
    if noisy:
        true_range, first_surface = np.full(slots.size, np.nan), np.full(slots.size, -1)
        ray, tri, dist = setup.target.caster.first_hits((origin - scene.local_origin).astype(np.float32),
                                                        direction.astype(np.float32))
        true_range[ray], first_surface[ray] = dist, scene.face_surface[tri]
    else:
        true_range, first_surface = axis_range, axis_surface
    return LinesOfSight(origin, direction, true_range, first_surface,
                        np.degrees(scanner.scan_angle_rad(times)), times, slots, trajectory.leg(times),
                        estimate.position, np.c_[estimate.roll_rad, estimate.pitch_rad, estimate.yaw_rad],
                        *true_beam, axis_range)
