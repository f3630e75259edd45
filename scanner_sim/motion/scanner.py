"""The RM3/RM4 scanner: mirror angle over time -> beam and receiver origins and directions.

The transmit mirror RM3 and the receive mirror RM4 turn on one shaft (MULS section 3), so the beam and the
receiver's field of view sweep the plane normal to the shaft together; their axes stay parallel, offset by
d = ``receiver_offset_m`` (0.130 m) along the shaft. The scan angle theta is the beam's angle from nadir,
right-handed about the shaft axis.

Mounting (platform frame x forward, y left, z up):
- ``along_track``: shaft along +x; the beam sweeps the y-z plane (cross-track lines); theta > 0 points left
  (port). Beam direction (0, sin theta, -cos theta). The receiver sits d ahead of the transmitter.
- ``across_track``: shaft along -y (to starboard); the beam sweeps the x-z plane (a forward-looking
  profile); theta > 0 points forward. Beam direction (sin theta, 0, -cos theta).

Modes:
- ``continuous``: the shaft turns at ``scan_rate_hz`` revolutions per second; each revolution starts at the
  sector's start, theta = center - sector/2 + 2 pi (f t mod 1). The laser fires at the pulse rate only while
  theta is inside the active sector: pulses outside it are *not fired* (they do not exist; the pulse slot
  numbers of fired pulses, k in t = k / pulse_rate, stay available for seeding).
- ``oscillating``: theta sweeps the sector back and forth, one line per half period (triangle: constant
  angular rate; sine: a resonant galvo). Every pulse slot fires.
- ``static``: theta = ``aim_deg`` for every pulse (the paper's tank tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from muls.infra.errors import ParameterError
from muls.infra.runtime import kernel


@dataclass(frozen=True)
class Scanner:
    """Scanner timing and geometry. Angles [rad], rates [Hz], positions [m] in the platform frame."""

    mode: str = "continuous"
    scan_rate_hz: float = 10.0
    sector_rad: float = math.radians(90.0)
    center_rad: float = 0.0
    aim_rad: float = 0.0
    oscillation: str = "triangle"
    pulse_rate_hz: float = 5000.0
    mounting: str = "along_track"
    mount_position_m: tuple = (0.0, 0.0, 0.0)
    receiver_offset_m: float = 0.130

    def __post_init__(self):
        if self.mode not in ("continuous", "oscillating", "static"):
            raise ParameterError(f"scanner.mode = {self.mode!r}: must be 'continuous', 'oscillating' or 'static'")
        if self.mounting not in ("along_track", "across_track"):
            raise ParameterError(f"scanner.mounting = {self.mounting!r}: must be 'along_track' or 'across_track'")
        if not (self.pulse_rate_hz > 0 and self.scan_rate_hz > 0 and 0 < self.sector_rad <= 2 * math.pi):
            raise ParameterError("scanner: pulse_rate_hz and scan_rate_hz must be > 0, sector in (0, 360] deg")

    @classmethod
    def from_config(cls, cfg, instrument) -> Scanner:
        """From a :class:`scanner_sim.config.ScannerConfig` and the muls instrument (pulse rate, offset d)."""
        return cls(
            mode=cfg.mode, scan_rate_hz=cfg.scan_rate_hz, sector_rad=math.radians(cfg.sector_deg),
            center_rad=math.radians(cfg.center_deg), aim_rad=math.radians(cfg.aim_deg),
            oscillation=cfg.oscillation,
            pulse_rate_hz=cfg.pulse_rate_hz or instrument.transmitter.repetition_rate_hz,
            mounting=cfg.mounting, mount_position_m=tuple(cfg.mount_position_m),
            receiver_offset_m=instrument.receiver.offset_m,
        )

    # -- timing -------------------------------------------------------------------------------------------
    @property
    def active_fraction(self) -> float:
        """Share of pulse slots that fire (sector / 360 deg in continuous mode, else 1)."""
        return self.sector_rad / (2 * math.pi) if self.mode == "continuous" else 1.0

    def pulse_slots(self, t0_s: float, t1_s: float) -> np.ndarray:
        """(n,) int64 slot numbers k of the pulses fired in [t0, t1): t_k = k / pulse_rate_hz."""
        k0 = math.ceil(t0_s * self.pulse_rate_hz - 1e-9)
        k1 = math.ceil(t1_s * self.pulse_rate_hz - 1e-9)
        k = np.arange(k0, max(k0, k1), dtype=np.int64)
        return k[self._fires(k)] if self.mode == "continuous" else k

    def fired_count(self, k0: int, k1: int) -> int:
        """How many of slots [k0, k1) fire: :meth:`pulse_slots`' count by the same test, a block of slots at a
        time (sector / 360 deg of the slots is only near it: a slot on the sector's edge fires or not by rounding)."""
        if self.mode != "continuous":
            return max(0, k1 - k0)
        block = 1 << 20
        return sum(int(np.count_nonzero(self._fires(np.arange(a, min(a + block, k1), dtype=np.int64))))
                   for a in range(k0, k1, block))

    def _fires(self, k: np.ndarray) -> np.ndarray:
        """(n,) bool: which slots k (n,) fire in continuous mode (the mirror's phase within the sector)."""
        return self._phase_rad(k / self.pulse_rate_hz) < self.sector_rad

    def pulse_times(self, t0_s: float, t1_s: float) -> np.ndarray:
        """(n,) float64 times [s] of the pulses fired in [t0, t1), ascending."""
        return self.pulse_slots(t0_s, t1_s) / self.pulse_rate_hz

    def _phase_rad(self, times_s: np.ndarray) -> np.ndarray:
        cycles = np.asarray(times_s, float) * self.scan_rate_hz
        return 2.0 * math.pi * (cycles - np.floor(cycles))

    def scan_angle_rad(self, times_s) -> np.ndarray:
        """(n,) scan angle theta [rad] from nadir about the shaft at ``times_s`` (n,) [s]."""
        t = np.asarray(times_s, float)
        start = self.center_rad - 0.5 * self.sector_rad
        if self.mode == "static":
            return np.full(t.shape, self.aim_rad)
        phase = self._phase_rad(t)
        if self.mode == "continuous":
            theta = start + phase
            return np.where(theta >= self.center_rad + math.pi, theta - 2.0 * math.pi, theta)
        if self.oscillation == "triangle":
            tri = 1.0 - np.abs(1.0 - phase / math.pi)  # 0 -> 1 -> 0 over one period
            return start + self.sector_rad * tri
        return self.center_rad - 0.5 * self.sector_rad * np.cos(phase)

    def line_index(self, times_s) -> np.ndarray:
        """(n,) int64 scan line of each time ``times_s`` (n,) [s]: the revolution (``continuous``), the half period
        (``oscillating``, one line per sweep) or the period of ``scan_rate_hz`` (``static``) since t = 0."""
        per_period = 2.0 if self.mode == "oscillating" else 1.0
        return np.floor(np.asarray(times_s, float) * self.scan_rate_hz * per_period).astype(np.int64)

    # -- geometry -----------------------------------------------------------------------------------------
    @property
    def shaft_axis(self) -> np.ndarray:
        """(3,) unit shaft direction in the platform frame."""
        return np.array([1.0, 0.0, 0.0]) if self.mounting == "along_track" else np.array([0.0, -1.0, 0.0])

    def directions(self, times_s):
        """Beam and receiver rays in the platform frame at ``times_s`` (n,) [s].

        Returns (beam_origin, beam_dir, rx_origin, rx_dir), each (n, 3) float64: origins [m] (the beam's exit
        point on the mirror axis and the receiver aperture centre, d along the shaft from it), unit
        directions (equal: the axes are parallel).
        """
        theta = self.scan_angle_rad(times_s)
        s, c = np.sin(theta), np.cos(theta)
        zero = np.zeros_like(theta)
        if self.mounting == "along_track":
            beam_dir = np.stack([zero, s, -c], axis=1)  # rotation about +x of nadir (0, 0, -1)
        else:
            beam_dir = np.stack([s, zero, -c], axis=1)  # rotation about -y of nadir
        beam_origin = np.broadcast_to(np.asarray(self.mount_position_m, float), beam_dir.shape).copy()
        rx_origin = beam_origin + self.receiver_offset_m * self.shaft_axis
        return beam_origin, beam_dir, rx_origin, beam_dir.copy()

    def world_rays(self, poses, times_s=None):
        """Beam and receiver rays in the world frame for platform ``poses`` (a trajectory.Poses of n).

        Returns (beam_origin, beam_dir, shaft_dir, rx_origin, rx_dir), each (n, 3) float64 world [m].
        """
        times_s = poses.time_s if times_s is None else times_s
        bo, bd, ro, _ = self.directions(times_s)
        R, p = poses.rotation, poses.position
        beam_dir = _rotate(R, bd)
        shaft = _rotate(R, np.broadcast_to(self.shaft_axis, bd.shape))
        return p + _rotate(R, bo), beam_dir, shaft, p + _rotate(R, ro), beam_dir.copy()  # the axes are parallel

    def beam_rays(self, poses):
        """The beam's rays alone, as :meth:`world_rays` gives them: (beam_origin, beam_dir), each (n, 3) world."""
        bo, bd, _, _ = self.directions(poses.time_s)
        return poses.position + _rotate(poses.rotation, bo), _rotate(poses.rotation, bd)


def _rotate(rotation, vectors):
    """(n, 3): each of ``vectors`` (n, 3) turned by its matrix of ``rotation`` (n, 3, 3)."""
    out = np.empty(np.shape(vectors))
    _turn(np.ascontiguousarray(rotation, np.float64), np.ascontiguousarray(vectors, np.float64), out)
    return out


@kernel(nogil=True)
def _turn(rotation, vectors, out):
    """out[n] = rotation[n] @ vectors[n], each row's three terms added as numpy's einsum adds them,
    (r_0 v_0 + r_2 v_2) + r_1 v_1 onto 0: the bits of ``numpy.einsum("nij,nj->ni", ...)`` without its set-up."""
    for n in range(out.shape[0]):
        v0, v1, v2 = vectors[n, 0], vectors[n, 1], vectors[n, 2]
        for i in range(3):
            out[n, i] = 0.0 + ((rotation[n, i, 0] * v0 + rotation[n, i, 2] * v2) + rotation[n, i, 1] * v1)
