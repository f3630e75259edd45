"""One Monte Carlo run: the targets, the run's settings, and its result as per-batch tallies.

A packet's path is the same in every scene until it first reaches the target's plane, so one run serves
parallel planes at several ranges: each plane records the first arrival of every packet (beam and
receiver), the column of the scene with the target at range R_k keeps the events before the packet first
reached plane k, and the packet is reflected only by the farthest plane. Energy bookkeeping, counting and
multiple bounces describe that farthest scene. The standard error of every time bin comes from the
spread of the batch estimates (beam batches, plus receiver batches for the scattered return).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..infra.errors import ParameterError, check_fraction, check_positive
from ..infra.signals import stop_if_signalled
from ..instrument.description import Instrument
from ..water.phase import PhaseFunction, check_phase
from ..water.properties import Water
from . import transport
from .layout import geo_vector
from .reciprocity import GRID_TIME_STEP_S, TILTED_SECTORS, ring_edges, scattered_return, trace_receiver

#: Time step of the Monte Carlo histograms [s] (the digitiser samples at 1 ns).
TIME_STEP_S = 0.5e-9
#: How long after the farthest echo starts the simulation runs [s]: the echo's multiply scattered tail.
TAIL_S = 150e-9
#: Statistical batches (beam and receiver packets each): standard errors come from their spread.
BATCHES = 20
#: Receiver packets are this fraction of the beam packets by default: the scattered return they estimate
#: is smooth, and its error is then well below the column's.
RECEIVER_SHARE = 4
MAX_TILT_RAD = math.radians(60.0)
#: A run is traced in parts lasting about this long [s]: a compiled kernel cannot be interrupted, so Ctrl-C and
#: SIGTERM take effect between two parts. Each batch traces its packets in the same order whatever the parts, so
#: the result is the same to the bit.
PART_S = 0.5
#: Packets per batch in a run's first part; each next part is sized from the last one's pace, at most 4 times it.
FIRST_PART_PACKETS = 64
#: The kernels number packets in 64-bit integers, and a batch's share as batch x packets: packets x batches (plus
#: the first packet's number) must stay below 2**63.
MAX_PACKET_NUMBER = 2**63 - 1

#: Energy budget keys, in the order of the kernels' columns (muls.montecarlo.transport.EMITTED ...).
ENERGY_KEYS = ("emitted", "absorbed_by_water", "escaped_behind_instrument", "escaped_time_window",
               "received_counted", "absorbed_by_target")


@dataclass(frozen=True)
class TargetPlanes:
    """Flat Lambertian targets: one scene per range, all traced in one run (see the module doc).

    ranges_m: ascending ranges [m] where each plane crosses the beam axis (empty: no target, the column
    alone); reflectance: Lambertian reflectance rho in [0, 1]; tilt_rad: rotation of the planes about the
    axis perpendicular to the offset (0: normal incidence), at most 60 deg.
    """

    ranges_m: tuple[float, ...] = ()
    reflectance: float = 0.1
    tilt_rad: float = 0.0

    def __post_init__(self):
        r = tuple(float(v) for v in np.atleast_1d(np.asarray(self.ranges_m, float)))
        if any(not (math.isfinite(v) and v > 0.0) for v in r) or any(b <= a for a, b in zip(r, r[1:])):
            raise ParameterError(f"ranges_m = {list(r)!r}: must be finite, > 0 and strictly ascending [m]")
        object.__setattr__(self, "ranges_m", r)
        check_fraction("reflectance", self.reflectance)
        if not (0.0 <= self.tilt_rad <= MAX_TILT_RAD):
            raise ParameterError(f"tilt_rad = {self.tilt_rad!r}: must lie in [0, {MAX_TILT_RAD:.4f}] (0 to 60 deg)")

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the planes, pointing back towards the instrument."""
        return np.array([math.sin(self.tilt_rad), 0.0, -math.cos(self.tilt_rad)])

    @property
    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Two unit vectors in the planes: e1 in the plane of the tilt, e2 = +y."""
        return np.array([math.cos(self.tilt_rad), 0.0, math.sin(self.tilt_rad)]), np.array([0.0, 1.0, 0.0])


@dataclass(frozen=True)
class MonteCarloResult:
    """Tallies of one run, as per-batch estimates of the received energy per emitted energy and time bin.

    Arrays are (batches, scenes, n_t) over time bins [i dt, (i+1) dt) after emission; scene k has the
    target at ``ranges_m[k]`` (or, without targets, one scene: the column alone). They are energies at
    the receiver aperture, before the receiver's optics (multiply by ``two_way_transmission``).

    column, column_first: water column, all orders and first scattering only; target_le: the target with an
    unscattered return (local estimate at the hit); target_direct: the part of it with an unscattered beam
    too (the lidar-equation target of Eq. 7 with c); scattered_return: (scenes, n_t) the target with a
    scattered return (reciprocity), scattered_beam / scattered_receiver: its per-batch estimates from the
    beam and from the receiver packets; counted: (batches, n_t) packets that crossed the aperture within the
    field of view (the farthest scene); energy: the energy budget of the farthest scene, fractions of the
    emitted energy; scene_end_s: (scenes,) end of the window in which each scene's target is complete.
    """

    time_step_s: float
    ranges_m: tuple[float, ...]
    speed_m_s: float
    column: np.ndarray
    column_first: np.ndarray
    target_le: np.ndarray
    target_direct: np.ndarray
    scattered_return: np.ndarray
    scattered_beam: np.ndarray
    scattered_receiver: np.ndarray
    counted: np.ndarray
    energy: dict
    scene_end_s: np.ndarray
    packets: int
    receiver_packets: int
    seconds: float
    settings: dict = field(default_factory=dict)

    @property
    def n_t(self) -> int:
        return int(self.column.shape[2])

    @property
    def time_s(self) -> np.ndarray:
        """(n_t,) bin centres [s]."""
        return (np.arange(self.n_t) + 0.5) * self.time_step_s

    def scene(self, range_m: float) -> int:
        """Index of the scene with the target at ``range_m``."""
        for k, r in enumerate(self.ranges_m):
            if abs(r - range_m) <= 1e-9 * max(1.0, r):
                return k
        raise ParameterError(f"range_m = {range_m!r}: this run has targets at {list(self.ranges_m)}")

    def target(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(mean (n_t,), variance of the mean (n_t,)) of scene k's target echo, cut at the scene's window."""
        beam = self.target_le[:, k] + self.scattered_beam[:, k]
        mean = self.target_le[:, k].mean(axis=0) + self.scattered_return[k]
        var = var_of_mean(beam) + var_of_mean(self.scattered_receiver[:, k])
        keep = self.time_s < self.scene_end_s[k]
        return np.where(keep, mean, 0.0), np.where(keep, var, 0.0)

    def total(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(mean, variance of the mean) of column plus target of scene k, per time bin."""
        keep = self.time_s < self.scene_end_s[k] if self.ranges_m else np.ones(self.n_t, bool)
        beam = self.column[:, k] + (self.target_le[:, k] + self.scattered_beam[:, k] if self.ranges_m else 0.0)
        mean = beam.mean(axis=0) + (self.scattered_return[k] if self.ranges_m else 0.0)
        var = var_of_mean(beam) + (var_of_mean(self.scattered_receiver[:, k]) if self.ranges_m else 0.0)
        return np.where(keep, mean, 0.0), np.where(keep, var, 0.0)


def var_of_mean(per_batch: np.ndarray) -> np.ndarray:
    """Variance of the mean of equally sized batch estimates (axis 0)."""
    return per_batch.var(axis=0, ddof=1) / per_batch.shape[0]


def max_packets(batches: int = BATCHES, first_packet: int = 0) -> int:
    """The most packets a run in ``batches`` batches may trace (:data:`MAX_PACKET_NUMBER`), a multiple of
    ``batches`` (a run rounds its packets up to one)."""
    return (MAX_PACKET_NUMBER - first_packet) // batches // batches * batches


def check_packets(key: str, packets, batches: int = BATCHES, first_packet: int = 0) -> int:
    """``packets`` as an int, or a :class:`ParameterError` naming ``key`` when it is not an integer from 1 to
    :func:`max_packets`."""
    if isinstance(packets, bool) or int(packets) != packets or packets < 1:
        raise ParameterError(f"{key} = {packets!r}: must be an integer >= 1")
    if packets > max_packets(batches, first_packet):
        raise ParameterError(f"{key} = {packets!r}: at most {max_packets(batches, first_packet):,} (the Monte Carlo "
                             f"numbers its packets in 64 bits, {batches} batches x packets < 2**63)")
    return int(packets)


def in_parts(trace, per_batch: int) -> None:
    """``trace(part)`` over the offsets [0, ``per_batch``) into every batch's share, in parts (start, stop) each
    sized to last about :data:`PART_S` at the pace of the one before: a signal ends the run between two parts."""
    start, size = 0, FIRST_PART_PACKETS
    while start < per_batch:
        stop_if_signalled()  # a signal whose exception was dropped (muls.infra.signals)
        stop = min(per_batch, start + size)
        t0 = time.perf_counter()
        trace((start, stop))
        seconds = time.perf_counter() - t0
        size = max(1, min(4 * size, int(PART_S * (stop - start) / seconds) if seconds > 0.0 else 4 * size))
        start = stop


def seed_key(seed: int) -> np.uint64:
    """The 64-bit key of the packets' counter-based streams for ``seed`` (an integer >= 0)."""
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ParameterError(f"seed = {seed!r}: must be an integer >= 0")
    with np.errstate(over="ignore"):
        return np.uint64((int(seed) * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) % (1 << 64))


def run_monte_carlo(instrument: Instrument, water: Water, targets: TargetPlanes = TargetPlanes(),
                    phase: str | PhaseFunction = "petzold", packets: int = 200_000,
                    receiver_packets: int | None = None, seed: int = 0, batches: int = BATCHES,
                    time_step_s: float = TIME_STEP_S, tail_s: float = TAIL_S,
                    end_s: float | None = None, peak_truncation_rad: float = 0.0, devices: dict | None = None,
                    first_packet: int = 0) -> MonteCarloResult:
    """Trace ``packets`` beam packets (and ``receiver_packets``, default a quarter as many, from the receiver).

    instrument: its beam diameter and divergence, aperture area, offset and field of view are used;
    water: a, b and its group velocity; phase: a :class:`muls.water.phase.PhaseFunction` or its name;
    end_s: end of the simulated time [s] (default: the farthest target's echo plus ``tail_s``; required
    without targets); devices: changes to the variance-reduction settings
    :data:`muls.montecarlo.transport.DEVICES` (e.g. ``{"ghosts": False}``, for tests of the estimators).
    Packets are rounded up to a multiple of ``batches``.
    """
    phase = check_phase(phase)
    if isinstance(batches, bool) or int(batches) != batches or batches < 2:
        raise ParameterError(f"batches = {batches!r}: must be an integer >= 2")
    batches = int(batches)
    for key, v in (("packets", packets), ("receiver_packets", receiver_packets)):
        if v is not None:
            check_packets(key, v, batches, first_packet)
    packets = -(-int(packets) // batches) * batches
    if receiver_packets is None:
        receiver_packets = max(batches, packets // RECEIVER_SHARE)
    receiver_packets = -(-int(receiver_packets) // batches) * batches
    check_positive("time_step_s", time_step_s)
    check_positive("tail_s", tail_s)
    speed = water.speed_m_s
    planes = targets
    K = len(planes.ranges_m)
    if end_s is None:
        if K == 0:
            raise ParameterError("end_s: give the end of the simulated time [s] when there is no target")
        end_s = 2.0 * planes.ranges_m[-1] / speed + tail_s
    check_positive("end_s", end_s)
    g = instrument.geometry
    r_ap = 0.5 * g.receiver_diameter_m
    half = 0.5 * g.fov_full_rad
    geo = geo_vector(g.beam_diameter_m, g.beam_divergence_full_rad, g.offset_m, r_ap, g.fov_full_rad,
                     transport.devices(**(devices or {})))
    b = water.scattering_per_m
    if peak_truncation_rad > 0.0:
        b *= 1.0 - phase.forward_fraction(peak_truncation_rad)
        phase = phase.truncated(peak_truncation_rad)
    wat = np.array([water.absorption_per_m, b, water.absorption_per_m + b, speed])
    tau = planes.tilt_rad
    ranges = np.array(planes.ranges_m, float)
    depth = ranges * math.cos(tau)
    origin = np.stack([np.full(K, g.offset_m), np.zeros(K), ranges + g.offset_m * math.tan(tau)], axis=1)
    edges = ring_edges(planes.ranges_m, tau, g.offset_m, r_ap, g.fov_full_rad) if K else np.zeros((0, 2))
    n_phi = TILTED_SECTORS if tau > 0.0 else 1
    reach = g.offset_m + r_ap + 0.5 * g.beam_diameter_m
    grid_start = np.maximum(0.0, depth - reach * math.sin(tau)) / speed
    e1, e2 = planes.axes
    scene = (planes.normal, e1, e2, depth, origin, edges, grid_start, n_phi, float(planes.reflectance))
    n_t = int(math.ceil(end_s / time_step_s))
    n_g = int(math.ceil(tail_s / GRID_TIME_STEP_S))
    times = np.array([time_step_s, n_t, GRID_TIME_STEP_S, n_g, end_s])
    cells = (edges.shape[1] - 1) * n_phi if K else 0
    ln_p, ln_theta0, inv_step = phase.log_table
    tables = (phase.sample_theta_rad, ln_p, ln_theta0, inv_step)
    key = seed_key(seed)

    column = np.zeros((batches, K + 1, n_t))
    column1 = np.zeros((batches, K + 1, n_t))
    target = np.zeros((batches, K, n_t))
    target_direct = np.zeros((batches, K, n_t))
    hits = np.zeros((batches, K, cells, n_g))
    counted = np.zeros((batches, n_t))
    energy = np.zeros((batches, len(ENERGY_KEYS)))
    field_r = np.zeros((batches, K, cells, n_g))
    t0 = time.perf_counter()
    stack = transport.split_stack(batches)
    in_parts(lambda part: transport.trace_beam(key, first_packet, packets, geo, wat, scene, tables, times, (
        column, column1, target, target_direct, hits, counted, energy), stack, part), packets // batches)
    if K:
        in_parts(lambda part: trace_receiver(key, first_packet, receiver_packets, geo, wat, scene,
                                             phase.sample_theta_rad, times, field_r, part), receiver_packets // batches)
    seconds = time.perf_counter() - t0

    per_beam = packets // batches
    per_receiver = receiver_packets // batches
    etendue = math.pi * r_ap**2 * math.pi * math.sin(half) ** 2
    hits /= per_beam
    field_r *= etendue / per_receiver
    scattered, scattered_beam, scattered_receiver = scattered_return(hits, field_r, grid_start, time_step_s, n_t)
    if K:
        column = np.cumsum(column, axis=1)[:, :K]  # scene k: events before plane k was first reached
        column1 = np.cumsum(column1, axis=1)[:, :K]
    budget = energy.sum(axis=0) / packets
    return MonteCarloResult(
        time_step_s=float(time_step_s), ranges_m=planes.ranges_m, speed_m_s=speed,
        column=column / per_beam, column_first=column1 / per_beam, target_le=target / per_beam,
        target_direct=target_direct / per_beam, scattered_return=scattered, scattered_beam=scattered_beam,
        scattered_receiver=scattered_receiver, counted=counted / per_beam,
        energy={k: float(v) for k, v in zip(ENERGY_KEYS, budget)},
        scene_end_s=2.0 * grid_start + n_g * GRID_TIME_STEP_S if K else np.array([end_s]),
        packets=packets, receiver_packets=receiver_packets if K else 0, seconds=seconds,
        settings={"water": water.name, "instrument": instrument.name, "phase": phase.name,
                  "reflectance": planes.reflectance, "tilt_rad": planes.tilt_rad, "seed": int(seed),
                  "batches": batches, "end_s": float(end_s), "tail_s": float(tail_s)},
    )
