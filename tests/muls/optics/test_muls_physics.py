"""Closed-form checks of the MULS optics: pulse (Eq. 2), water (Eqs. 5, 6), overlap (Eq. 11), radiometry
(Eqs. 3, 4, 7-10) and the exactly-cut water column."""

import math
from dataclasses import replace

import numpy as np
import pytest

from muls import Digitiser, ParameterError, PulseShape, Transmitter, Water, mul2023, water_preset
from muls.optics.optical_model import OpticalModel
from muls.optics.radiometry import (
    background_power_w,
    column_density_per_m,
    lambertian_weight,
    target_factor,
    two_way_transmission,
    window_factor,
)
from muls.presets import coaxial

REL_TOL_TABLE = 2e-3  # column tables: trapezoid rule on a 25 ps grid


def paper(name: str) -> Water:
    """The preset water under the paper's attenuation rule (Eq. 6's k_lidar), for tests of the paper's equations."""
    return water_preset(name).with_models(attenuation_model="k_lidar")


def with_overlap(instrument, model: str):
    """``instrument`` whose receiver sees the beam by overlap ``model`` (muls.instrument.overlap.OVERLAP_MODELS)."""
    return replace(instrument, receiver=replace(instrument.receiver, overlap_model=model))


def test_pulse_has_unit_area_fwhm_and_peak_at_0409_width():
    pulse = PulseShape(10e-9)
    t = np.linspace(0.0, 400e-9, 400001)
    w = pulse(t)
    assert np.trapezoid(w, t) == pytest.approx(1.0, abs=1e-7)
    above = t[w >= 0.5 * w.max()]
    assert above[-1] - above[0] == pytest.approx(10e-9, abs=2e-12)
    assert pulse.peak_delay_s == pytest.approx(0.4088 * 10e-9, rel=1e-3)
    assert pulse(-1e-9) == 0.0


def test_band_limited_pulse_keeps_unit_area_and_is_later_and_lower():
    raw, filtered = PulseShape(10e-9), PulseShape(10e-9, 200e6)
    t = np.linspace(0.0, 400e-9, 400001)
    assert np.trapezoid(filtered(t), t) == pytest.approx(1.0, abs=1e-7)
    assert filtered.peak_delay_s > raw.peak_delay_s
    assert filtered(filtered.peak_delay_s) < raw(raw.peak_delay_s)
    # The first-order low-pass adds its time constant 1 / (2 pi B) to the mean delay.
    mean_raw = np.trapezoid(t * raw(t), t)
    mean_filtered = np.trapezoid(t * filtered(t), t)
    assert mean_filtered - mean_raw == pytest.approx(1.0 / (2 * math.pi * 200e6), rel=1e-4)


@pytest.mark.parametrize("bandwidth_hz", [None, 200e6, 2e9])
def test_pulse_peak_is_its_maximum_over_a_fine_grid(bandwidth_hz):
    """``peak_per_s`` bounds the pulse (the dropout causes set faint pulses aside with it): no sample of a 10 ps grid
    over its duration exceeds it, and the grid's highest is within a millionth of it."""
    pulse = PulseShape(10e-9, bandwidth_hz)
    grid_max = pulse(np.arange(0.0, pulse.duration_s, 1e-11)).max()
    assert grid_max <= pulse.peak_per_s
    assert grid_max == pytest.approx(pulse.peak_per_s, rel=1e-6)


@pytest.mark.parametrize("bandwidth_hz", [None, 200e6])
def test_pulse_rms_width_is_the_standard_deviation_of_its_profile(bandwidth_hz):
    """rms_width_s against the profile's second central moment integrated numerically."""
    pulse = PulseShape(10e-9, bandwidth_hz)
    t = np.linspace(0.0, 400e-9, 400001)
    mean = np.trapezoid(t * pulse(t), t)
    assert pulse.rms_width_s == pytest.approx(math.sqrt(np.trapezoid((t - mean) ** 2 * pulse(t), t)), rel=1e-6)


@pytest.mark.parametrize("name, expected", [("clean_ocean", 0.119), ("coastal_ocean", 0.202), ("turbid_harbor", 0.521)])
def test_k_lidar_of_petzold_waters(name, expected):
    assert water_preset(name).k_lidar_per_m == pytest.approx(expected, abs=6e-4)


