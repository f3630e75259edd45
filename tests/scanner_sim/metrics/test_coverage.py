"""Coverage arithmetic (docs/coverage.md) on constructed cases counted by hand, then on real passes."""

import numpy as np
import pytest

from muls.infra.errors import ParameterError
from scanner_sim.config import load_scene, parse_scene
from scanner_sim.metrics.coverage import (
    COVERED,
    GAP_CAUSES,
    NOT_REACHED,
    CableBins,
    CoverageAccumulator,
    CoverageSettings,
    Footprint,
    PlanGrid,
)
from scanner_sim.records.point_records import DROPOUT_CAUSES, DropoutRecords, PointRecords
from scanner_sim.survey.pipeline import run_pass
from scanner_sim.survey.setup import PassOptions
from scanner_sim.world.scene import build_scene

CELL = 0.25


def _flat_scene(objects=()):
    """A flat 2 m x 1 m seabed at z = -10 (corner at the origin): 8 x 4 cells of 0.25 m."""
    return build_scene(parse_scene({
        "format_version": 1, "name": "flat",
        "seabed": {"size_m": [2, 1], "center_m": [1, 0.5], "resolution_m": 0.05, "depth_m": 10, "seed": 1,
                   "relief": {"rms_m": 0.0}, "ripples": {"amplitude_m": 0.0}, "rocks": {"count": 0}},
        "objects": list(objects),
        "platform": {"mode": "static", "position_m": [1, 0.5, -5]},
        "survey": {"max_pulses": 10},
    }))


def _centre(ix, iy):
    return [(ix + 0.5) * CELL, (iy + 0.5) * CELL, -10.0]


def _points(pulse, error_m, object_id=0):
    n = len(pulse)
    z, one = np.zeros(n), np.ones(n, np.int64)
    return PointRecords(gps_time_s=z, xyz=np.zeros((n, 3)), intensity=0 * one, return_number=one,
                        number_of_returns=one, classification=40 * one, scan_angle_deg=z,
                        channel=one, amplitude_lsb=z, snr=z, saturated=np.zeros(n, bool),
                        true_range_m=np.full(n, 5.0), range_error_m=error_m, incidence_deg=z,
                        object_id=np.broadcast_to(object_id, (n,)), leg=one, pulse_index=pulse)


def _dropouts(pulse, causes):
    n = len(pulse)
    return DropoutRecords(pulse_index=pulse, time_s=np.zeros(n), origin=np.zeros((n, 3)),
                          direction=np.tile([0.0, 0.0, -1.0], (n, 1)),
                          cause=[DROPOUT_CAUSES.index(c) for c in causes])


def _footprint(xyz_or_none, object_id=0):
    hit = np.array([p is not None for p in xyz_or_none])
    xyz = np.array([p if p is not None else [np.nan] * 3 for p in xyz_or_none], float)
    return Footprint(xyz, np.where(hit, np.broadcast_to(object_id, hit.shape), -1))


def test_plan_grid_cells_edges_and_outside():
    grid = PlanGrid.over((0.0, 2.0), (0.0, 1.0), CELL)
    assert grid.shape == (4, 8) and grid.size == 32
    assert grid.extent_m == (0.0, 2.0, 0.0, 1.0)
    xy = np.array([[0.0, 0.0], [0.2499, 0.0], [0.25, 0.0], [1.99, 0.99], [2.0, 0.5], [-0.01, 0.5], [np.nan, 0.5],
                   [0.3, 0.6]])
    # lower and left edges belong to the cell; the grid's upper edge is outside; row = y, column = x
    assert grid.index(xy).tolist() == [0, 0, 1, 31, -1, -1, -1, 2 * 8 + 1]
    assert PlanGrid.over((0.0, 2.1), (0.0, 1.0), CELL).shape == (4, 9)  # a partial cell is a cell


