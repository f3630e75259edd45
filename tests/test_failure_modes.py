"""The places where the methods fail, each built from the scene format: a test per failure of issue 12, named
after it, with its root cause in the docstring (docs/fidelity.md tables their sizes)."""

import numpy as np
import pytest

from scanner_sim.config import parse_scene
from scanner_sim.survey import PassSetup

LIDAR_Z = -1.0


def _panel(name, centre, size, material="carbonate_sand", label="panel", normal=(0, 0, 1)):
    return {"type": "panel", "name": name, "center_m": list(centre), "size_m": list(size), "normal": list(normal),
            "label": label, "material": material}


def _static_scene(objects, water="coastal_ocean", fidelity="balanced", pulses=500, instrument=None, aim_deg=0.0,
                  seed=2):
    """A static lidar at z = -1 m aiming ``aim_deg`` from nadir at ``objects``."""
    return parse_scene({
        "format_version": 1, "name": "failure", "water": water,
        **({"instrument": instrument} if instrument else {}),
        "objects": objects, "platform": {"mode": "static", "position_m": [0.0, 0.0, LIDAR_Z]},
        "scanner": {"mode": "static", "aim_deg": aim_deg},
        "survey": {"max_pulses": pulses, "fidelity": fidelity, "seed": seed},
    })


def _points(config, record_mode=None):
    setup = PassSetup.build(config)
    return setup.simulate_chunk(np.concatenate(list(setup.slot_chunks())), record_mode=record_mode).points


# -- 1. the blind-zone edge -------------------------------------------------------------------------------------
#: The far channel's gate open from the start (0 ns), as a user ranging close targets would set it.
OPEN_GATE = {"preset": "mul2023", "gate_delay_ns": 0, "gate_width_ns": 400}


@pytest.mark.parametrize("fidelity", ["fast", "balanced", "reference"])
@pytest.mark.parametrize("distance_m", [1.6, 1.7, 1.75, 1.8, 2.0, 2.5])
def test_regression_no_phantom_returns_at_the_blind_zone_edge(distance_m, fidelity):
    """Root cause: on the far channel (CH3, gain ~5,000 times CH2's) a sand plate at 1.75 m clips for tens of
    nanoseconds, and the column behind the echo clips CH3 on its own from about 1.8 m on (the channel is
    blind there). The clipped plateau ran into those blind samples, where the residual is set to zero, so the
    plateau looked a few samples wide: its amplitude came out below the clip level and its time at the
    plateau's start, a phantom return 0.5 m in front of the plate, a 4.8 ns earlier return than the merge window
    (4 ns) joins (1,440 points from 1,000 pulses). A plateau that runs into blind samples has no known width
    and is not ranged on that channel now; the near channels range the plate."""
    plate_z = LIDAR_Z - distance_m
    points = _points(_static_scene([_panel("plate", (0, 0, plate_z), (3, 3))], fidelity=fidelity,
                                   instrument=OPEN_GATE, pulses=400))
    assert len(points) <= 400  # one return per pulse at most: a single plate
    assert np.all(np.abs(points.xyz[:, 2] - plate_z) < 0.15)


# -- 3. a surface the receiver cannot see -------------------------------------------------------------------
@pytest.mark.parametrize("fidelity", ["fast", "balanced", "reference"])
def test_regression_no_level_puts_points_on_a_surface_the_receiver_cannot_see(fidelity):
    """Root cause: ``fast`` checked each hit against the receiver's FOV cone only, without shadow rays, so a plate
    that a visor hides from the receiver (13 cm beside the beam) but not from the beam gave a point on every
    pulse (300 of 300 here). Every level now casts shadow rays (docs/fidelity.md: they cost ``fast`` a few per
    cent); the plate gives no point at any level."""
    visor = _panel("visor", (0, 0.3, LIDAR_Z - 0.5), (1.0, 0.5), material="black_painted_aluminium", label="debris")
    points = _points(_static_scene([_panel("plate", (0, 0, -6.0), (3, 3)), visor], water="pool", fidelity=fidelity,
                                   pulses=300))
    assert len(points) == 0
