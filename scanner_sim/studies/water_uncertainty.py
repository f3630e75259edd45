"""Coverage as a band over a water's unknown phase function (``scanner-sim coverage --water-uncertainty``).

A preset water names c and a (or a, b) and, by assumption, Petzold's average phase function. For each combination
of the coverage study, the members of the sensitivity family (:data:`muls.water.phase_family.SENSITIVITY_FAMILY`)
are ranked by the echo energy the model gives a flat 0.1 plate at the nadir range (the vehicle's altitude; quick
table runs, :func:`muls.studies.sensitivity.member_tables`); the weakest and the strongest then fly the same pass
as the default (standard tables, the ones any pass of that water would use). The band is (low, default, high): the
pass with the weakest echo, Petzold's, the one with the strongest.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from muls.optics.optical_model import OpticalModel
from muls.studies.bands import BAND_PACKETS
from muls.studies.sensitivity import echo_quantities, member_tables
from muls.water.phase_family import SENSITIVITY_FAMILY, PhaseMember
from scanner_sim.config import SceneConfig

#: The family a band runs over, and the packets of the table runs that rank its members.
FAMILY = SENSITIVITY_FAMILY
RANKING_PACKETS = BAND_PACKETS
#: Reflectance of the plate that ranks the members (the studies' panel).
RANKING_REFLECTANCE = 0.1
#: The S-44 order whose compliant share the band reports beside the covered share.
BAND_ORDER = "1a"


def extreme_members(config: SceneConfig, range_m: float, family: tuple[PhaseMember, ...] | None = None,
                    packets: int | None = None) -> tuple[PhaseMember, PhaseMember]:
    """(weakest, strongest) members of ``family`` (default :data:`FAMILY`) by the echo energy of a flat plate at
    ``range_m`` [m] in the scene's water seen by its instrument, ranked on table runs of ``packets`` (default
    :data:`RANKING_PACKETS`)."""
    family = FAMILY if family is None else family
    packets = RANKING_PACKETS if packets is None else packets
    water = config.water_model()
    instrument = config.instrument_model()
    energy = []
    for member in family:
        tables = member_tables(water, member, packets, geometry=instrument.geometry)
        model = OpticalModel.build(instrument, replace(water, phase_function=member.spec), tables=tables)
        energy.append(float(echo_quantities(model, np.array([float(range_m)]), RANKING_REFLECTANCE)
                            ["echo_energy_j"][0]))
    return family[int(np.argmin(energy))], family[int(np.argmax(energy))]


def member_config(config: SceneConfig, member: PhaseMember) -> SceneConfig:
    """The combination's scene with the water's phase function set to ``member``'s."""
    return config.with_overrides({"water.phase_function": member.spec})


def band_figures(default: dict, low: dict, high: dict, low_member: PhaseMember, high_member: PhaseMember) -> dict:
    """The band of a combination from its three pass summaries' coverage: covered share of the reached area and the
    S-44 Order 1a compliant share, each (low, default, high), with the members that gave low and high."""

    def figures(summary):
        coverage = summary["coverage"]
        return coverage["covered_fraction"], coverage["orders"][BAND_ORDER]["compliant_fraction"]

    (c_lo, o_lo), (c_def, o_def), (c_hi, o_hi) = figures(low), figures(default), figures(high)
    return {"phase_function": "petzold (default)", "band": True,
            "low_member": {"label": low_member.label, "spec": low_member.spec, "source": low_member.source},
            "high_member": {"label": high_member.label, "spec": high_member.spec, "source": high_member.source},
            "covered_fraction": [c_lo, c_def, c_hi],
            f"order_{BAND_ORDER}_fraction": [o_lo, o_def, o_hi],
            "ranked_by": f"echo energy of a flat {RANKING_REFLECTANCE:g} plate at the nadir range over "
                         f"{len(FAMILY)} phase functions"}