def test_hand_counted_pattern_on_a_flat_seabed():
    """Eleven pulses in six cells; every cell's state, the areas, holes and gap causes counted by hand."""
    scene = _flat_scene()
    acc = CoverageAccumulator(scene, CoverageSettings(cell_m=CELL, min_points=1, tolerance_m=0.15))
    assert acc.grid.shape == (4, 8)
    #            pulse: 0          1          2          3          4          5          6          7
    aim = [_centre(0, 0), _centre(0, 0), _centre(3, 1), _centre(4, 1), _centre(4, 1), _centre(4, 1),
           #        8           9     10
           _centre(7, 3), _centre(1, 2), None]
    aim += [_centre(1, 2), _centre(1, 2)]  # pulses 11, 12 also in cell (1, 2)
    slots = np.arange(100, 100 + len(aim))  # pass slots, not chunk positions
    footprint = _footprint(aim)
    # cell (0,0): pulse 0 two valid returns, pulse 1 a valid one    -> covered, 3 valid points
    # cell (3,1): pulse 2 below threshold                           -> missed, below_threshold
    # cell (4,1): pulse 3 masked, pulses 4 and 5 saturated           -> missed, saturated (most pulses)
    # cell (7,3): pulse 6 a point 0.3 m off                          -> missed, out_of_tolerance
    # cell (1,2): pulse 7 NaN error, 9 valid, 10 below threshold     -> covered, 1 valid point
    # pulse 8: no nominal hit (no cell), its point counts nowhere
    points = _points(slots[[0, 0, 1, 6, 7, 8, 9]], np.array([0.01, -0.14, 0.0, 0.3, np.nan, 0.0, 0.02]))
    dropouts = _dropouts(slots[[2, 3, 4, 5, 10]], ["below_threshold", "masked_by_backscatter", "saturated",
                                                    "saturated", "below_threshold"])
    acc.add(slots, footprint, points, dropouts)

    state = acc.cell_states()
    expected = np.full((4, 8), NOT_REACHED)
    expected[0, 0] = expected[2, 1] = COVERED
    expected[1, 3] = GAP_CAUSES.index("below_threshold")
    expected[1, 4] = GAP_CAUSES.index("saturated")
    expected[3, 7] = GAP_CAUSES.index("out_of_tolerance")
    assert np.array_equal(state, expected)
    assert acc.cells.valid.reshape(4, 8)[0, 0] == 3 and acc.cells.valid.reshape(4, 8)[2, 1] == 1
    assert acc.cells.reaching.sum() == 10  # pulse 8 reaches nothing

    f = acc.figures()
    a = CELL ** 2
    assert f["reached_area_m2"] == pytest.approx(5 * a)
    assert f["covered_area_m2"] == pytest.approx(2 * a)
    assert f["covered_fraction"] == pytest.approx(2 / 5)
    assert f["valid_points_in_reach"] == 4
    assert f["density_pts_per_m2"] == pytest.approx(4 / (5 * a))
    assert f["median_density_covered_pts_per_m2"] == pytest.approx(2 / a)  # median of 3 and 1 points
    # (3,1) and (4,1) touch: one hole of two cells; (7,3) alone: a second
    assert f["holes"] == {"count": 2, "largest_m2": pytest.approx(2 * a), "total_m2": pytest.approx(3 * a)}
    gaps = f["gaps_m2"]
    assert gaps["below_threshold"] == gaps["saturated"] == gaps["out_of_tolerance"] == pytest.approx(a)
    assert sum(gaps.values()) == pytest.approx(f["reached_area_m2"] - f["covered_area_m2"])


def test_min_points_raises_the_bar_for_reach_and_cover():
    scene = _flat_scene()
    acc = CoverageAccumulator(scene, CoverageSettings(cell_m=CELL, min_points=2))
    aim = [_centre(0, 0)] * 3 + [_centre(1, 0)] * 2 + [_centre(2, 0)]
    slots = np.arange(len(aim))
    # cell (0,0): 3 pulses, 2 valid -> covered; cell (1,0): 2 pulses, 1 valid -> missed; (2,0): 1 pulse -> not reached
    acc.add(slots, _footprint(aim), _points(slots[[0, 1, 3, 5]], np.zeros(4)),
            _dropouts(slots[[2, 4]], ["below_threshold", "outside_gate"]))
    state = acc.cell_states()[0]
    assert state[0] == COVERED
    assert state[1] == GAP_CAUSES.index("outside_gate")
    assert state[2] == NOT_REACHED


def test_chunks_add_up_to_the_whole():
    scene = _flat_scene()
    rng = np.random.default_rng(4)
    n = 400
    aim = [[x, y, -10.0] for x, y in rng.uniform([0, 0], [2, 1], (n, 2))]
    slots = np.arange(n)
    good = rng.random(n) < 0.7
    errors = np.where(rng.random(n) < 0.9, 0.01, 0.5)
    whole = CoverageAccumulator(scene)
    whole.add(slots, _footprint(aim), _points(slots[good], errors[good]),
              _dropouts(slots[~good], ["below_threshold"] * int((~good).sum())))
    parts = CoverageAccumulator(scene)
    for lo, hi in ((0, 150), (150, 151), (151, n)):
        s = slice(lo, hi)
        g = good[s]
        parts.add(slots[s], _footprint(aim[lo:hi]), _points(slots[s][g], errors[s][g]),
                  _dropouts(slots[s][~g], ["below_threshold"] * int((~g).sum())))
    assert np.array_equal(whole.cell_states(), parts.cell_states())
    assert whole.figures() == parts.figures()


