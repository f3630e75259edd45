"""Trajectories: waypoints at speed, constant depth, constant altitude over relief, lawnmower, noise."""

import math

import numpy as np
import pytest

from scanner_sim.config import NavigationNoiseConfig, build, load_scene
from scanner_sim.motion.track_checks import build_trajectory
from scanner_sim.motion.trajectory import Trajectory, lawnmower_waypoints
from scanner_sim.world.terrain import generate_heightfield

#: Stated tolerance of constant-altitude following (docs/scene-format.md): over fractal relief of 0.3 m rms
#: (10 m features, Hurst 0.7) plus 3 cm ripples, followed with follow_length_m = 1.5 m, the altitude above
#: the seabed directly below stays within 0.5 m of the set altitude (4 m) and within 0.15 m rms; pitch stays
#: under 10 degrees. The residual is the sub-metre relief a vehicle cannot (and should not) follow.
ALTITUDE_TOLERANCE_M = 0.5
ALTITUDE_RMS_TOLERANCE_M = 0.15


@pytest.fixture(scope="module")
def relief():
    rng = np.random.default_rng(5)
    return generate_heightfield((0, 0), (60, 20), 0.1, 20.0, 0.3, 10.0, 0.7, 0.03, 0.5, 20.0, 0.15, rng)


def test_constant_altitude_holds_over_relief(relief):
    for y in (-5.0, 0.0, 5.0):
        traj = Trajectory([[-28, y], [28, y]], 1.0, "altitude", 4.0, relief, follow_length_m=1.5)
        t = np.linspace(0, traj.duration_s, 5000)
        p = traj.poses(t)
        ground = relief.height(p.position[:, 0], p.position[:, 1])
        error = p.position[:, 2] - ground - 4.0
        assert np.abs(error).max() <= ALTITUDE_TOLERANCE_M
        assert np.sqrt(np.mean(error**2)) <= ALTITUDE_RMS_TOLERANCE_M
        assert np.sqrt(np.mean(error**2)) < 0.6 * np.std(ground)  # much better than a constant depth
    # Smooth: pitch follows the smoothed profile, a few degrees at most.
    assert np.abs(np.degrees(p.pitch_rad)).max() < 10


def test_constant_depth_and_speed(relief):
    traj = Trajectory([[0, 0], [30, 40]], 2.0, "depth", 12.0)
    assert traj.duration_s == pytest.approx(25.0)
    p = traj.poses(np.array([0.0, 10.0, 25.0, 30.0]))
    np.testing.assert_allclose(p.position[:, 2], -12.0)
    np.testing.assert_allclose(p.position[1, :2], [12, 16], atol=1e-9)
    np.testing.assert_allclose(p.position[3, :2], [30, 40], atol=1e-9)  # held at the end
    assert p.heading_deg[1] == pytest.approx(math.degrees(math.atan2(30, 40)))


def test_rotation_follows_heading_and_is_orthonormal():
    traj = Trajectory([[0, 0], [0, 10]], 1.0, "depth", 5.0)  # due north
    p = traj.poses(np.array([3.0]))
    R = p.rotation[0]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-12)  # forward is north
    np.testing.assert_allclose(R @ [0, 1, 0], [-1, 0, 0], atol=1e-12)  # left is west
    assert p.heading_deg[0] == pytest.approx(0.0)


def test_lawnmower_lines_and_spacing():
    w = lawnmower_waypoints((10, 20), (30, 20), 90.0, 5.0)  # lines run east
    assert w.shape == (10, 2)
    np.testing.assert_allclose(w[0], [10 - 15, 20 + 10])
    np.testing.assert_allclose(w[1], [10 + 15, 20 + 10])
    ys = w[::2, 1]
    np.testing.assert_allclose(np.diff(ys), -5.0)
    assert w[2, 0] == pytest.approx(25.0)  # alternating direction


def test_navigation_noise_is_seeded_chunk_independent_and_truth_is_kept():
    cfg = build(NavigationNoiseConfig, {"position_sigma_m": 0.5, "attitude_sigma_deg": 0.2, "seed": 4,
                                        "correlation_time_s": 5.0}, "noise")
    a = Trajectory([[0, 0], [100, 0]], 1.0, "depth", 10.0, noise=cfg)
    b = Trajectory([[0, 0], [100, 0]], 1.0, "depth", 10.0, noise=cfg)
    t = np.linspace(0, 100, 20001)
    truth = a.poses(t)
    est = a.poses(t, estimated=True)
    assert np.array_equal(truth.position[:, 1], np.zeros(len(t)))
    err = est.position - truth.position
    assert 0.2 < err[:, 0].std() < 0.8 and np.all(err[:, 2] == 0)
    whole = b.poses(t, estimated=True).position
    parts = np.concatenate([b.poses(t[:7000], estimated=True).position, b.poses(t[7000:], estimated=True).position])
    assert np.array_equal(whole, est.position) and np.array_equal(parts, whole)


def test_shipped_cable_survey_altitude(tmp_path):
    from scanner_sim.world.scene import build_scene

    cfg = load_scene("cable_survey")
    scene = build_scene(cfg)
    traj = build_trajectory(cfg, scene)
    p = traj.poses(np.linspace(0, traj.duration_s, 2000))
    alt = p.position[:, 2] - scene.surface_height(p.position[:, 0], p.position[:, 1])
    assert np.abs(alt - cfg.platform.altitude_m).max() <= ALTITUDE_TOLERANCE_M
    assert np.sqrt(np.mean((alt - cfg.platform.altitude_m) ** 2)) <= ALTITUDE_RMS_TOLERANCE_M


def test_static_trajectory():
    traj = Trajectory([[1, 2]], 0.0, "fixed", -3.0, duration_s=1.0, heading_deg=90.0)
    p = traj.poses(np.array([0.0, 0.5]))
    np.testing.assert_allclose(p.position, [[1, 2, -3], [1, 2, -3]])
    np.testing.assert_allclose(p.rotation[0] @ [1, 0, 0], [1, 0, 0], atol=1e-12)
