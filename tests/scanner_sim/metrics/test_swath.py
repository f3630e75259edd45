"""Swath-to-swath consistency (the open3d extra): a known offset between two lines, the command on the
lawnmower, and a clear error when the extra is missing."""

import builtins
import json
import os

import numpy as np
import pytest

from scanner_sim.metrics import swath
from scanner_sim.records.point_records import PointRecords

try:
    import open3d  # noqa: F401
except (ImportError, OSError):
    if os.environ.get("MULS_REQUIRE_OPEN3D"):
        raise
    pytest.skip("the open3d extra is not installed (CI installs it)", allow_module_level=True)


def _line(leg, x0, z, spacing=0.1, width=10.0, length=20.0):
    """A flat strip of points at height z [m], ``width`` across x from x0, ``length`` along y."""
    x, y = np.meshgrid(np.arange(x0, x0 + width, spacing), np.arange(0.0, length, spacing))
    n = x.size
    one = np.ones(n, int)
    return PointRecords(gps_time_s=np.zeros(n), xyz=np.c_[x.ravel(), y.ravel(), np.full(n, z)], intensity=one,
                        return_number=one, number_of_returns=one, classification=40 * one,
                        scan_angle_deg=np.zeros(n), channel=one, amplitude_lsb=np.zeros(n), snr=np.zeros(n),
                        saturated=np.zeros(n, bool), true_range_m=np.zeros(n), range_error_m=np.zeros(n),
                        incidence_deg=np.zeros(n), object_id=0 * one, leg=leg * one, pulse_index=np.arange(n))


def test_a_vertical_offset_between_lines_shows_as_their_mean_difference():
    """Line 3 lies 4 cm above line 1 on the same grid, overlapping half its width: the overlap is that half
    plus the fringe whose nearest neighbour is within 0.5 m (x >= 5 - sqrt(0.5^2 - 0.04^2) m), the median C2C
    distance is 4 cm, and the vertical difference 1 - 3 is -4 cm with no spread."""
    points = PointRecords.concatenate([_line(1, 0.0, 0.0), _line(2, 50.0, 0.0, width=1.0), _line(3, 5.0, 0.04)])
    assert swath.survey_lines(points, min_points=100) == [1, 3]
    (pair,) = swath.swath_consistency(points)
    assert pair["leg_a"] == 1 and pair["leg_b"] == 3
    line_1 = _line(1, 0.0, 0.0)
    assert pair["overlap_points"] == np.count_nonzero(line_1.xyz[:, 0] >= 5.0 - np.sqrt(0.5**2 - 0.04**2) + 1e-9)
    assert pair["c2c_median_m"] == pytest.approx(0.04, abs=1e-6)
    assert pair["dz_mean_m"] == pytest.approx(-0.04, abs=1e-6) and pair["dz_rms_m"] == pytest.approx(0.04, abs=1e-6)


def test_swath_command_on_the_lawnmower_prints_one_figure_per_pair_of_lines(tmp_path, capsys):
    from scanner_sim.cli import main

    assert main(["run", "seabed_lawnmower", "--set", "platform.speed_m_s=10", "--out", str(tmp_path),
                 "--quiet", "--no-render"]) == 0
    capsys.readouterr()
    assert main(["swath", str(tmp_path), "--json"]) == 0
    pairs = json.loads(capsys.readouterr().out)["pairs"]
    assert [(p["leg_a"], p["leg_b"]) for p in pairs] == [(1, 3), (3, 5), (5, 7), (7, 9)]
    for p in pairs:  # clean water, no navigation noise: lines agree to within the relief between neighbours
        assert p["overlap_points"] > 1000 and abs(p["dz_mean_m"]) < 0.03 and p["dz_rms_m"] < 0.2


def test_missing_open3d_names_the_extra(monkeypatch):
    real_import = builtins.__import__

    def no_open3d(name, *args, **kwargs):
        if name == "open3d":
            raise ImportError("No module named 'open3d'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_open3d)
    with pytest.raises(ImportError, match=r"muls-scanner\[open3d\]"):
        swath.open3d()
