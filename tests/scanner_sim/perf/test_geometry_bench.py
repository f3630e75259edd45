"""The ray-throughput benchmark reports both figures on the same rays (its speed goals are read from
`scanner-sim bench-rays`, not asserted in a timed test: on a shared 2-core machine the ratio swings by 25 %)."""

import pytest

from scanner_sim.fidelity import FIDELITY_LEVELS
from scanner_sim.perf.bench import bench_pass
from scanner_sim.perf.profiling import stage_profile
from scanner_sim.perf.raybench import bench_rays


def test_bench_reports_both_throughputs():
    result = bench_rays("pool_panel", pulses=200, subrays=7, repeat=1)
    assert result["primary_rays"] == 1400 and result["hits"] == 1400
    assert result["raw_embreex_rays_per_s"] > 0 and result["pipeline_rays_per_s"] > 0
    assert 0 < result["ratio"]


@pytest.mark.slow
def test_pass_bench_reports_every_level_with_cores_and_memory():
    """Each level in a fresh process: pulses/s, cores used and peak memory, in the same keys every run."""
    result = bench_pass("pool_panel", pulses=600, repeat=2, large_seabed=False)
    assert list(result) == ["scene", "pulses", "repeat", "cpu_count", "load_avg_1min", *FIDELITY_LEVELS,
                            "load_avg_1min_after"]
    for name in FIDELITY_LEVELS:
        level = result[name]
        assert level["pulses_per_s"] >= level["median_pulses_per_s"] > 0
        assert 0 < level["cores_used"] <= result["cpu_count"] + 0.5
        assert level["peak_rss_mb"] > 50 and level["raw_embreex_pulses_per_s"] > level["pulses_per_s"]


@pytest.mark.slow
def test_stage_profile_accounts_for_the_whole_chunk_loop():
    """Every stage of a pass over a seabed takes time, and the stages add up to the loop's CPU seconds."""
    result = stage_profile("cable_survey", "balanced", pulses=4000)
    stages = result["stages"]
    assert set(stages) >= {"rays (Embree)", "digitise", "ranging", "truth", "georeference", "uncertainty", "coverage", "LAS"}
    assert all(r["cpu_s"] > 0 for name, r in stages.items() if name != "other")
    assert sum(r["cpu_s"] for r in stages.values()) == pytest.approx(result["cpu_s_one_thread"], abs=5e-3)
    assert result["pulses"] == 4000 and result["pass_cores_used"] > 0