def test_attenuation_options_and_limits():
    clean = water_preset("clean_ocean")
    assert clean.with_models(attenuation_model="c").two_way_attenuation_per_m == pytest.approx(0.151)
    # k_lidar is c for an absorbing-only water (w0 = 0) and below c for any scattering water.
    absorbing = Water("absorbing", 0.2, 0.0)
    assert absorbing.k_lidar_per_m == pytest.approx(0.2)
    assert clean.k_lidar_per_m < clean.attenuation_per_m
    kd = clean.with_models(attenuation_model="kd").two_way_attenuation_per_m
    assert clean.absorption_per_m < kd < clean.attenuation_per_m


def test_backscatter_options():
    harbor = water_preset("turbid_harbor")
    b = harbor.scattering_per_m
    assert harbor.beta_pi_per_m_sr == pytest.approx(0.0031 * b)
    assert harbor.with_models(backscatter_model="hg").beta_pi_per_m_sr == pytest.approx(1.634e-3 * b, rel=1e-3)
    assert harbor.with_models(backscatter_model="eq5").beta_pi_per_m_sr == pytest.approx(0.0962 * b, rel=2e-3)
    # The pond has no measured beta(pi): "measured" falls back to Petzold's average particle phase function, the Monte
    # Carlo's, with p(pi) = 0.00318 per sr (docs/multiple-scattering.md), twice Henyey-Greenstein's.
    pond = water_preset("pond")
    assert pond.beta_pi_per_m_sr == pytest.approx(0.00318 * pond.scattering_per_m, rel=2e-3)
    assert pond.beta_pi_per_m_sr == pond.with_models(backscatter_model="petzold").beta_pi_per_m_sr
    assert harbor.with_models(backscatter_model="petzold").beta_pi_per_m_sr == pytest.approx(0.00318 * b, rel=2e-3)


def test_group_velocity():
    assert water_preset("clean_ocean").speed_m_s == pytest.approx(299_792_458 / 1.364)
    assert water_preset("pool").speed_m_s == pytest.approx(299_792_458 / 1.357)


@pytest.mark.parametrize("model", ["eq11", "finite_aperture"])
def test_overlap_blind_zone_and_full_overlap_from_closed_form(model):
    """Both models start where the beam first touches the union of the aperture points' fields (1.68 m); Eq. 11
    reaches 1 where the spot lies inside that union, a finite aperture where every aperture point's own field holds
    the whole spot (d + r_ap + r_beam = z tan(theta_r / 2), 3.59 m for the MUL)."""
    g = with_overlap(mul2023(), model).geometry
    r10, r20, t1, t2, d = 0.005, g.receiver_diameter_m / 2, math.tan(2e-3), math.tan(50e-3), 0.13
    assert g.blind_zone_m == pytest.approx((d - r10 - r20) / (t1 + t2))
    assert g.blind_zone_m == pytest.approx(1.683, abs=1e-3)  # docs/design.md#angles: 1.68 m (half-angle reading)
    full = (d - r20 + r10) / (t2 - t1) if model == "eq11" else (d + r20 + r10) / (t2 - t1)
    assert g.full_overlap_m == pytest.approx(full)
    z = np.linspace(0.0, 10.0, 20001)
    o = g.overlap(z)
    assert np.all(o[z <= g.blind_zone_m] == 0.0)
    assert np.all(o[z >= g.full_overlap_m] == pytest.approx(1.0))
    assert np.all(np.diff(o) >= -1e-12)  # monotone
    assert np.max(np.abs(np.diff(o))) < 5e-3  # continuous: no jump on a 0.5 mm grid
    inside = (z > g.blind_zone_m) & (z < g.full_overlap_m - 0.05)  # a finite aperture nears 1 quadratically
    assert np.all((o[inside] > 0.0) & (o[inside] < 1.0))


def test_eq11_overlap_equals_lens_area_by_monte_carlo():
    g = with_overlap(mul2023(), "eq11").geometry
    z = 1.85
    r1, r2 = float(g.beam_radius_m(z)), float(g.footprint_radius_m(z))
    rng = np.random.default_rng(1)
    n = 400_000
    rad, ang = r1 * np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
    x, y = rad * np.cos(ang), rad * np.sin(ang)
    inside = (x - g.offset_m) ** 2 + y**2 <= r2**2
    assert float(g.overlap(z)) == pytest.approx(inside.mean(), abs=4e-3)


