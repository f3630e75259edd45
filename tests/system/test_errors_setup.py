"""Set-ups (docs/errors.md): physically impossible or useless set-ups are refused naming the key, or run with a
warning naming it (docs/errors.md says which), and a pass too large for the machine is refused from an
estimate made before anything pass-sized is allocated.
"""

import copy
import time
import tracemalloc
import warnings

import pytest
import yaml

from scanner_sim.cli import main
from scanner_sim.config import SCENES_DIR, ConfigError, load_scene, parse_scene
from scanner_sim.config.errors import SetupWarning
from scanner_sim.survey.setup import checked_trajectory
from scanner_sim.survey.sizing import MAX_LEGS, MAX_PASS_PULSES, check_pass_budget, estimate_pass
from scanner_sim.world.scene import build_scene

MINE_FIELD = yaml.safe_load((SCENES_DIR / "mine_field.yaml").read_text())


@pytest.fixture(scope="module")
def mine_scene():
    """mine_field's scene (seabed 20 x 12 m, 15 m deep; the moored sphere at [-5, 0.8]); its platform varies."""
    return build_scene(load_scene("mine_field"))


def _config(**changes):
    data = copy.deepcopy(MINE_FIELD)
    for key, value in changes.items():
        *sections, last = key.split(".")
        node = data
        for name in sections:
            node = node.setdefault(name, {})
        if value is None:
            node.pop(last, None)
        else:
            node[last] = value
    return parse_scene(data, base_dir=SCENES_DIR)


def _refused(match, scene=None, **changes):
    with pytest.raises(ConfigError) as exc:
        checked_trajectory(_config(**changes), scene)
    text = str(exc.value)
    assert "\n" not in text, text
    assert match in text, text
    return text


def _warned(match, scene, **changes):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        checked_trajectory(_config(**changes), scene)
    messages = [str(w.message) for w in caught if issubclass(w.category, SetupWarning)]
    assert any(match in m for m in messages), messages
    return messages


def test_shipped_scenes_pass_the_checks_without_warnings():
    for name in ("cable_survey", "mine_field", "seabed_lawnmower", "pool_panel", "pond_panel"):
        config = load_scene(name)
        with warnings.catch_warnings():
            warnings.simplefilter("error", SetupWarning)
            checked_trajectory(config, build_scene(config))


# -- refused when the file is read ---------------------------------------------------------------------------
@pytest.mark.parametrize("changes, match", [
    ({"platform.altitude_m": 300}, "platform.altitude_m = 300.0: puts the vehicle above the water surface: "
                                   "the seabed lies 15 m deep"),
    ({"platform.waypoints_m": [[2, 1], [2, 1], [2, 1]]}, "platform.waypoints_m = [[2.0, 1.0], [2.0, 1.0], [2.0, 1.0]]:"
                                                         " the points coincide"),
    ({"platform.altitude_m": None, "platform.depth_m": 40_000}, "platform.depth_m = 40000.0: deeper than any ocean"),
    ({"seabed.depth_m": 15_000}, "seabed.depth_m = 15000.0: deeper than any ocean"),
    ({"survey.seed": 2**63}, "survey.seed = 9223372036854775808: must be an integer >= 0 and <= 9223372036854775807"),
])
def test_impossible_values_refused_naming_the_key(changes, match):
    with pytest.raises(ConfigError) as exc:
        _config(**changes)
    assert match in str(exc.value), str(exc.value)


def test_static_vehicle_above_the_surface_and_coinciding_cable_points():
    pool = yaml.safe_load((SCENES_DIR / "pool_panel.yaml").read_text())
    pool["platform"]["position_m"] = [0, 0, 2.5]
    with pytest.raises(ConfigError, match=r"platform.position_m = \[0.0, 0.0, 2.5\]: z = 2.5 m is above the water"):
        parse_scene(pool)
    cable = yaml.safe_load((SCENES_DIR / "cable_survey.yaml").read_text())
    cable["objects"][0]["points_m"] = [[3, 1], [3, 1]]
    with pytest.raises(ConfigError, match=r"objects\[0\].points_m = .*the points coincide in plan"):
        parse_scene(cable)


# -- refused when the pass is set up -------------------------------------------------------------------------
def test_vehicle_above_the_surface_over_relief(mine_scene):
    _refused("platform.altitude_m = 14.9: the vehicle rises above the water surface (z = 0", mine_scene,
             **{"platform.altitude_m": 14.9})


def test_vehicle_under_the_seabed(mine_scene):
    _refused("platform.depth_m = 16.0: the vehicle goes", mine_scene,
             **{"platform.altitude_m": None, "platform.depth_m": 16})
    _refused("platform.altitude_m = 0.05: the vehicle goes", mine_scene, **{"platform.altitude_m": 0.05})


def test_vehicle_through_an_object(mine_scene):
    _refused("platform.waypoints_m: the vehicle passes through objects[0] ('moored_sphere')", mine_scene,
             **{"platform.altitude_m": 1.2, "platform.waypoints_m": [[-9, 0.8], [9, 0.8]]})


