"""Features no pulse reached (scanner_sim/metrics/coverage.py, scanner_sim/survey/feature_placement.py): a cube hidden by
another is `shadowed`, one outside the reached swath `not_reached`, both counted apart from the detection rate."""

import pytest

import scanner_sim
from scanner_sim.config import load_scene
from scanner_sim.metrics.feature_cubes import detection_table, with_cubes

# cable_survey: track along y = 0 from x = -12 at 6 m altitude, a 90 degree scan sector (reach y = +-6 m on a flat
# seabed); 25,000 pulses at 5 kHz and 0.6 m/s fly x = -12 to -9.
PULSES = 25000
BIG = {"name": "big", "size_m": 2.0, "x_m": -10.5, "y_m": 3.0, "heading_deg": 0.0}
# Behind the big cube as seen from the track: a beam from (y 0, 6 m up) to the small cube's top (y 4.35-4.85,
# 0.5 m up) is 0.94-1.46 m up at y = 4, inside the 2 m cube (y 2-4).
HIDDEN = {"name": "hidden", "size_m": 0.5, "x_m": -10.5, "y_m": 4.6, "heading_deg": 0.0}
# Beyond the swath's edge: the outermost beam (45 degrees) meets the seabed at y = 6 m and is 0.5 m up at y = 5.5 m.
OUTSIDE = {"name": "outside", "size_m": 0.5, "x_m": -10.5, "y_m": 6.6, "heading_deg": 0.0}


@pytest.fixture(scope="module")
def objects():
    config = with_cubes(load_scene("cable_survey").with_overrides({"water": "clean_ocean"}), [BIG, HIDDEN, OUTSIDE])
    result = scanner_sim.simulate_pass(config, scanner_sim.PassOptions(max_pulses=PULSES, progress=False))
    return {o["name"]: o for o in result.summary["coverage"]["objects"]}


def test_a_cube_no_pulse_reached_is_shadowed_or_not_reached_not_few_soundings(objects):
    """Cubes that no pulse reached (one in the shadow of a placed 2 m cube, one beyond the swath) were counted as
    `few_soundings` misses, which means pulses reached them and too few of their points were valid. Root cause: an
    object's gap cause was `few_soundings` for every undetected object that no failing pulse reached."""
    assert objects["big"]["detected"]
    hidden, outside = objects["hidden"], objects["outside"]
    assert hidden["reaching_pulses"] == 0 and hidden["shadowing_pulses"] > 100
    assert hidden["gap_cause"] == "shadowed"
    assert outside["reaching_pulses"] == 0 and outside["shadowing_pulses"] == 0
    assert outside["gap_cause"] == "not_reached"


def test_cubes_no_pulse_reached_are_counted_apart_from_the_detection_rate(objects):
    table = detection_table(list(objects.values()), [BIG, HIDDEN, OUTSIDE])
    assert table["0.5"] == {"placed": 2, "not_reached": 1, "shadowed": 1, "reached": 0, "detected": 0,
                            "fraction": None, "valid_soundings": [0, 0]}
    assert table["2"]["reached"] == 1 and table["2"]["fraction"] == 1.0


def test_cubes_are_placed_where_the_scan_reaches_the_seabed_out_of_other_objects_shadows():
    """Cubes were placed anywhere inside the swath planned over a flat seabed, so one could stand in another
    object's shadow (or under it) and no pulse reach it. Root cause: the placement looked at the planned swath
    alone. Now it maps where a sample of the pass's beam axes meets the actual seabed first and keeps cubes out of
    each other's shadow. Two 2 m cubes beside the track hide 4 m of the swath's width over 2 m of track; the 0.5 m
    cubes placed around them are all reached."""
    from scanner_sim.metrics.coverage import NOT_REACHED_OBJECT, SHADOWED
    from scanner_sim.survey.feature_placement import cube_positions

    walls = [BIG, {**BIG, "name": "big_south", "y_m": -3.0}]
    config = with_cubes(load_scene("cable_survey").with_overrides({"water": "clean_ocean"}), walls)
    placed = cube_positions(config, [0.5], 6, seed=5, max_pulses=PULSES)
    result = scanner_sim.simulate_pass(with_cubes(config, placed),
                                       scanner_sim.PassOptions(max_pulses=PULSES, progress=False))
    objects = {o["name"]: o for o in result.summary["coverage"]["objects"]}
    for p in placed:
        assert objects[p["name"]]["reaching_pulses"] > 0, p
        assert objects[p["name"]]["gap_cause"] not in (NOT_REACHED_OBJECT, SHADOWED)