@pytest.mark.parametrize("z", [1.9, 2.5, 3.0, 3.4])
def test_finite_aperture_overlap_is_the_share_of_the_aperture_that_sees_each_point_of_the_spot(z):
    """Sampled directly: uniform points of the beam spot and of the aperture; a pair counts when the spot point lies
    within the aperture point's own field of view (z tan(theta_r / 2) of its axis). Both sample sets are independent
    of the quadrature the model integrates with."""
    g = mul2023().geometry
    rng = np.random.default_rng(7)

    def disc(n, radius):
        rad, ang = radius * np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
        return np.c_[rad * np.cos(ang), rad * np.sin(ang)]

    spot = disc(3000, float(g.beam_radius_m(z)))
    aperture = disc(3000, g.receiver_diameter_m / 2) + [g.offset_m, 0.0]
    rho = z * math.tan(0.5 * g.fov_full_rad)
    seen = np.mean(((spot[:, None, :] - aperture[None, :, :]) ** 2).sum(axis=2) <= rho**2)
    assert float(g.overlap(z)) == pytest.approx(seen, abs=0.01)
    assert float(g.overlap(z)) < float(g.eq11_overlap(z))  # Eq. 11 counts the whole aperture for the union


def test_full_angle_reading_moves_blind_zone_to_337_m():
    ins = mul2023()
    full_reading = replace(
        ins, transmitter=replace(ins.transmitter, beam_divergence_full_rad=2e-3),
        receiver=replace(ins.receiver, fov_full_rad=50e-3))
    assert full_reading.geometry.blind_zone_m == pytest.approx(3.37, abs=0.01)


def test_flat_plate_factor_is_eq7():
    ins, water = mul2023(), paper("pond")
    z, rho = 8.5, 0.1
    weight = lambertian_weight(ins, z, rho)
    expected = (ins.receiver.area_m2 * 1.0 * rho / math.pi * 0.9 * 0.6 * (1 - 0.0039) ** 2
                * math.exp(-2 * water.k_lidar_per_m * z) / z**2)
    assert float(target_factor(ins, water, z, weight)) == pytest.approx(expected, rel=1e-12)
    # Inside the blind zone no light reaches the receiver.
    assert float(target_factor(ins, water, 1.0, lambertian_weight(ins, 1.0, rho))) == 0.0


def test_flat_plate_echo_energy_in_the_record_equals_eq7():
    """The noise-free waveform of a plate minus that of a black plate at the same range is the Eq. 7 echo."""
    from muls.optics.optical_model import PulseBatch
    from muls.simulate import simulate

    ins, water = mul2023(), water_preset("pool")
    ins = ins.with_channel("ch3", gate_delay_s=None, gate_width_s=None)
    model = OpticalModel.build(ins, water)
    z = 12.0
    records = []
    for rho in (0.05, 0.0):
        batch = PulseBatch.flat_target(ins, [z], rho)
        rec, _ = simulate(model, batch, seed=1, mode="full", keep_noise_free=True)
        records.append(rec.noise_free_lsb[0, 1].astype(float))  # ch2: stays far from clipping
    echo_lsb = records[0] - records[1]
    energy_j = echo_lsb.sum() * ins.digitizer.sample_interval_s / (ins.channels[1].volts_per_watt * ins.digitizer.lsb_per_volt)
    expected = ins.transmitter.pulse_energy_j * float(target_factor(ins, water, z, lambertian_weight(ins, z, 0.05)))
    assert energy_j == pytest.approx(expected, rel=2e-3)


def test_column_with_a_short_pulse_is_the_eq4_closed_form():
    ins = with_overlap(mul2023(), "eq11")  # Eq. 11's overlap is 1 from 2.03 m on
    ins = replace(ins, transmitter=replace(ins.transmitter, pulse_width_s=1e-9),
                  digitizer=replace(ins.digitizer, bandwidth_hz=1e12))
    water = paper("coastal_ocean")
    model = OpticalModel.build(ins, water)
    a = ins.pulse.decay_per_s
    mean_delay = 2.0 / a  # first moment of a^2 t exp(-a t)
    z = np.array([3.0, 5.0, 10.0, 20.0, 40.0])
    t = 2 * z / water.speed_m_s
    got = model.column_power_w(t + mean_delay)
    closed = (ins.transmitter.pulse_energy_j * water.speed_m_s / 2 * ins.receiver.area_m2 * water.beta_pi_per_m_sr
              * two_way_transmission(ins) * np.exp(-2 * water.k_lidar_per_m * z) / z**2)
    assert got == pytest.approx(closed, rel=1e-2)
    assert column_density_per_m(ins, water, z) * ins.transmitter.pulse_energy_j * water.speed_m_s / 2 == pytest.approx(closed)


