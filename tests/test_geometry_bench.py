"""The ray-throughput benchmark reports both figures on the same rays (its speed goals are read from
`scanner-sim bench-rays`, not asserted in a timed test: on a shared 2-core machine the ratio swings by 25 %)."""

from scanner_sim.raybench import bench_rays


def test_bench_reports_both_throughputs():
    result = bench_rays("pool_panel", pulses=200, subrays=7, repeat=1)
    assert result["primary_rays"] == 1400 and result["hits"] == 1400
    assert result["raw_embreex_rays_per_s"] > 0 and result["pipeline_rays_per_s"] > 0
    assert 0 < result["ratio"]