def test_cable_stretches_and_objects():
    cable = {"type": "cable", "name": "c", "points_m": [[0.1, 0.5], [1.9, 0.5]], "diameter_m": 0.05,
             "burial_fraction": 0.0, "material": "polyethylene"}
    mine = {"type": "cone_mine", "name": "m", "position_m": [1.0, 0.2], "bottom_radius_m": 0.1,
            "top_radius_m": 0.05, "height_m": 0.1}
    scene = _flat_scene([cable, mine])
    cable_id, mine_id = scene.object_named("c").object_id, scene.object_named("m").object_id
    line = scene.object_named("c").centreline
    acc = CoverageAccumulator(scene, CoverageSettings(cell_m=CELL))
    bins = acc.cables[0][1]
    assert bins.length_m == pytest.approx(1.8, abs=1e-6)
    assert bins.n_bins == 8 and bins.stretch_length_m[-1] == pytest.approx(0.05, abs=1e-6)
    # Cable: pulses aimed at stretches 0 and 3; stretch 0 gives a valid cable point, stretch 3 gives a valid
    # point labelled seabed (its echo came from the seabed) -> other_surface. Mine: 2 pulses, 2 valid points.
    on = lambda x: line[np.argmin(np.abs(line[:, 0] - x))]  # noqa: E731
    aim = [on(0.2), on(0.95), [1.0, 0.2, -9.9], [1.0, 0.2, -9.9]]
    objects = np.array([cable_id, cable_id, mine_id, mine_id])
    slots = np.arange(4)
    points = _points(slots, np.zeros(4), object_id=np.array([cable_id, 0, mine_id, mine_id]))
    points = PointRecords(**{**points.as_dict(), "xyz": np.array(aim)})
    acc.add(slots, Footprint(np.array(aim), objects), points, _dropouts(np.zeros(0, int), []))
    f = acc.figures()
    (c,) = f["cables"]
    assert c["reached_m"] == pytest.approx(2 * CELL) and c["covered_m"] == pytest.approx(CELL)
    assert c["covered_fraction"] == pytest.approx(0.5)
    assert c["gaps_m"]["other_surface"] == pytest.approx(CELL)
    (m,) = [o for o in f["objects"] if o["name"] == "m"]
    # two valid points are not a detection: the rule asks five (scanner_sim.metrics.s44.FEATURE_MIN_SOUNDINGS)
    assert (m["reaching_pulses"], m["valid_points"], m["detected"], m["gap_cause"]) == (2, 2, False, "few_soundings")


def test_cable_bins_straight_line():
    line = np.c_[np.linspace(0, 1.1, 23), np.zeros(23), np.zeros(23)]
    bins = CableBins(line, 0.25)
    assert bins.n_bins == 5
    assert bins.stretch_length_m == pytest.approx([0.25, 0.25, 0.25, 0.25, 0.1])
    assert bins.index([[0.6, 0.3, 0.0], [1.09, 0.0, 0.0], [0.0, 0.0, 0.0]]).tolist() == [2, 4, 0]


@pytest.mark.parametrize("kw, key", [({"cell_m": 0.0}, "cell_m"), ({"min_points": 0}, "min_points"),
                                     ({"tolerance_m": float("nan")}, "tolerance_m"), ({"min_points": 1.5}, "min_points")])
def test_bad_settings_name_the_key(kw, key):
    with pytest.raises(ParameterError, match=key):
        CoverageSettings(**kw)


def test_scene_without_seabed_has_no_coverage(tmp_path):
    with pytest.raises(ParameterError, match="no seabed"):
        CoverageAccumulator(build_scene(load_scene("pool_panel")))
    summary = run_pass(load_scene("pool_panel"), tmp_path,
                       PassOptions(max_pulses=50, progress=False, render=False)).summary
    assert "coverage" not in summary and not (tmp_path / "coverage_grid.npz").exists()


def test_pass_coverage_is_consistent_with_its_counts(tmp_path):
    """A short real pass: every missed cell has a cause, gaps add up, reaching pulses <= pulses."""
    config = load_scene("cable_survey")
    summary = run_pass(config, tmp_path, PassOptions(max_pulses=6000, progress=False, render=False)).summary
    f = summary["coverage"]
    assert 0.0 < f["covered_fraction"] <= 1.0
    assert sum(f["gaps_m2"].values()) == pytest.approx(f["reached_area_m2"] - f["covered_area_m2"])
    from scanner_sim.io import read_coverage_grid_npz

    grid = read_coverage_grid_npz(tmp_path / "coverage_grid.npz")
    assert grid["reaching"].sum() <= summary["pulses"]
    assert grid["valid"].sum() <= summary["points"]
    reached = grid["reaching"] >= 1
    assert np.array_equal(grid["state"] != NOT_REACHED, reached)
    assert np.all(grid["state"][reached & (grid["valid"] == 0)] >= 0)  # every gap has a cause