def test_cut_column_equals_numerical_convolution_of_truncated_profile():
    """Single scattering (Eq. 4) under the product's range-dependent attenuation rule: the exact cut of the tables
    against a direct convolution of the density the rule gives."""
    ins, water = mul2023(), water_preset("turbid_harbor")
    model = OpticalModel.build(ins, water, "none")
    cut = 4.0
    t = np.array([10e-9, 30e-9, 2 * cut / water.speed_m_s, 45e-9, 60e-9, 90e-9])
    dz = 1e-4
    z = np.arange(dz / 2, cut, dz)
    density = column_density_per_m(ins, water, z) * ins.transmitter.pulse_energy_j
    expected = [np.sum(density * ins.pulse(ti - 2 * z / water.speed_m_s)) * dz for ti in t]
    assert model.column_power_w(t, cut) == pytest.approx(expected, rel=REL_TOL_TABLE)
    # Before the cut's echo time the cut changes nothing.
    early = t[:2]
    assert model.column_power_w(early, cut) == pytest.approx(model.column_power_w(early), rel=1e-12)


def test_baselines_a_window_at_once_are_the_uncut_column_plus_background():
    """The peak search and the channel test take a window's baseline from ``baseline_values`` (a loop of selects
    over the uncut column table); it must be the background plus the column that meets nothing, as the exact
    column (``column_power_w`` with no cut, a second engine) gives it, zero before emission and past the tables."""
    from muls.optics.sample_kernels import baseline_values

    model = OpticalModel.build(mul2023(), water_preset("coastal_ocean"))
    end = model.column.step_s * (model.column.uncut.shape[0] - 1)
    t = np.concatenate([[-5e-9, 0.0], np.linspace(1e-10, 300e-9, 997), [end - 1e-12, end, end + 1e-9]])
    out = np.empty_like(t)
    baseline_values(out, t, 2e-9, model.column)
    expected = model.column_power_w(t)
    assert out - 2e-9 == pytest.approx(expected, rel=REL_TOL_TABLE, abs=1e-15)
    assert np.all(out[:2] == 2e-9) and np.all(out[-2:] == 2e-9) and out[200] > 1e-7


def test_column_energy_is_conserved():
    """The time integral of the column power is E_t times the integral of the Eq. 4 density over range."""
    ins, water = mul2023(), water_preset("coastal_ocean")
    model = OpticalModel.build(ins, water, "none")
    cut = 15.0
    t = np.arange(0.0, 2 * cut / water.speed_m_s + 200e-9, 0.05e-9)
    z = np.linspace(1e-6, cut, 300001)
    expected = ins.transmitter.pulse_energy_j * np.trapezoid(column_density_per_m(ins, water, z), z)
    assert np.trapezoid(model.column_power_w(t, cut), t) == pytest.approx(expected, rel=REL_TOL_TABLE)


def test_window_return_vanishes_for_non_coaxial_and_follows_eq3_for_coaxial():
    assert window_factor(mul2023()) == 0.0
    ins = coaxial()
    rx = ins.receiver
    assert window_factor(ins) == pytest.approx(min(1.0, rx.area_m2 / rx.window_distance_m**2) * 0.9 * 0.6 * 0.0039)
    far = replace(ins, receiver=replace(rx, window_distance_m=0.5))
    assert window_factor(far) == pytest.approx(rx.area_m2 / 0.25 * 0.9 * 0.6 * 0.0039)


