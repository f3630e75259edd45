"""The scanner-sim command line: scenes, validate (exit 2, one line, no traceback), overlap."""

import json
import subprocess
import sys

import pytest
import yaml

from scanner_sim.cli import SUBCOMMANDS, main
from scanner_sim.config import SCENES_DIR

SHIPPED = ["cable_survey", "mine_field", "seabed_lawnmower", "pool_panel", "pond_panel"]


def test_scenes_lists_one_line_each(capsys):
    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) >= 5
    for name in SHIPPED:
        assert sum(line.startswith(name + " ") for line in lines) == 1


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scenes_validate(name, capsys):
    assert main(["validate", name]) == 0
    assert capsys.readouterr().out.startswith(f"OK {name}")


def test_validate_build_pool(capsys):
    assert main(["validate", "--build", "pool_panel"]) == 0
    assert "2 triangles" in capsys.readouterr().out


def _write(tmp_path, mutate, name="bad.yaml"):
    data = yaml.safe_load((SCENES_DIR / "mine_field.yaml").read_text())
    mutate(data)
    (tmp_path / "assets").mkdir(exist_ok=True)
    (tmp_path / "assets" / "mooring_block.obj").write_text((SCENES_DIR / "assets" / "mooring_block.obj").read_text())
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


CASES = {
    "typo": (lambda d: d["scanner"].update(scan_rat_hz=5), ["scanner.scan_rat_hz", "did you mean 'scan_rate_hz'"]),
    "negative_altitude": (lambda d: d["platform"].update(altitude_m=-2.0),
                          ["platform.altitude_m = -2.0", "must be a number > 0"]),
    "reflectance": (lambda d: d["objects"][0].update(reflectance=1.5),
                    ["objects[0].reflectance = 1.5", ">= 0 and <= 1"]),
    "missing_mesh": (lambda d: d["objects"][3].update(file="assets/missing.ply"),
                     ["objects[3].file = 'assets/missing.ply'", "file not found"]),
    "nan": (lambda d: d["seabed"]["relief"].update(rms_m=float("nan")),
            ["seabed.relief.rms_m = nan", "finite number"]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_scene_one_line_exit_2(case, tmp_path, capsys):
    mutate, expected = CASES[case]
    path = _write(tmp_path, mutate)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    for piece in expected:
        assert piece in err


def test_validate_subprocess_exit_code_and_no_traceback(tmp_path):
    path = _write(tmp_path, CASES["nan"][0])
    proc = subprocess.run([sys.executable, "-m", "scanner_sim.cli", "validate", str(path)], capture_output=True,
                          text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1
    assert "seabed.relief.rms_m = nan" in proc.stderr
    ok = subprocess.run([sys.executable, "-m", "scanner_sim.cli", "validate", "cable_survey"], capture_output=True,
                        text=True)
    assert ok.returncode == 0 and ok.stdout.startswith("OK cable_survey")


def test_overlap_json_and_plot(tmp_path, capsys):
    out = tmp_path / "overlap.png"
    argv = ["overlap", "--distances-m", "1", "1.5", "2", "2.5", "3", "4", "5", "6", "7", "8", "--subrays", "61",
            "--json", "--out", str(out)]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out)
    assert len(result["distance_m"]) == len(result["raycast"]) == len(result["analytic"]) == 10
    assert max(abs(r - a) for r, a in zip(result["raycast"], result["analytic"])) <= 0.03
    assert out.stat().st_size > 1000


def test_overlap_bad_distance_exit_2(capsys):
    assert main(["overlap", "--distances-m", "-1"]) == 2
    assert "--distances-m" in capsys.readouterr().err


def test_registry_has_room_for_more_subcommands():
    assert {"scenes", "validate", "overlap", "bench-rays"} <= set(SUBCOMMANDS)
