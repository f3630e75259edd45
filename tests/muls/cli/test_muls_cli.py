"""The muls command line: JSON output, pictures, and one-line errors with exit code 2."""

import json

import pytest
from conftest import run_muls as _run

from muls.cli import main


def test_waveform_json_and_picture(capsys, tmp_path):
    png = tmp_path / "wf.png"
    code, out, err = _run(capsys, "waveform", "--water", "pond", "--range-m", "11.5", "--seed", "1",
                          "--out", str(png), "--json")
    assert code == 0, err
    r = json.loads(out)
    assert set(r["channels"]) == {"ch0", "ch1", "ch2", "ch3"}
    assert len(r["time_ns"]) == len(r["channels"]["ch1"]) == len(r["noise_free"]["ch3"])
    assert r["settings"]["seed"] == 1
    assert png.stat().st_size > 10_000


def test_waveform_custom_gate_and_table(capsys, tmp_path):
    code, out, err = _run(capsys, "waveform", "--water", "coastal_ocean", "--range-m", "20",
                          "--gate-delay-ns", "150", "--gate-width-ns", "300", "--no-plot")
    assert code == 0, err
    assert "gate 150/300 ns" in out and "ch3" in out


def test_precision_json(capsys, tmp_path):
    code, out, err = _run(capsys, "precision", "--water", "pond", "--ranges-m", "8.5", "10", "--shots", "40",
                          "--json", "--out", str(tmp_path / "p.png"))
    assert code == 0, err
    r = json.loads(out)
    assert set(r) == {"8.5", "10", "settings"}
    assert {"precision_m", "mean_deviation_m", "detected_fraction", "saturated_fraction"} <= set(r["10"]["ch1"])
    assert (tmp_path / "p.png").exists()


def test_coaxial_json_and_picture(capsys, tmp_path):
    code, out, err = _run(capsys, "coaxial", "--water", "turbid_harbor", "--json", "--out", str(tmp_path / "c.png"))
    assert code == 0, err
    r = json.loads(out)
    assert r["peak_ratio"] > 1.0 and len(r["time_ns"]) == len(r["coaxial_w"]) == len(r["non_coaxial_w"])
    assert (tmp_path / "c.png").exists()


def test_maxrange_table_one_water(capsys, tmp_path):
    code, out, err = _run(capsys, "maxrange", "--waters", "turbid_harbor", "--shots", "20",
                          "--out", str(tmp_path / "m.png"))
    assert code == 0, err
    assert "turbid_harbor" in out and "improvement" in out
    assert (tmp_path / "m.png").exists()


def test_bench_json_small(capsys):
    code, out, err = _run(capsys, "bench", "--pulses", "1000", "--full-pulses", "100", "--repeats", "1", "--json")
    assert code == 0, err
    r = json.loads(out)
    assert {"windowed_pulses_per_s", "full_record_pulses_per_s", "machine"} <= set(r)


def test_edge_bias_json_small(capsys):
    code, out, err = _run(capsys, "edge-bias", "--waters", "pool", "--ranges-m", "1.65", "2.0", "--shots", "5", "--json")
    assert code == 0, err
    r = json.loads(out)
    assert set(r) == {"pool", "settings"}
    assert r["pool"]["1.65"]["chosen"]["detected_fraction"] == 0.0  # inside the blind zone
    assert {"ch1", "ch2", "ch3", "chosen", "noise_free_m", "echo_alone_m", "column_deficit_m"} <= set(r["pool"]["2.00"])


@pytest.mark.parametrize("argv, option", [
    (["waveform", "--water", "mud"], "--water"),
    (["precision", "--water", "swamp", "--shots", "5"], "--water"),
    (["waveform", "--range-m", "-3"], "--range-m"),
    (["precision", "--ranges-m", "8.5", "-1", "--shots", "5"], "--ranges-m"),
    (["maxrange", "--shots", "0"], "--shots"),
    (["maxrange", "--waters", "clean_ocean", "lake"], "--water"),
    (["coaxial", "--water", "Pond"], "--water"),
    (["waveform", "--range-m", "ten"], "--range-m"),
    (["waveform", "--gate-width-ns", "0"], "--gate-width-ns"),
    (["bench", "--pulses", "0"], "--pulses"),
    (["edge-bias", "--waters", "pool", "lake"], "--water"),
    (["edge-bias", "--shots", "0"], "--shots"),
    (["edge-bias", "--reflectance", "1.5"], "--reflectance"),
    (["frobnicate"], "invalid choice"),
])
def test_bad_arguments_give_one_line_and_exit_2(capsys, argv, option):
    code, out, err = _run(capsys, *argv)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert option in lines[0]
    assert "Traceback" not in err


def test_bad_water_lists_the_allowed_names(capsys):
    code, _, err = _run(capsys, "waveform", "--water", "mud")
    assert code == 2
    for name in ("clean_ocean", "coastal_ocean", "pond", "pool", "turbid_harbor", "jerlov_I", "jerlov_9C"):
        assert name in err


def test_console_script_help_exits_0(capsys):
    assert main(["--help"]) == 0
    assert "maxrange" in capsys.readouterr().out


def test_help_imports_no_command_module():
    """``muls --help`` lists every subcommand from the registry without importing the studies, the Monte Carlo or
    the plots behind them (they load only for the subcommand that runs)."""
    import subprocess
    import sys

    code = ("import sys\nfrom muls.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m.startswith(('muls.montecarlo', 'muls.studies', 'muls.plots', "
            "'muls.cli.studies', 'muls.cli.montecarlo', 'muls.cli.sensitivity', 'matplotlib'))))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "validate-pass" in proc.stdout and "mobley1993" in proc.stdout
    assert proc.stdout.strip().splitlines()[-1] == "[]"
