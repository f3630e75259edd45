"""A pass says what made it (summary.json's and the LAS metadata's ``provenance``), and a campaign takes a pass
as complete only for the inputs that made it (its inputs fingerprint); a sweep and an option may not set one key."""

import json
from dataclasses import replace

import pytest
import yaml

from muls import water_preset
from muls.water.properties import HG_ASYMMETRY, henyey_greenstein
from scanner_sim.cli import main
from scanner_sim.config import SCENES_DIR, ConfigError, load_scene
from scanner_sim.io import read_las_metadata, read_waveforms_npz
from scanner_sim.runs.campaign import parse_campaign, run_campaign
from scanner_sim.survey.pipeline import run_pass
from scanner_sim.survey.setup import PassOptions
from scanner_sim.version import __version__

PULSES = 400
OPTIONS = PassOptions(max_pulses=PULSES, fidelity="fast", progress=False, render=False, write_scene=False)


def _provenance(folder):
    summary = json.loads((folder / "summary.json").read_text())
    block = summary["provenance"]
    las = read_las_metadata(folder / "points.las")["pass_metadata"]["provenance"]
    # the same block in the cloud, but for the fingerprint and the values that change no point
    neutral = {k: v for k, v in block.items() if k != "inputs_fingerprint"}
    neutral["overrides"] = {k: v for k, v in block["overrides"].items() if k != "survey.chunk_pulses"}
    assert las == neutral
    return summary, block


def test_attenuation_rule_and_overrides_are_in_the_provenance(tmp_path):
    """Passes under different attenuation rules, or with any ``--set`` override, wrote the same ``"water":
    "turbid_harbor"`` and nothing else about the water: summary.json and the LAS metadata carried the water's
    name only (PassFacts held no resolved water, no instrument, no overrides), so the points could not be traced
    to the model that made them. Two passes differing only by the rule (one through the Python API, one through
    ``--set`` on the command line) must each name their rule, the resolved water, the instrument as fired and the
    values given."""
    scene = load_scene("cable_survey")
    given = {"preset": "turbid_harbor", "attenuation_model": "c", "backscatter_model": "hg"}
    run_pass(scene.with_overrides({"water": given}), tmp_path / "api", OPTIONS)
    code = main(["run", "cable_survey", "--out", str(tmp_path / "cli"), "--max-pulses", str(PULSES),
                 "--fidelity", "fast", "--no-render", "--quiet", "--chunk-pulses", "150",
                 "--set", "water={preset: turbid_harbor, attenuation_model: k_lidar}", "--set", "survey.seed=4"])
    assert code == 0
    api_summary, api = _provenance(tmp_path / "api")
    cli_summary, cli = _provenance(tmp_path / "cli")
    assert api_summary["water"] == cli_summary["water"] == "turbid_harbor"  # the name alone cannot tell them apart

    harbor = water_preset("turbid_harbor")
    for block, rule in ((api, "c"), (cli, "k_lidar")):
        water = block["water"]
        assert (water["name"], water["attenuation_model"]) == ("turbid_harbor", rule)
        assert (water["absorption_per_m"], water["scattering_per_m"]) == (harbor.absorption_per_m,
                                                                          harbor.scattering_per_m)
        assert water["attenuation_per_m"] == pytest.approx(harbor.absorption_per_m + harbor.scattering_per_m)
        assert water["phase_function"] is None  # neither coefficient rule integrates a phase function
        assert block["muls_scanner_version"] == __version__
    # backscatter: the API pass asked for Henyey-Greenstein (b p_HG(pi), g = 0.924), the CLI pass kept the measured
    assert (api["water"]["backscatter_model"], api["water"]["beta_pi_source"]) == ("hg", "henyey_greenstein")
    assert api["water"]["beta_pi_per_m_sr"] == pytest.approx(
        harbor.scattering_per_m * (1 - HG_ASYMMETRY**2) / (4 * 3.141592653589793 * (1 + HG_ASYMMETRY) ** 3))
    assert api["water"]["beta_pi_per_m_sr"] == pytest.approx(harbor.scattering_per_m * henyey_greenstein(-1.0))
    assert (cli["water"]["backscatter_model"], cli["water"]["beta_pi_source"]) == ("measured", "measured")
    assert cli["water"]["beta_pi_per_m_sr"] == harbor.beta_pi_measured_per_m_sr

    # every value given, as given
    assert api["overrides"]["water"] == given
    assert cli["overrides"]["water"] == {"preset": "turbid_harbor", "attenuation_model": "k_lidar"}
    assert cli["overrides"]["survey.seed"] == 4 and cli_summary["seed"] == 4
    assert api["overrides"]["survey.max_pulses"] == cli["overrides"]["survey.max_pulses"] == PULSES
    assert cli["overrides"]["survey.chunk_pulses"] == 150 and "survey.chunk_pulses" not in api["overrides"]
    # the instrument as fired: the far channel's gate is the one the summary reports (the scene's 35 ns, 400 ns)
    far = [ch for ch in cli["instrument"]["channels"] if ch["gate_delay_s"] is not None]
    assert [ch["name"] for ch in far] == ["ch3"]
    assert far[0]["gate_delay_s"] * 1e9 == pytest.approx(cli_summary["settings"]["gate_delay_ns"]) \
        == pytest.approx(35.0)
    assert cli["instrument"]["transmitter"]["pulse_energy_j"] == 500e-6
    assert api["inputs_fingerprint"] != cli["inputs_fingerprint"]