@pytest.mark.parametrize("water", [paper("turbid_harbor"), water_preset("turbid_harbor")], ids=["eq4", "monte_carlo"])
def test_coaxial_column_is_stronger_near_field(water):
    """Single scattering (Eq. 4) and the Monte Carlo's column alike: the coaxial receiver sees the near field the
    offset one cannot. Under Eq. 4, far beyond both overlaps' plateau they see the same column; multiply scattered
    light keeps favouring the coaxial receiver for longer, so the Monte Carlo's columns only draw nearer."""
    t = np.arange(0.0, 200e-9, 0.25e-9)
    coax = OpticalModel.build(coaxial(), water).column_power_w(t)
    paraxial = OpticalModel.build(mul2023(), water).column_power_w(t)
    assert coax.max() > paraxial.max()
    # Far beyond full overlap both columns coincide (same optics, O = 1).
    far = t > 150e-9
    if water.attenuation_model == "k_lidar":
        assert coax[far] == pytest.approx(paraxial[far], rel=1e-4)
    else:
        ratio = coax / np.maximum(paraxial, 1e-300)
        near, later = (t > 30e-9) & (t < 40e-9), (t > 90e-9) & (t < 100e-9)
        assert np.all(coax[near | later] >= paraxial[near | later]) and ratio[later].mean() < ratio[near].mean() / 3


def test_background_terms_eqs_8_to_10():
    ins, water = mul2023(), paper("clean_ocean")
    assert np.all(background_power_w(ins, water, 0.0, [5.0], [0.1]) == 0.0)
    lb, z, rho = 1e-3, 5.0, 0.1
    rx = ins.receiver
    att = math.exp(-2 * water.k_lidar_per_m * z)
    common = lb * rx.area_m2 * rx.efficiency * 1.0 * att
    expected = common * rho * rx.fov_full_rad**2 / 4 + common * water.beta_pi_per_m_sr * math.pi * rx.fov_full_rad**2 / 4
    # powers of 1e-10 W: pytest.approx's default absolute tolerance (1e-12) would hide a 1 % error
    assert float(background_power_w(ins, water, lb, z, rho)[()]) == pytest.approx(expected, rel=1e-9, abs=0)
    # a 2 nm filter lets in twice the light (Eqs. 9, 10 are linear in the filter width)
    wide = replace(ins, receiver=replace(rx, filter_bandwidth_m=2e-9))
    assert float(background_power_w(wide, water, lb, z, rho)[()]) == pytest.approx(2 * expected, rel=1e-9, abs=0)
    # a pulse that meets nothing: no target term, the scattered term at the record's far end, c_w x 1 us / 2
    far = water.speed_m_s * 1e-6 / 2
    scatter_far = lb * rx.area_m2 * rx.efficiency * math.exp(-2 * water.k_lidar_per_m * far) * water.beta_pi_per_m_sr \
        * math.pi * rx.fov_full_rad**2 / 4
    got = background_power_w(ins, water, lb, np.array([np.inf, 5.0]), np.array([0.1, 0.1]))
    assert got[0] == pytest.approx(scatter_far, rel=1e-9, abs=0) and got[1] == pytest.approx(expected, rel=1e-9, abs=0)
    # linear in L_b (1 W/(m^2 sr nm) too), the shape of the ranges kept when dark, and any attenuation rule
    assert float(background_power_w(ins, water, 1.0, z, rho)[()]) == pytest.approx(1e3 * expected, rel=1e-9, abs=0)
    assert background_power_w(ins, water, 0.0, np.array([5.0, 6.0]), np.array([0.1, 0.1])).shape == (2,)
    from muls.optics.radiometry import lidar_attenuation_per_m

    small = water.with_models(attenuation_model="small_angle")
    k5 = float(lidar_attenuation_per_m(ins, small, 5.0))
    assert float(background_power_w(ins, small, lb, z, rho)[()]) == pytest.approx(
        expected * math.exp(-2 * (k5 - water.k_lidar_per_m) * z), rel=1e-9, abs=0)


@pytest.mark.parametrize("build, key", [
    (lambda: Water("bad", -0.1, 0.2), "absorption_per_m"),
    (lambda: Water.from_attenuation("bad", 0.1, 0.2), "absorption_per_m"),
    (lambda: Digitiser(bits=0), "digitizer.bits"),
    (lambda: Transmitter(pulse_energy_j=0.0), "transmitter.pulse_energy_j"),
    (lambda: water_preset("muddy"), "water"),
])
def test_bad_parameters_are_rejected_with_their_name(build, key):
    with pytest.raises(ParameterError, match=key.replace(".", r"\.")):
        build()


