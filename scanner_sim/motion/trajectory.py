"""Platform trajectories: poses at any array of times, true and as navigation estimates them.

A trajectory is a path in plan (waypoints, a lawnmower pattern, or one static point) run at constant speed,
with its height set by a constant depth or a constant altitude over the seabed. Altitude is followed
smoothly: the seabed height along the track is low-passed with a Gaussian of standard deviation
``follow_length_m`` [m] before the altitude is added, so the vehicle pitches realistically instead of
copying every ripple. Corners are rounded the same way over ``turn_length_m``.

Attitude: yaw from the track (0 east, counter-clockwise), pitch nose-up positive (from the smoothed
profile plus configured offset and oscillation), roll starboard-down positive. The platform-to-world
rotation is R = Rz(yaw) Ry(-pitch) Rx(roll) (platform x forward, y left, z up).

Navigation noise: first-order Gauss-Markov errors in east, north, z, roll, pitch and yaw, sampled once
for the whole pass on a fixed ``rate_hz`` grid from the noise seed and interpolated, so any chunking of the
times gives the same result. ``poses(t)`` is the truth (the rays use it); ``poses(t, estimated=True)`` is
what the navigation reports (points are georeferenced with it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from muls.infra.errors import ParameterError
from muls.infra.filters import first_order_filter
from scanner_sim.world.objects import compass_to_yaw_rad
from scanner_sim.world.raster import lawnmower_area

PATH_STEP_M = 0.05  # arc-length resolution of the precomputed path [m]


@dataclass(frozen=True)
class Poses:
    """Platform poses at n times: time_s (n,) [s]; position (n, 3) world [m]; rotation (n, 3, 3)
    platform-to-world; yaw_rad, pitch_rad, roll_rad (n,) [rad]; speed_m_s (n,) along-track speed."""

    time_s: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    yaw_rad: np.ndarray
    pitch_rad: np.ndarray
    roll_rad: np.ndarray
    speed_m_s: np.ndarray

    @property
    def heading_deg(self) -> np.ndarray:
        """Compass heading [deg, 0 north, clockwise, in [0, 360)]."""
        return np.mod(90.0 - np.degrees(self.yaw_rad), 360.0)


def rotation_matrices(yaw_rad, pitch_rad, roll_rad) -> np.ndarray:
    """(n, 3, 3) R = Rz(yaw) Ry(-pitch) Rx(roll), platform (x fwd, y left, z up) to world."""
    cy, sy = np.cos(yaw_rad), np.sin(yaw_rad)
    cp, sp = np.cos(-np.asarray(pitch_rad)), np.sin(-np.asarray(pitch_rad))
    cr, sr = np.cos(roll_rad), np.sin(roll_rad)
    R = np.empty(np.shape(yaw_rad) + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def lawnmower_waypoints(center_m, size_m, heading_deg: float, line_spacing_m: float) -> np.ndarray:
    """(2 n_lines, 2) waypoints [m] of a lawnmower over a rectangle.

    size_m: (length along the lines, width across them); heading_deg: compass direction of the first line.
    Lines are ``line_spacing_m`` apart, alternate in direction, and step to the right of the first line.
    """
    length, width = size_m
    n_lines = int(math.floor(width / line_spacing_m + 1e-9)) + 1
    offsets = -0.5 * (n_lines - 1) * line_spacing_m + line_spacing_m * np.arange(n_lines)
    pts = []
    for i, off in enumerate(offsets):  # a handful of lines: not a hot path
        ends = [-0.5 * length, 0.5 * length]
        for a in (ends if i % 2 == 0 else ends[::-1]):
            pts.append((a, -off))  # along, left
    pts = np.array(pts)
    yaw = float(compass_to_yaw_rad(heading_deg))
    c, s = math.cos(yaw), math.sin(yaw)
    world = np.c_[c * pts[:, 0] - s * pts[:, 1], s * pts[:, 0] + c * pts[:, 1]]
    return world + np.asarray(center_m, float)


#: [Hz] Rate of the trajectory table a pass writes (trajectory.csv).
TABLE_RATE_HZ = 10.0

class Trajectory:
    """Poses along a plan path at constant speed (or a static pose).

    path_xy_m: (m, 2) waypoints [m] (one point for a static platform); speed_m_s [m/s]; z_mode: 'depth'
    (z = -depth) or 'altitude' (z = smoothed seabed + altitude) or 'fixed' (z given); z_value_m: depth,
    altitude or z [m]; heightfield: the seabed (needed for 'altitude'); duration_s: pass length [s] (static:
    required; moving: defaults to path length / speed); heading_deg: static heading (compass).
    """

    def __init__(self, path_xy_m, speed_m_s: float, z_mode: str, z_value_m: float, heightfield=None,
                 follow_length_m: float = 3.0, turn_length_m: float = 1.0, attitude=None, noise=None,
                 duration_s: float | None = None, heading_deg: float = 0.0):
        path = np.atleast_2d(np.asarray(path_xy_m, float))
        self.static = path.shape[0] == 1
        self.speed_m_s = 0.0 if self.static else float(speed_m_s)
        self.z_mode, self.z_value_m = z_mode, float(z_value_m)
        self.follow_length_m = follow_length_m
        self.heightfield = heightfield
        self.attitude = attitude
        if z_mode == "altitude" and heightfield is None:
            raise ParameterError("platform.altitude_m needs a seabed to follow")
        if self.static:
            s = np.zeros(1)
            xy = path[:1]
            yaw = np.array([float(compass_to_yaw_rad(heading_deg))])
            self.length_m = 0.0
            if duration_s is None:
                raise ParameterError("a static platform needs a duration (survey.duration_s or max_pulses)")
        else:
            seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
            path = path[np.r_[True, seg > 1e-9]]
            chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))]
            self.length_m = float(chord[-1])
            n = max(2, int(math.ceil(self.length_m / PATH_STEP_M)) + 1)
            s = np.linspace(0.0, self.length_m, n)
            xy = np.c_[np.interp(s, chord, path[:, 0]), np.interp(s, chord, path[:, 1])]
            ds = s[1] - s[0]
            if turn_length_m > 0 and path.shape[0] > 2:  # round the corners
                xy = gaussian_filter1d(xy, turn_length_m / ds, axis=0, mode="nearest")
            d = np.gradient(xy, ds, axis=0)
            yaw = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        self._s, self._xy, self._yaw = s, xy, yaw
        self.waypoints_xy_m = path[:1] if self.static else path  # (m, 2) the plan the legs join [m]
        # Where each leg ends along the path [m]: a leg runs from one waypoint to the next.
        self._leg_end_m = chord[1:-1] if not self.static else np.zeros(0)
        self._z, self._terrain_pitch = self._profile(s, xy)
        self.duration_s = float(duration_s) if duration_s is not None else self.length_m / self.speed_m_s
        self._noise = self._make_noise(noise)

    def _profile(self, s, xy):
        if self.z_mode == "depth":
            z = np.full(len(s), -self.z_value_m)
        elif self.z_mode == "fixed":
            z = np.full(len(s), self.z_value_m)
        else:
            ground = self.heightfield.height(xy[:, 0], xy[:, 1])
            if len(s) > 1:
                ground = gaussian_filter1d(ground, self.follow_length_m / (s[1] - s[0]), mode="nearest")
            z = ground + self.z_value_m
        pitch = np.arctan(np.gradient(z, s[1] - s[0])) if len(s) > 1 else np.zeros(1)
        return z, pitch

    def _make_noise(self, cfg):
        if cfg is None or not any((cfg.position_sigma_m, cfg.depth_sigma_m, cfg.attitude_sigma_deg,
                                   cfg.heading_sigma_deg)):
            return None
        n = int(math.ceil(self.duration_s * cfg.rate_hz)) + 2
        rng = np.random.default_rng(cfg.seed)
        phi = math.exp(-1.0 / (cfg.rate_hz * cfg.correlation_time_s))
        w = rng.standard_normal((n, 6))
        w[0] /= math.sqrt(1.0 - phi * phi)  # start in the stationary distribution
        x = first_order_filter(w, phi, math.sqrt(1.0 - phi * phi))  # AR(1), unit variance
        sigma = np.array([cfg.position_sigma_m, cfg.position_sigma_m, cfg.depth_sigma_m,
                          math.radians(cfg.attitude_sigma_deg), math.radians(cfg.attitude_sigma_deg),
                          math.radians(cfg.heading_sigma_deg)])
        return np.arange(n) / cfg.rate_hz, x * sigma

    @property
    def has_navigation_noise(self) -> bool:
        """Does the navigation's estimate differ from the truth (``poses(t, estimated=True)`` != ``poses(t)``)?"""
        return self._noise is not None

    def distance_m(self, times_s) -> np.ndarray:
        """(n,) distance along the path [m] at ``times_s`` (held at the ends)."""
        return np.clip(np.asarray(times_s, float) * self.speed_m_s, 0.0, self.length_m)

    def path(self) -> tuple[np.ndarray, np.ndarray]:
        """The precomputed path, every PATH_STEP_M: arc length (k,) [m] and points (k, 3) [m], world frame."""
        return self._s, np.c_[self._xy, self._z]

    def leg(self, times_s) -> np.ndarray:
        """(n,) uint16 leg of the path (1-based) the platform is on at ``times_s`` (n,) [s]: leg k runs from
        waypoint k to waypoint k + 1 (1 for a static platform)."""
        return (np.searchsorted(self._leg_end_m, self.distance_m(times_s), side="right") + 1).astype(np.uint16)

    def poses(self, times_s, estimated: bool = False) -> Poses:
        """Poses at ``times_s`` (n,) [s]: the truth, or with ``estimated`` the navigation's estimate."""
        t = np.atleast_1d(np.asarray(times_s, float))
        if self.static:
            xy = np.broadcast_to(self._xy[0], (len(t), 2))
            z = np.full(len(t), self._z[0])
            yaw = np.full(len(t), self._yaw[0])
            pitch = np.zeros(len(t))
        else:
            s = self.distance_m(t)
            xy = np.c_[np.interp(s, self._s, self._xy[:, 0]), np.interp(s, self._s, self._xy[:, 1])]
            z = np.interp(s, self._s, self._z)
            yaw = np.interp(s, self._s, self._yaw)
            pitch = np.interp(s, self._s, self._terrain_pitch)
        roll = np.zeros(len(t))
        a = self.attitude
        if a is not None:
            if not a.follow_terrain_pitch:
                pitch = np.zeros(len(t))
            pitch = pitch + math.radians(a.pitch_deg) + math.radians(a.pitch_amplitude_deg) * np.sin(
                2 * math.pi * t / a.pitch_period_s)
            roll = roll + math.radians(a.roll_deg) + math.radians(a.roll_amplitude_deg) * np.sin(
                2 * math.pi * t / a.roll_period_s)
        speed = np.full(len(t), self.speed_m_s)
        if not self.static:
            speed[(t < 0) | (t * self.speed_m_s > self.length_m)] = 0.0
        truth = Poses(t, np.c_[xy, z], rotation_matrices(yaw, pitch, roll), yaw, pitch, roll, speed)
        return self.estimate_of(truth) if estimated else truth

    def estimate_of(self, truth: Poses) -> Poses:
        """The navigation's estimate of the true poses ``truth`` (at their times): ``truth`` itself without
        navigation noise, else the truth plus the noise's position and attitude errors then."""
        if self._noise is None:
            return truth
        grid, err = self._noise
        e = np.stack([np.interp(truth.time_s, grid, err[:, k]) for k in range(6)], axis=1)
        roll, pitch, yaw = truth.roll_rad + e[:, 3], truth.pitch_rad + e[:, 4], truth.yaw_rad + e[:, 5]
        return Poses(truth.time_s, truth.position + e[:, :3], rotation_matrices(yaw, pitch, roll), yaw, pitch, roll,
                     truth.speed_m_s)

    def table(self, start_s: float, stop_s: float, rate_hz: float = TABLE_RATE_HZ) -> dict[str, np.ndarray]:
        """True and estimated poses from ``start_s`` to ``stop_s`` [s] at ``rate_hz``: time_s (n,), position_m
        (n, 3), attitude_deg (n, 3) roll, pitch, yaw, est_position_m, est_attitude_deg, leg (n,)."""
        t = np.arange(start_s, stop_s, 1.0 / rate_hz)
        true = self.poses(t)
        est = self.estimate_of(true)

        def rpy(p):
            return np.degrees(np.c_[p.roll_rad, p.pitch_rad, p.yaw_rad])

        return {"time_s": t, "position_m": true.position, "attitude_deg": rpy(true), "est_position_m": est.position,
                "est_attitude_deg": rpy(est), "leg": self.leg(t)}


