"""Georeferencing: the instrument's ranged returns to world points with their ground truth attached.

:func:`georeference` (and :func:`dropout_records`, for the pulses that gave no point) is a pure function of what
the stages before it produced: the ranging of a chunk (each return carries the index of the echo that dominates it,
:attr:`muls.ranging.returns.Peaks.echo_index`), the hits that made those echoes, and each pulse's line of sight as
navigation estimates it, with the truth along it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from muls.ranging.returns import Ranging
from scanner_sim.config.materials import NOISE_CLASS
from scanner_sim.rays.hits import Hits
from scanner_sim.records.point_records import DropoutRecords, PointRecords

#: Intensity scale: log10 of the echo's peak optical power [W] from 1 nW (0) to 1 W (65535).
INTENSITY_LOG10_RANGE_W = (-9.0, 0.0)

#: object_id of a point that no object made (a noise return, class :data:`NOISE_CLASS`).
NO_OBJECT = -1


class LinesOfSight(NamedTuple):
    """Each pulse's beam where navigation puts it, and the truth along it (one row per pulse of a chunk).

    origin_m (n, 3), direction (n, 3) unit: the estimated beam in the world frame; true_range_m (n,): range to
    the first truth surface along it (nan where it meets none) and first_surface (n,) int that surface
    (``Scene.face_surface`` of the triangle met; -1: none);
    scan_angle_deg (n,); time_s (n,) [s from the pass start]; slot (n,) int64: the pulse's number in the pass;
    leg (n,) uint16: the survey leg, 1-based; platform_m (n, 3) and attitude_rad (n, 3) roll, pitch, yaw: the
    vehicle's pose as navigation estimates it (what the uncertainty's Jacobians are evaluated at); true_origin_m
    (n, 3), true_direction (n, 3) and axis_range_m (n,): the true beam axis and the range to its first hit (nan where
    it meets nothing), where each point truly belongs (:mod:`scanner_sim.survey.tpu_calibration`).
    """

    origin_m: np.ndarray
    direction: np.ndarray
    true_range_m: np.ndarray
    first_surface: np.ndarray
    scan_angle_deg: np.ndarray
    time_s: np.ndarray
    slot: np.ndarray
    leg: np.ndarray
    platform_m: np.ndarray
    attitude_rad: np.ndarray
    true_origin_m: np.ndarray
    true_direction: np.ndarray
    axis_range_m: np.ndarray


def intensity_from_power(peak_power_w: np.ndarray) -> np.ndarray:
    """LAS intensity (uint16) of echoes of peak optical power ``peak_power_w`` (n,) [W], log-scaled so that
    one number spans the channels' 10^4 dynamic range (see docs/outputs.md)."""
    lo, hi = INTENSITY_LOG10_RANGE_W
    level = (np.log10(np.maximum(peak_power_w, 1e-30)) - lo) / (hi - lo)
    return np.round(np.clip(level, 0.0, 1.0) * 65535.0).astype(np.uint16)


#: Below this |cosine| between the line of sight and a facet's normal (89.4 degrees), the facet's plane is
#: too close to edge-on to place the truth along the line; the first truth surface along it is used instead.
GRAZING_COS = 0.01


def ranged_surface_range(origin_m, direction, point_m, normal) -> np.ndarray:
    """(n,) range [m] along each line (origin (n, 3), unit direction (n, 3)) to the plane through ``point_m``
    (n, 3) with ``normal`` (n, 3); nan where the plane is within :data:`GRAZING_COS` of edge-on, behind the
    origin, or not given (nan rows)."""
    normal = np.asarray(normal, np.float64)
    along = np.einsum("ij,ij->i", direction, normal)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.einsum("ij,ij->i", np.asarray(point_m) - origin_m, normal) / along
    return np.where((np.abs(along) >= GRAZING_COS) & (t > 0.0), t, np.nan)