def test_track_that_never_passes_over_the_seabed(mine_scene):
    _refused("the track never passes over the seabed (x -10 to 10, y -6 to 6 m)", mine_scene,
             **{"platform.waypoints_m": [[100, 0], [120, 0]]})


def test_pass_that_starts_after_the_track_ends(mine_scene):
    _refused("survey.start_s = 1000.0: at or after the end of the track (36.0 s long", mine_scene,
             **{"survey.start_s": 1000})


def test_too_many_pulses_refused_before_anything_is_allocated(mine_scene):
    """A speed in the wrong unit makes a pass of 225 billion pulses: refused in well under a second, the
    trajectory never built (its path and noise grid would take hundreds of GB)."""
    tracemalloc.start()
    started = time.perf_counter()
    try:
        text = _refused("platform.speed_m_s = 1e-07: the pass would fire 225,000,000,000 pulses", mine_scene,
                        **{"platform.speed_m_s": 1e-7})
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.perf_counter() - started < 1.0 and peak < 50e6
    assert f"more than the {MAX_PASS_PULSES:,} one pass may" in text


def test_memory_estimate_names_the_key_that_drives_it():
    config = _config(**{"survey.chunk_pulses": 10**9})
    est = estimate_pass(config)
    assert est.memory["survey.chunk_pulses"][0] == 10**9 * (19 * 350 + 3_500)  # balanced: 19 sub-rays, windowed
    with pytest.raises(ConfigError) as exc:
        check_pass_budget(config, available_bytes=32 << 30)
    assert str(exc.value).startswith("survey.chunk_pulses = 1000000000: the pass would need about 10,150.0 GB of "
                                     "memory (chunks of 1,000,000,000 pulses x 19 sub-rays"), str(exc.value)
    big_seabed = _config(**{"seabed.size_m": [10_000, 10_000], "seabed.resolution_m": 10})
    with pytest.raises(ConfigError, match=r"seabed.size_m = \[10000.0, 10000.0\]: .*\(coverage over 1,600,000,000 cells"):
        check_pass_budget(big_seabed, available_bytes=32 << 30)
    check_pass_budget(load_scene("mine_field"), available_bytes=2 << 30)  # the shipped scene fits in 2 GB


def test_too_many_legs():
    config = _config(**{"platform.mode": "lawnmower", "platform.waypoints_m": None,
                        "platform.lawnmower": {"size_m": [10, 1000], "line_spacing_m": 0.01}})
    with pytest.raises(ConfigError, match=f"platform.lawnmower.line_spacing_m = 0.01: gives a track of 200,001 legs, "
                                          f"more than the {MAX_LEGS:,}"):
        check_pass_budget(config)


# -- run with a warning --------------------------------------------------------------------------------------
def test_track_partly_off_the_seabed_warns(mine_scene):
    _warned("platform.waypoints_m: 50% of the track lies off the seabed", mine_scene,
            **{"platform.waypoints_m": [[-20, 0], [20, 0]]})


def test_implausible_speed_warns(mine_scene):
    _warned("platform.speed_m_s = 50.0: faster than survey vehicles go", mine_scene, **{"platform.speed_m_s": 50})


def test_pass_past_the_end_of_the_track_warns(mine_scene):
    _warned("survey.duration_s = 100.0: the pass runs 64.0 s past the end of the track", mine_scene,
            **{"survey.duration_s": 100})


def test_seabed_beyond_any_echo_warns():
    config = _config(**{"platform.altitude_m": None, "platform.depth_m": 10, "seabed.depth_m": 3010,
                        "seabed.resolution_m": 0.5})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        checked_trajectory(config, build_scene(config))
    assert any("platform.depth_m = 10.0: the seabed lies about 3,000 m below the vehicle" in str(w.message)
               for w in caught)


def test_command_line_prints_refusals_and_warnings_as_one_line(tmp_path, capsys):
    data = copy.deepcopy(MINE_FIELD)
    data["platform"]["speed_m_s"] = 50
    (tmp_path / "assets").mkdir()
    (tmp_path / "assets" / "mooring_block.obj").write_text((SCENES_DIR / "assets" / "mooring_block.obj").read_text())
    (tmp_path / "fast.yaml").write_text(yaml.safe_dump(data))
    assert main(["validate", "--build", str(tmp_path / "fast.yaml")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["scanner-sim validate: warning: platform.speed_m_s = 50.0: faster than survey vehicles go (about "
                   "0.5 to 3 m/s, at most 10); speeds are in m/s, not km/h or knots"]
    data["platform"]["speed_m_s"] = 1e-7
    (tmp_path / "slow.yaml").write_text(yaml.safe_dump(data))
    assert main(["validate", "--build", str(tmp_path / "slow.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("scanner-sim validate: error: platform.speed_m_s = 1e-07: ")