def trajectory_of(config, scene=None) -> Trajectory:
    """The :class:`Trajectory` a :class:`scanner_sim.config.SceneConfig` describes over its built ``scene``, unchecked
    (:func:`scanner_sim.motion.track_checks.build_trajectory` checks it first)."""
    p = config.platform
    hf = scene.heightfield if scene is not None else None
    if p.mode == "static":
        pos = p.position_m
        if len(pos) == 3:
            z_mode, z_val = "fixed", pos[2]
        else:
            z_mode, z_val = ("altitude", p.altitude_m) if p.altitude_m is not None else ("depth", p.depth_m)
        sv = config.survey
        duration = sv.duration_s
        if duration is None:
            rate = config.scanner.pulse_rate_hz or config.instrument_model().transmitter.repetition_rate_hz
            duration = sv.max_pulses / rate
        return Trajectory([pos[:2]], 0.0, z_mode, z_val, hf, p.follow_length_m, p.turn_length_m, p.attitude,
                          p.navigation_noise, duration_s=sv.start_s + duration, heading_deg=p.heading_deg)
    if p.mode == "lawnmower":
        lm = p.lawnmower
        center, size = lawnmower_area(lm, config.seabed)
        path = lawnmower_waypoints(center, size, lm.heading_deg, lm.line_spacing_m)
    else:
        path = np.asarray(p.waypoints_m, float)
    z_mode, z_val = ("altitude", p.altitude_m) if p.altitude_m is not None else ("depth", p.depth_m)
    return Trajectory(path, p.speed_m_s, z_mode, z_val, hf, p.follow_length_m, p.turn_length_m, p.attitude,
                      p.navigation_noise)