def test_provenance_keeps_a_seed_byte_identical(tmp_path):
    """The provenance holds no clock time, and the cloud's leaves out what changes no point: two runs of one seed,
    at two chunk sizes, one with renders, write the same LAS bytes."""
    config = load_scene("cable_survey").with_overrides({"water": {"preset": "turbid_harbor",
                                                                  "attenuation_model": "kd"}})
    run_pass(config, tmp_path / "one", OPTIONS)
    run_pass(config, tmp_path / "two", replace(OPTIONS, chunk_pulses=90, render=True))
    assert (tmp_path / "one" / "points.las").read_bytes() == (tmp_path / "two" / "points.las").read_bytes()
    one, two = (json.loads((tmp_path / n / "summary.json").read_text()) for n in ("one", "two"))
    assert one["provenance"]["water"] == two["provenance"]["water"]
    assert one["provenance"]["water"]["attenuation_model"] == "kd"
    assert one["provenance"]["inputs_fingerprint"] != two["provenance"]["inputs_fingerprint"]


def _write_campaign(folder, sweep_water, **options):
    scene = yaml.safe_load((SCENES_DIR / "cable_survey.yaml").read_text())
    (folder / "scene.yaml").write_text(yaml.safe_dump(scene))
    data = {"scene": "scene.yaml", "sweep": {"water": sweep_water},
            "options": {"max_pulses": 300, "render": False, **options}}
    (folder / "campaign.yaml").write_text(yaml.safe_dump(data))


def _statuses(folder, out):
    from scanner_sim.runs.campaign import load_campaign

    result = run_campaign(load_campaign(folder / "campaign.yaml"), out, progress=False)
    return {p["dir"]: p["status"] for p in result["passes"]}


def test_a_pass_reruns_when_an_input_it_was_made_with_changed(tmp_path):
    """A campaign re-run skipped a pass as complete when its inputs had changed (a custom water's absorption
    edited from 0.1 to 0.9, a scene value edited, an option added): the completeness check compared only names,
    seed, fidelity, instrument name, pulse limit and coverage settings, so campaign.json listed the new values
    beside results made with the old ones. The fingerprint now covers the whole resolved configuration: the
    changed pass runs again, the unchanged one is skipped."""
    custom = {"absorption_per_m": 0.1, "scattering_per_m": 0.3, "attenuation_model": "k_lidar"}
    harbor = {"preset": "turbid_harbor", "attenuation_model": "c"}
    _write_campaign(tmp_path, [custom, harbor])
    out = tmp_path / "out"
    assert _statuses(tmp_path, out) == {"water=v1": "ran", "water=v2": "ran"}
    assert _statuses(tmp_path, out) == {"water=v1": "skipped", "water=v2": "skipped"}

    # the custom water's absorption edited: that pass only
    _write_campaign(tmp_path, [{**custom, "absorption_per_m": 0.9}, harbor])
    assert _statuses(tmp_path, out) == {"water=v1": "ran", "water=v2": "skipped"}
    summary = json.loads((out / "water=v1" / "summary.json").read_text())
    assert summary["provenance"]["water"]["absorption_per_m"] == 0.9

    # a preset's rule given on top of it changed: that pass only
    _write_campaign(tmp_path, [{**custom, "absorption_per_m": 0.9}, {**harbor, "attenuation_model": "k_lidar"}])
    assert _statuses(tmp_path, out) == {"water=v1": "skipped", "water=v2": "ran"}

    # a value of the scene file edited (the scan rate): every pass
    scene = yaml.safe_load((tmp_path / "scene.yaml").read_text())
    scene["scanner"]["scan_rate_hz"] = 10
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(scene))
    assert _statuses(tmp_path, out) == {"water=v1": "ran", "water=v2": "ran"}
    assert _statuses(tmp_path, out) == {"water=v1": "skipped", "water=v2": "skipped"}


