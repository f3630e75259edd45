"""report.html of a coverage study embeds the interactive 3-D view of the pass ``--view-pass`` names, in the page."""

from __future__ import annotations

import contextlib
import html
import io as stdio
import json
import re

import pytest

from scanner_sim.cli import main


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """Two waters at 6 m, 2000 pulses each, the second water's pass chosen for the view."""
    out = tmp_path_factory.mktemp("study") / "study"
    with contextlib.redirect_stdout(stdio.StringIO()):
        assert main(["coverage", "cable_survey", "--waters", "clean_ocean", "turbid_harbor", "--instruments", "mul2023",
                     "--altitudes-m", "6", "--max-pulses", "2000", "--out", str(out), "--quiet", "--workers", "0",
                     "--view-pass", "turbid_harbor-mul2023-6m"]) == 0
    return out


def test_report_embeds_the_chosen_pass_view(study):
    from scanner_sim.io import read_las

    text = (study / "report.html").read_text(encoding="utf-8")
    assert json.loads((study / "coverage.json").read_text())["view_pass"] == "turbid_harbor-mul2023-6m"
    frames = re.findall(r'<iframe title="3-D view of ([^"]+)" srcdoc="([^"]*)"', text)
    assert [name for name, _ in frames] == ["turbid_harbor-mul2023-6m"]
    page = html.unescape(frames[0][1])
    data = json.loads(re.search(r'id="muls-data">(.*?)</script>', page, re.S)[1])
    assert data["count_in_files"] == len(read_las(study / "turbid_harbor-mul2023-6m" / "points.las"))
    assert data["mesh"] is not None  # the study's scene.ply, one folder up
    assert "THREE" in page and 'src="http' not in page


def test_an_unknown_view_pass_is_one_line(tmp_path, capsys):
    assert main(["coverage", "cable_survey", "--waters", "clean_ocean", "--instruments", "mul2023", "--altitudes-m",
                 "6", "--max-pulses", "200", "--out", str(tmp_path / "x"), "--quiet", "--workers", "0",
                 "--view-pass", "nowhere"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "view_pass = 'nowhere'" in err and "clean_ocean-mul2023-6m" in err
    assert not (tmp_path / "x").exists()
