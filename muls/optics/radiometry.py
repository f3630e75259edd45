"""Received power terms of the lidar equation: window (Eq. 3), column (Eq. 4), target (Eq. 7), background
(Eqs. 8-10). Functions are vectorised over their array arguments.

Energy form: the pulse shape is normalised to unit area (docs/design.md#pulse), so each echo is
E_t * F * w(t - delay) with F the dimensionless factor of its equation and P_t = E_t / dt replaced by
E_t * w(t). The peak-power forms of the paper follow by replacing E_t * w by P_t.
"""

from __future__ import annotations

import math

import numpy as np

from ..instrument.description import Instrument
from ..montecarlo.scattering_tables import ScatteringTables
from ..montecarlo.tables import find_or_build_tables
from ..water import smallangle
from ..water.properties import RANGE_DEPENDENT_MODELS, Water


def lidar_attenuation_per_m(instrument: Instrument, water: Water, range_m, tables: ScatteringTables | None = None):
    """The k of exp(-2 k z) in Eqs. 4, 7, 9, 10 for light scattered back at ``range_m`` [m] (any shape) [1/m].

    The water's ``attenuation_model`` decides: Eq. 6's k_lidar, c or K_d are constants; ``monte_carlo`` is the
    Monte Carlo reference's transmission for this water and receiver, range by range (:mod:`muls.montecarlo.scattering_tables`;
    ``tables``: those tables if the caller holds them, else they are found or built); ``small_angle`` keeps the
    forward scattering that stays inside the receiver's footprint r2(z) of Eq. 11 (:mod:`muls.water.smallangle`).
    docs/design.md#attenuation compares them. k is the lidar attenuation; the beam attenuation c is
    ``water.attenuation_per_m``.

    Parameters
    ----------
    instrument : Instrument
        Its receiver geometry sets the footprint of the ``small_angle`` and ``monte_carlo`` rules.
    water : Water
        The water and its ``attenuation_model``.
    range_m : float or array_like, any shape
        One-way ranges [m].
    tables : ScatteringTables, optional
        The Monte Carlo's tables of this water and receiver, if the caller holds them.

    Returns
    -------
    numpy.ndarray, the shape of ``range_m``
        k [1/m].
    """
    r = np.asarray(range_m, dtype=float)
    if water.attenuation_model not in RANGE_DEPENDENT_MODELS:
        return np.full(r.shape, water.two_way_attenuation_per_m)
    g = instrument.geometry
    if water.attenuation_model == "monte_carlo":
        if tables is None:
            tables = find_or_build_tables(g, water)
        return tables.lidar_attenuation_per_m(r)
    return smallangle.lidar_attenuation_per_m(water.attenuation_per_m, water.scattering_per_m, 0.5 * g.receiver_diameter_m,
                                        math.tan(0.5 * g.fov_full_rad), r)


def two_way_transmission(instrument: Instrument) -> float:
    """eta_t eta_o (1 - T_s)^2: optics and the window crossed out and back [-]."""
    rx, tx = instrument.receiver, instrument.transmitter
    return tx.efficiency * rx.efficiency * (1.0 - rx.window_reflectance) ** 2


def target_factor(instrument: Instrument, water: Water, range_m, weight_per_sr, tables: ScatteringTables | None = None):
    """Echo energy over emitted energy for hits at ``range_m`` [m] (any shape).

    weight_per_sr = sum over the footprint of w_j (rho_j / pi) cos(theta_j) times the receiver weight,
    which for a flat Lambertian plate at normal incidence is (rho / pi) O(Z), giving exactly Eq. 7.
    ``tables``: as :func:`lidar_attenuation_per_m`.
    """
    r = np.asarray(range_m, dtype=float)
    k = lidar_attenuation_per_m(instrument, water, r, tables)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = (instrument.receiver.area_m2 * np.asarray(weight_per_sr, float) * two_way_transmission(instrument)
             * np.exp(-2.0 * k * r) / r**2)  # MULS Eq. 7
    return np.where(r > 0.0, f, 0.0)


def lambertian_weight(instrument: Instrument, range_m, reflectance, incidence_rad=0.0):
    """weight_per_sr of a flat Lambertian target filling the beam: (rho / pi) cos(theta) O(Z) (Eq. 7, 11)."""
    return (np.asarray(reflectance, float) / np.pi * np.cos(incidence_rad)
            * instrument.geometry.overlap(range_m))


def column_density_per_m(instrument: Instrument, water: Water, z_m, tables: ScatteringTables | None = None):
    """Water-column backscatter per unit range, over emitted energy [1/m] (MULS Eq. 4), single scattering.

    The column power is P_C(t) = E_t integral of this (z) w(t - 2 z / c_w) dz. The receiver's field-stop
    limit (``TransceiverGeometry.collection_limit``) keeps A_r O(z) / z^2 finite near the window. ``tables``: as
    :func:`lidar_attenuation_per_m`.
    """
    z = np.asarray(z_m, dtype=float)
    geometry = instrument.geometry
    k = lidar_attenuation_per_m(instrument, water, z, tables)
    with np.errstate(divide="ignore", invalid="ignore"):
        density = (instrument.receiver.area_m2 * geometry.overlap(z) * geometry.collection_limit(z)
                   * water.beta_pi_per_m_sr * two_way_transmission(instrument) * np.exp(-2.0 * k * z) / z**2)  # MULS Eq. 4
    return np.where(z > 0.0, density, 0.0)


def window_factor(instrument: Instrument) -> float:
    """Window return energy over emitted energy [-] (MULS Eq. 3); 0 for non-coaxial optics (O = 0).

    A_r / D^2 is the share of the window's reflection the receiver collects; it is capped at 1 (a window
    closer than sqrt(A_r) cannot return more than it reflects).
    """
    rx, tx = instrument.receiver, instrument.transmitter
    collected = min(1.0, rx.area_m2 / rx.window_distance_m**2)
    return collected * rx.window_coupling * tx.efficiency * rx.efficiency * rx.window_reflectance  # MULS Eq. 3


def background_power_w(instrument: Instrument, water: Water, spectral_radiance_w_m2_sr_nm: float,
                       range_m, reflectance, tables: ScatteringTables | None = None):
    """Background light power [W] (MULS Eqs. 8-10) for targets at ``range_m`` with ``reflectance``.

    spectral_radiance_w_m2_sr_nm: L_b of the artificial light [W/(m^2 sr nm)]; 0 in deep, dark water.
    A pulse that meets nothing has no target term; its scattered term uses the record's far end. ``tables``: as
    :func:`lidar_attenuation_per_m`.
    """
    if spectral_radiance_w_m2_sr_nm == 0.0:
        return np.zeros(np.shape(range_m))
    rx = instrument.receiver
    theta_r = rx.fov_full_rad
    band_nm = rx.filter_bandwidth_m * 1e9
    r = np.asarray(range_m, dtype=float)
    far = water.speed_m_s * instrument.digitizer.record_length_s / 2.0
    r = np.where(np.isfinite(r), r, far)
    rho = np.where(np.isfinite(np.asarray(range_m, float)), reflectance, 0.0)
    attenuation = np.exp(-2.0 * lidar_attenuation_per_m(instrument, water, r, tables) * r)
    common = spectral_radiance_w_m2_sr_nm * rx.area_m2 * rx.efficiency * band_nm * attenuation
    p_target = common * rho * theta_r**2 / 4.0  # MULS Eq. 9
    p_scatter = common * water.beta_pi_per_m_sr * np.pi * theta_r**2 / 4.0  # MULS Eq. 10
    return p_target + p_scatter  # MULS Eq. 8