def test_reflectance_over_one_is_rejected():
    from muls.optics.optical_model import PulseBatch

    with pytest.raises(ParameterError, match="reflectance"):
        PulseBatch.flat_target(mul2023(), [5.0], 1.2)


# --- the small_angle attenuation rule (muls.water.smallangle) ---------------------------------------------------------

def _small_angle(water, fov_full_rad=0.1, ranges=(5.0, 10.0, 20.0)):
    from muls.optics.radiometry import lidar_attenuation_per_m

    ins = mul2023()
    ins = replace(ins, receiver=replace(ins.receiver, fov_full_rad=fov_full_rad))
    return lidar_attenuation_per_m(ins, water.with_models(attenuation_model="small_angle"), np.asarray(ranges))


def test_small_angle_rule_of_an_absorbing_water_is_its_absorption():
    """With no scattering there is nothing to keep: k = a = c at every range and field of view."""
    np.testing.assert_allclose(_small_angle(Water("absorbing", 0.2, 0.0)), 0.2, rtol=1e-9)
    np.testing.assert_allclose(_small_angle(Water("absorbing", 0.2, 0.0), fov_full_rad=1.0), 0.2, rtol=1e-9)


def test_small_angle_rule_at_low_optical_depth_is_single_scattering_kept_in_the_footprint():
    """Through the pool (b Z = 0.06 at 10 m) only single scattering counts: k = a + b (1 - s), s the share of
    single scattering that lands inside the footprint, int_0^1 F(theta_h / (1 - u)) du, computed directly
    from Petzold's cumulative distribution (a different path from the rule's Hankel integral)."""
    from muls.water.phase import petzold

    phase = petzold()
    u = (np.arange(4000) + 0.5) / 4000
    share = np.mean([phase.forward_fraction(min(0.05 / (1 - v), math.pi / 2)) for v in u])
    assert 0.55 < share < 0.65
    pool = water_preset("pool")
    expected = pool.absorption_per_m + pool.scattering_per_m * (1.0 - share)
    np.testing.assert_allclose(_small_angle(pool, ranges=(10.0,)), expected, rtol=2e-3)


def test_small_angle_rule_lies_between_c_and_the_fully_kept_limit_and_falls_as_the_field_widens():
    """A narrow field keeps little (k within 20 % of c: even 0.1 mrad holds part of Petzold's sharp forward
    peak); a wide one nearly all forward scattering (k near a + b_b, Petzold's b_b/b = 0.0183); in between k
    falls as the field of view widens, and in the pond as the range grows."""
    coastal = water_preset("coastal_ocean")
    a, b, c = coastal.absorption_per_m, coastal.scattering_per_m, coastal.attenuation_per_m
    narrow, medium, wide = (_small_angle(coastal, fov) for fov in (1e-4, 0.1, 1.5))
    assert np.all(narrow > 0.8 * c) and np.all(narrow <= c + 1e-9)
    assert np.all(wide < a + 0.0183 * b + 0.1 * b) and np.all(wide >= a + 0.0183 * b - 1e-3)
    assert np.all(narrow > medium) and np.all(medium > wide)
    pond = _small_angle(water_preset("pond"))
    assert np.all(np.diff(pond) < 0.0)  # more multiple scattering kept farther away


def test_small_angle_rule_keeps_more_through_a_wider_aperture():
    """The footprint is the aperture plus the field's spread (Eq. 11's r2 = d_r/2 + z tan(theta_r/2)): a wider
    aperture with the same field keeps more forward scattering, so k falls, most where the aperture is a large
    part of the footprint (close in: at 1 m it is 43 % of r2 for the 75 mm lens, 3 % at 20 m)."""
    from muls.optics.radiometry import lidar_attenuation_per_m

    pond = water_preset("pond").with_models(attenuation_model="small_angle")
    ins = mul2023()
    wide = replace(ins, receiver=replace(ins.receiver, area_m2=4.0 * ins.receiver.area_m2))  # twice the diameter
    ranges = np.array([1.0, 3.0, 20.0])
    k, k_wide = lidar_attenuation_per_m(ins, pond, ranges), lidar_attenuation_per_m(wide, pond, ranges)
    assert np.all(k_wide < k)
    gain = k - k_wide
    assert gain[0] > gain[2] > 0.0


