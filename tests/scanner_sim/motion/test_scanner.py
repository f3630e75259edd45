"""Scanner timing and shaft geometry: pulse times, scan angles, sector, mounting."""

import math

import numpy as np
import pytest

from scanner_sim.motion.scanner import Scanner

PRF = 5000.0


def test_continuous_fires_only_inside_the_sector_at_the_pulse_rate():
    s = Scanner(mode="continuous", scan_rate_hz=10.0, sector_rad=math.radians(90), pulse_rate_hz=PRF)
    t = s.pulse_times(0.0, 1.0)
    theta = s.scan_angle_rad(t)
    assert len(t) == pytest.approx(PRF * 90 / 360, abs=10)  # 1250 of 5000 slots fire
    assert np.all(np.abs(theta) <= math.radians(45) + 1e-12)
    slots = np.round(t * PRF)
    np.testing.assert_allclose(t, slots / PRF, atol=1e-12)  # on the pulse grid
    # Within one line the angle advances 2 pi f / PRF per pulse; lines start every 1 / f s.
    step = np.diff(theta)
    assert np.allclose(step[step > 0], 2 * math.pi * 10 / PRF)
    starts = t[np.r_[True, np.diff(t) > 1.5 / PRF]]
    np.testing.assert_allclose(np.diff(starts), 0.1, atol=1 / PRF)
    assert theta[0] == pytest.approx(-math.pi / 4)


def test_continuous_wraps_outside_sector_angles_to_the_back():
    s = Scanner(mode="continuous", scan_rate_hz=1.0, sector_rad=math.radians(90), pulse_rate_hz=100)
    theta = s.scan_angle_rad(np.linspace(0, 0.999, 1000))
    assert theta.min() >= -math.pi - 1e-12 and theta.max() < math.pi


@pytest.mark.parametrize("shape", ["triangle", "sine"])
def test_oscillating_sweeps_the_sector_back_and_forth(shape):
    s = Scanner(mode="oscillating", scan_rate_hz=8.0, sector_rad=math.radians(60), oscillation=shape,
                pulse_rate_hz=PRF)
    t = s.pulse_times(0.0, 0.5)
    assert len(t) == 2500  # every slot fires
    theta = s.scan_angle_rad(t)
    # Extremes within one pulse step of the sector edges (2 sector f / PRF for the triangle).
    assert theta.min() == pytest.approx(-math.radians(30), abs=2 * math.radians(60) * 8 / PRF)
    assert theta.max() == pytest.approx(math.radians(30), abs=2 * math.radians(60) * 8 / PRF)
    # Period 1 / scan rate: the angle repeats.
    np.testing.assert_allclose(s.scan_angle_rad(t + 0.125), theta, atol=1e-9)
    if shape == "triangle":
        rate = np.abs(np.diff(theta))
        assert np.median(rate) == pytest.approx(2 * math.radians(60) * 8 / PRF, rel=1e-6)


def test_static_aims_every_pulse_the_same_way():
    s = Scanner(mode="static", aim_rad=math.radians(10), pulse_rate_hz=PRF)
    t = s.pulse_times(0.0, 0.2)
    assert len(t) == 1000
    assert np.all(s.scan_angle_rad(t) == math.radians(10))


def test_chunks_concatenate_to_the_whole():
    s = Scanner(mode="continuous", scan_rate_hz=13.0, sector_rad=math.radians(100), pulse_rate_hz=PRF)
    whole = s.pulse_slots(0.0, 2.0)
    parts = np.concatenate([s.pulse_slots(a, b) for a, b in [(0, 0.37), (0.37, 1.2), (1.2, 2.0)]])
    assert np.array_equal(whole, parts)


def test_along_track_geometry_offset_along_the_shaft():
    s = Scanner(mode="static", aim_rad=math.radians(30), receiver_offset_m=0.13, mount_position_m=(0.2, 0, -0.1))
    bo, bd, ro, rd = s.directions(np.zeros(3))
    np.testing.assert_allclose(bd[0], [0, 0.5, -math.sqrt(3) / 2])  # theta > 0 tilts to port (+y)
    np.testing.assert_allclose(ro - bo, np.tile([0.13, 0, 0], (3, 1)))
    np.testing.assert_allclose(rd, bd)
    np.testing.assert_allclose(bo[0], [0.2, 0, -0.1])
    assert np.dot(bd[0], s.shaft_axis) == 0.0  # the beam sweeps the plane normal to the shaft


def test_across_track_sweeps_fore_and_aft():
    s = Scanner(mode="static", aim_rad=math.radians(20), mounting="across_track")
    bo, bd, ro, rd = s.directions(np.zeros(1))
    assert bd[0, 0] > 0 and bd[0, 1] == 0.0  # forward
    np.testing.assert_allclose(ro[0] - bo[0], [0, -0.13, 0])


def test_bad_mode_is_a_value_error():
    with pytest.raises(ValueError, match="scanner.mode"):
        Scanner(mode="spiral")