def test_an_option_that_changes_no_file_name_still_reruns(tmp_path):
    """``options.waveforms`` raised from 2 to 5 left the same file names, so the pass with 2 kept records was
    taken as complete. Options are inputs too: a pass made with other ones runs again."""
    custom = {"absorption_per_m": 0.1, "scattering_per_m": 0.3, "attenuation_model": "k_lidar"}
    _write_campaign(tmp_path, [custom], waveforms=2)
    out = tmp_path / "out"
    assert _statuses(tmp_path, out) == {"water=v1": "ran"}
    _write_campaign(tmp_path, [custom], waveforms=5)
    assert _statuses(tmp_path, out) == {"water=v1": "ran"}
    assert len(read_waveforms_npz(out / "water=v1" / "waveforms.npz")[0]) == 5
    assert _statuses(tmp_path, out) == {"water=v1": "skipped"}


@pytest.mark.parametrize("sweep, option, words", [
    ({"survey.max_pulses": [100, 200]}, {"max_pulses": 300}, ["options.max_pulses = 300", "'survey.max_pulses'"]),
    ({"survey.chunk_pulses": [100, 200]}, {"chunk_pulses": 50}, ["options.chunk_pulses = 50", "'survey.chunk_pulses'"]),
    ({"survey": [{"max_pulses": 100}]}, {"max_pulses": 300}, ["options.max_pulses = 300", "axis 'survey'"]),
])
def test_a_sweep_and_an_option_that_set_one_key_are_refused(tmp_path, capsys, sweep, option, words):
    """A swept ``survey.max_pulses`` beside ``options.max_pulses`` ran every pass with the option's value (the
    options were applied over the sweep), so every folder held the same pass under different names. Refused
    before any pass runs: one line naming the option and the key, exit 2."""
    data = {"scene": "cable_survey", "sweep": sweep, "options": {"render": False, **option}}
    path = tmp_path / "clash.yaml"
    path.write_text(yaml.safe_dump(data))
    assert main(["campaign", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and all(w in err for w in words), err
    assert not (tmp_path / "out").exists()
    with pytest.raises(ConfigError, match="give it in one place"):
        parse_campaign(data)


def test_a_sweep_beside_options_of_other_keys_is_accepted():
    campaign = parse_campaign({"scene": "cable_survey", "sweep": {"seed": [1, 2]},
                               "options": {"max_pulses": 300, "chunk_pulses": 100}})
    assert [(j.config.survey.seed, j.config.survey.max_pulses) for j in campaign.jobs] == [(1, 300), (2, 300)]


def test_a_summary_without_provenance_is_not_complete(tmp_path):
    """A folder written before passes carried their fingerprint is run again (its inputs are unknown)."""
    from scanner_sim.runs.jobs import completed_summary

    campaign = parse_campaign({"scene": "cable_survey", "sweep": {"seed": [1]},
                               "options": {"max_pulses": 300, "render": False}})
    (job,) = campaign.jobs
    folder = tmp_path / job.name
    run_campaign(campaign, tmp_path, progress=False)
    summary = json.loads((folder / "summary.json").read_text())
    assert completed_summary(folder, job) == summary
    del summary["provenance"]
    (folder / "summary.json").write_text(json.dumps(summary))
    assert completed_summary(folder, job) is None