@pytest.mark.slow
def test_small_angle_rule_against_the_monte_carlo():
    """The Monte Carlo reference (muls.montecarlo) through the MUL's geometry: in single-scattering waters the
    rule gives the echo's effective attenuation within 3 %; in the pond (b Z = 12 at 10 m) the approximation
    keeps more scattered light than the Monte Carlo (no longer paths, no scattering back from large angles):
    k lower, within 15 %."""
    from muls.montecarlo import TargetPlanes, run_monte_carlo
    from muls.validation import effective_attenuation_per_m, two_way_transmission

    ins = mul2023()
    for name, tol in (("coastal_ocean", 0.03), ("pond", 0.15)):
        water = water_preset(name)
        result = run_monte_carlo(ins, water, TargetPlanes((10.0,), 0.1), packets=100_000, seed=3)
        energy = float(result.target(0)[0].sum()) * ins.transmitter.pulse_energy_j * two_way_transmission(ins)
        k_mc = effective_attenuation_per_m(ins, 10.0, 0.1, water, energy)
        k_rule = float(_small_angle(water, ranges=(10.0,))[0])
        assert k_rule == pytest.approx(k_mc, rel=tol), name
        assert k_rule <= k_mc * 1.01


@pytest.mark.parametrize("model", ["eq11", "finite_aperture"])
def test_eq4_inside_the_first_metre_and_at_zero_range(model):
    """The coaxial receiver: Eq. 4's density is A_r beta_pi eta_t eta_o (1 - T_s)^2 exp(-2 k z) / z^2 with A_r / z^2
    capped at the field stop's pi tan^2(theta_r / 2): closer than sqrt(A_r / pi) / tan(0.05) = 0.75 m the z^2 is
    gone. Under Eq. 11 the cap is the collection limit; a finite aperture holds it already (a point on the axis is
    seen by the aperture points within z tan(theta_r / 2) of it), exactly where the whole spot lies within
    r_ap - z tan(theta_r / 2) of the axis (z <= 0.5 m) or every aperture point sees all of it (z >= 0.9 m); in
    between its own integral gives less. At zero and negative range there is no column."""
    ins, water = with_overlap(coaxial(), model), paper("pool")
    k = 0.050923  # Eq. 6 for the pool, worked by hand in tests/muls/test_photon_budget.py
    optics = 0.9 * 0.6 * (1 - 0.0039) ** 2
    for z in (0.3, 0.5, 0.9, 1.2):
        collected = min(math.pi * math.tan(0.05) ** 2, 4.4e-3 / z**2)
        assert float(column_density_per_m(ins, water, z)) == pytest.approx(
            collected * water.beta_pi_per_m_sr * optics * math.exp(-2 * k * z), rel=2e-3)
    for z in (0.0, -1.0):
        assert float(column_density_per_m(ins, water, z)) == 0.0


def test_eq7_inside_the_first_metre_and_at_zero_range():
    """Where Eq. 11's overlap is 1 from the window on (the coaxial receiver), Eq. 7 holds at 0.5 m as at any
    range; at zero and negative range there is no echo (0, never inf or NaN)."""
    ins, water = with_overlap(coaxial(), "eq11"), paper("pool")
    k = 0.050923  # Eq. 6 for the pool, worked by hand in tests/muls/test_photon_budget.py
    optics = 0.9 * 0.6 * (1 - 0.0039) ** 2
    for z in (0.3, 0.5, 0.7, 0.9):
        assert float(target_factor(ins, water, z, 0.01)) == pytest.approx(
            4.4e-3 * 0.01 * optics * math.exp(-2 * k * z) / z**2, rel=1e-4)
    for z in (0.0, -1.0):
        assert float(target_factor(ins, water, z, 0.01)) == 0.0


def test_lambertian_weight_follows_the_cosine_of_incidence():
    """A Lambertian plate tilted by theta returns cos(theta) of a normal one: half at 60 degrees, none at 90."""
    ins = mul2023()
    normal = float(lambertian_weight(ins, 6.0, 0.1))
    assert normal == pytest.approx(0.1 / math.pi * float(ins.geometry.overlap(6.0)))
    assert float(lambertian_weight(ins, 6.0, 0.1, math.radians(60.0))) == pytest.approx(0.5 * normal, rel=1e-12)
    assert float(lambertian_weight(ins, 6.0, 0.1, math.pi / 2)) == pytest.approx(0.0, abs=1e-15)