def georeference(ranging: Ranging, hits: Hits, sight: LinesOfSight) -> PointRecords:
    """Points where the instrument and its navigation put them, with the truth attached (their uncertainty, ``thu_m``
    and ``tvu_m``, unknown: :meth:`scanner_sim.survey.uncertainty.TpuModel.predict` gives it).

    xyz = estimated beam origin + measured range x estimated beam direction. Class, object and incidence are
    those of the hit whose echo the instrument ranged (``Peaks.echo_index``; the chunk's PulseBatch has one
    return per hit, in hit order); a return no echo explains gets :data:`NOISE_CLASS`, object -1 and
    incidence nan. true_range_m is where the surface the instrument ranged lies along the point's own line of
    sight, and range_error_m the point's signed distance from it along that line: ranging error, merged echoes
    and navigation noise all show in it. The surface is the ranged hit's own (``Hits.surface_id``, its triangle's
    smooth surface), not its object's: a step inside one mesh is two surfaces, as it is as two objects. The truth
    is the first truth surface along the line when that is the ranged surface; otherwise (a return behind an
    edge, or on the upper surface of a step whose lower one the line meets first) the plane of the ranged hit's
    facet, so each return is judged against the surface it came from. A noise return takes the first surface;
    where neither applies (a facet within :data:`GRAZING_COS` of edge-on, a line that meets nothing), the
    ranged hit's own range, else nan: never another pulse's hit.
    """
    r = ranging.returns
    pulse = r.pulse
    echo = r.echo_index
    explained = echo >= 0
    j = np.where(explained, echo, 0)
    have = explained & (len(hits) > 0)

    def of_hit(values, missing):
        out = np.full(pulse.shape + values.shape[1:], missing, dtype=np.result_type(values.dtype, np.asarray(missing).dtype))
        out[have] = values[j[have]]
        return out

    true_range = sight.true_range_m[pulse].astype(np.float64)
    other = have & (sight.first_surface[pulse] != of_hit(hits.surface_id, -1))  # ranged off the first surface
    true_range[other] = ranged_surface_range(sight.origin_m[pulse][other], sight.direction[pulse][other],
                                             hits.point[j[other]], hits.normal[j[other]])
    unseen = np.isnan(true_range)
    true_range[unseen] = of_hit(hits.range_m, np.nan)[unseen]
    return PointRecords(
        gps_time_s=sight.time_s[pulse], xyz=sight.origin_m[pulse] + r.range_m[:, None] * sight.direction[pulse],
        intensity=intensity_from_power(r.peak_power_w), return_number=ranging.return_number,
        number_of_returns=ranging.number_of_returns, classification=of_hit(hits.label, NOISE_CLASS).astype(np.uint8),
        scan_angle_deg=sight.scan_angle_deg[pulse], channel=r.channel.astype(np.uint8), amplitude_lsb=r.amplitude_lsb,
        snr=r.snr, saturated=r.saturated, true_range_m=true_range, range_error_m=r.range_m - true_range,
        incidence_deg=np.degrees(of_hit(hits.incidence_rad, np.nan)), object_id=of_hit(hits.object_id, NO_OBJECT),
        leg=sight.leg[pulse], pulse_index=sight.slot[pulse])


def dropout_records(ranging: Ranging, sight: LinesOfSight) -> DropoutRecords:
    """The pulses of a chunk that gave no point (``Ranging.dropout_cause`` >= 0), each with its line of sight as
    navigation estimates it (the beam a surveyor would look along for what was missed) and its cause."""
    lost = ranging.dropout_cause >= 0
    return DropoutRecords(pulse_index=sight.slot[lost], time_s=sight.time_s[lost], origin=sight.origin_m[lost],
                          direction=sight.direction[lost], cause=ranging.dropout_cause[lost].astype(np.uint8))


def ranged_normals(ranging: Ranging, hits: Hits) -> np.ndarray:
    """(n, 3) unit normal of the facet whose echo each of the n returns of ``ranging`` ranged (``Peaks.echo_index``
    into ``hits``, as :func:`georeference` reads it); NaN rows for returns no echo explains (noise)."""
    echo = ranging.returns.echo_index
    have = (echo >= 0) & (len(hits) > 0)
    out = np.full((echo.size, 3), np.nan)
    out[have] = hits.normal[echo[have]]
    return out
