"""A survey pass end to end on the default scene: accuracy against the truth meshes, water types, labels,
chunking invariance, outputs, memory."""

import json
import os
import subprocess
import sys

import laspy
import numpy as np
import pytest
import trimesh
from conftest import drop_a_signal

from muls.infra.command import EXIT_SIGINT, run_guarded
from scanner_sim.cli import main
from scanner_sim.config import load_scene
from scanner_sim.records.point_records import DROPOUT_CAUSES
from scanner_sim.survey.pipeline import last_round_cut, pass_chunks, run_pass
from scanner_sim.survey.setup import PassOptions, PassSetup
from scanner_sim.world.scene import LABELS

POOL_P95_MAX_M = 0.15
INDEPENDENT_TOL_M = 0.01


@pytest.fixture(scope="module")
def cable_survey():
    return load_scene("cable_survey")


def _pass(config, out, **kw):
    kw.setdefault("progress", False)
    kw.setdefault("render", False)
    return run_pass(config, out, PassOptions(**kw)).summary


def test_pool_points_lie_on_the_truth_meshes(cable_survey):
    setup = PassSetup.build(cable_survey, PassOptions(water="pool", max_pulses=8000))
    slots = next(setup.slot_chunks())
    points = setup.simulate_chunk(slots).points
    assert len(points) > 7000
    assert np.percentile(np.abs(points.range_error_m), 95) <= POOL_P95_MAX_M

    # Independent check: intersect each point's line of sight with the truth mesh using trimesh's pure-numpy
    # triangle intersector (not Embree, float64), on a sample of points.
    pick = np.random.default_rng(0).choice(len(points), 150, replace=False)
    times = points.gps_time_s[pick]
    est_o, est_d, *_ = setup.scanner.world_rays(setup.trajectory.poses(times, estimated=True))
    mesh = trimesh.Trimesh(setup.scene.vertices - setup.scene.local_origin, setup.scene.faces, process=False)
    intersector = trimesh.ray.ray_triangle.RayMeshIntersector(mesh)
    origins = est_o - setup.scene.local_origin
    locations, ray, tri = intersector.intersects_location(origins, est_d, multiple_hits=False)
    truth = np.full(pick.size, np.nan)
    truth[ray] = np.einsum("ij,ij->i", locations - origins[ray], est_d[ray])
    first_object = np.full(pick.size, -1)
    first_object[ray] = setup.scene.face_object[tri]
    measured = np.linalg.norm(points.xyz[pick] - est_o, axis=1)
    independent_error = measured - truth
    # A point is judged against the surface it ranged: where that is the first along its line (nearly all).
    ok = np.isfinite(independent_error) & (first_object == points.object_id[pick])
    assert ok.mean() > 0.95
    assert np.all(np.abs(independent_error[ok] - points.range_error_m[pick][ok]) < INDEPENDENT_TOL_M)


def test_turbid_water_loses_points_that_clean_water_keeps(cable_survey, tmp_path):
    clean = _pass(cable_survey, tmp_path / "clean", water="clean_ocean", max_pulses=20000)
    turbid = _pass(cable_survey, tmp_path / "turbid", water="turbid_harbor", max_pulses=20000)
    assert turbid["points"] < clean["points"]
    lost = lambda s: s["dropouts"]["below_threshold"] + s["dropouts"]["masked_by_backscatter"]  # noqa: E731
    assert lost(turbid) > lost(clean)
    assert turbid["dropouts"]["below_threshold"] > clean["dropouts"]["below_threshold"]
    assert turbid["dropouts"]["masked_by_backscatter"] > clean["dropouts"]["masked_by_backscatter"]


def test_points_on_the_cable_are_labelled_cable(cable_survey):
    setup = PassSetup.build(cable_survey, PassOptions(max_pulses=20000))
    points = setup.simulate_chunk(next(setup.slot_chunks())).points
    cable_id = next(o.object_id for o in setup.scene.objects if o.label == LABELS["cable"])
    on_cable = points.object_id == cable_id
    assert on_cable.sum() > 50
    assert np.all(points.classification[on_cable] == LABELS["cable"])
    assert np.all(points.classification[points.object_id != cable_id] != LABELS["cable"])


def test_same_seed_same_points_whatever_the_chunk_size(cable_survey, tmp_path):
    _pass(cable_survey, tmp_path / "a", max_pulses=12000, chunk_pulses=4096)
    _pass(cable_survey, tmp_path / "b", max_pulses=12000, chunk_pulses=50000)
    a, b = laspy.read(tmp_path / "a" / "points.las"), laspy.read(tmp_path / "b" / "points.las")
    assert len(a.points) == len(b.points) > 11000
    for name in a.point_format.dimension_names:
        assert np.array_equal(np.asarray(a[name]), np.asarray(b[name])), name
    other = _pass(cable_survey, tmp_path / "c", max_pulses=12000, seed=2)
    c = laspy.read(tmp_path / "c" / "points.las")
    assert not np.array_equal(np.asarray(a.z), np.asarray(c.z)[: len(a.z)]) and other["seed"] == 2


@pytest.mark.parametrize(("sizes", "parts", "expected"), [
    ([10, 10, 10], 2, [10, 10, 5, 5]),  # three chunks, two workers: the third in halves (1.5 chunks' time, not 2)
    ([10, 10, 10, 1], 2, [10, 10, 6, 5]),  # a max_pulses remainder counts with the chunk before it
    ([10, 10, 10, 10], 2, [10, 10, 10, 5, 5]),  # a whole last round: its last chunk in halves, as the cores end
    ([10, 10, 10, 10, 10], 4, [10, 10, 10, 10, 3, 3, 2, 2]),
    ([10, 10, 10, 10, 10, 10], 4, [10, 10, 10, 10, 5, 5, 5, 5]),  # two chunks past the round, four workers: in quarters
    ([10, 10, 1], 2, [10, 6, 5]),
    ([7], 2, [4, 3]),
    ([1], 2, [1]),
    ([], 2, []),
])
def test_the_last_round_is_shared_by_the_workers_and_no_slot_is_lost(sizes, parts, expected):
    """The pass's chunks in order, every slot once; what follows the last whole round of ``parts`` chunks is cut into
    ``parts`` near-equal chunks, so no worker idles while another runs the pass's last chunks alone."""
    chunks = [np.arange(sum(sizes[:i]), sum(sizes[: i + 1])) for i in range(len(sizes))]
    out = list(last_round_cut(iter(chunks), parts))
    assert np.array_equal(np.concatenate(out) if out else np.zeros(0), np.arange(sum(sizes)))
    assert [c.size for c in out] == expected


def test_regression_a_pass_stops_at_its_next_chunk_after_a_dropped_ctrl_c(cable_survey):
    """Root cause as in tests/muls/infra/test_signals.py: a Ctrl-C raised where Python drops the exception (a
    finaliser) left the pass running to its end, and a dataset to its millionth scene. The chunk loop now stops
    before it submits another chunk: of a 20-chunk pass, no chunk is taken after the one during which it came."""
    options = PassOptions(max_pulses=2000, progress=False, render=False)
    setup = PassSetup.build(cable_survey.with_overrides({"survey.chunk_pulses": 100}), options)
    taken = []

    def consume():
        for chunk in pass_chunks(setup, options):
            taken.append(chunk.slots.size)
            if len(taken) == 1:
                assert drop_a_signal() == [KeyboardInterrupt]
        return 0

    assert run_guarded("scanner-sim run", consume) == EXIT_SIGINT
    assert taken == [100]


def test_same_seed_same_points_whatever_the_thread_count(tmp_path):
    """One numba thread (the chunks one after another) and two (two chunks side by side, each on one thread of
    its own): the same bytes."""
    code = ("import sys; from scanner_sim.cli import main; main(['run', '--out', sys.argv[1], '--max-pulses', "
            "'12000', '--chunk-pulses', '5000', '--no-render', '--quiet'])")
    for threads in ("1", "2"):
        env = {**os.environ, "NUMBA_NUM_THREADS": threads}
        subprocess.run([sys.executable, "-c", code, str(tmp_path / threads)], check=True, env=env)
    a, b = (laspy.read(tmp_path / t / "points.las") for t in ("1", "2"))
    assert len(a.points) > 11000
    assert a.points.array.tobytes() == b.points.array.tobytes()


def test_idle_parallel_workers_sleep_unless_the_user_says_otherwise():
    """A pass's set-up sets OpenMP's wait policy to PASSIVE before any parallel kernel runs (muls.infra.runtime): spinning
    workers take a core from the threads working beside them (measured when a ray-stage thread ran beside the
    physics: ``fast`` on cable_survey 91,000 against 103,000 pulses/s, medians of five). A policy the user set is
    kept."""
    code = ("import os, scanner_sim\n"
            "scanner_sim.PassSetup.build(scanner_sim.load_scene('pool_panel'), scanner_sim.PassOptions(max_pulses=10))\n"
            "print(os.environ['OMP_WAIT_POLICY'])")
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    for given, expected in ((None, "PASSIVE"), ("ACTIVE", "ACTIVE")):
        run_env = env if given is None else {**env, "OMP_WAIT_POLICY": given}
        out = subprocess.run([sys.executable, "-c", code], check=True, env=run_env, capture_output=True, text=True)
        assert out.stdout.strip() == expected


def test_run_writes_every_output(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "--out", str(out), "--max-pulses", "3000", "--waveforms", "3", "--quiet"]) == 0
    for name in ("points.las", "dropouts.npz", "summary.json", "trajectory.csv", "scene.ply", "render.png",
                 "waveforms.npz"):
        assert (out / name).stat().st_size > 0, name
    las = laspy.read(out / "points.las")
    assert las.header.version.major == 1 and las.header.version.minor == 4
    for field in ("gps_time", "intensity", "return_number", "number_of_returns", "classification", "scan_angle",
                  "channel", "amplitude_lsb", "snr", "saturated", "true_range_m", "range_error_m",
                  "incidence_deg", "object_id"):
        assert field in las.point_format.dimension_names, field
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["dropouts"]) == set(DROPOUT_CAUSES)
    pulses_with_points = len(np.unique(np.asarray(las.gps_time)))  # one emission time per pulse
    assert summary["pulses"] == 3000 == pulses_with_points + sum(summary["dropouts"].values())
    for key in ("scene", "water", "seed", "fidelity", "channels", "wall_s", "pulses_per_s", "range_error_m"):
        assert key in summary
    with np.load(out / "waveforms.npz") as wf:
        assert wf["ch0"].shape[0] == 3 and wf["ch1"].shape == wf["ch0"].shape


def test_run_rejects_a_bad_water_in_one_line(capsys):
    assert main(["run", "--water", "muddy", "--max-pulses", "10", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "muddy" in err[0] and "clean_ocean" in err[0]


@pytest.mark.slow
def test_memory_does_not_grow_with_the_pass(tmp_path):
    """Peak RSS of a pass 10 times longer grows by less than 25 %. The peak is the child's own address space's
    (VmHWM): getrusage's ru_maxrss keeps, across exec, the resident size of the process it was forked from, so
    with pytest's grown process both passes read the same figure and the test could not fail."""
    code = ("import re, sys; from pathlib import Path; from scanner_sim.cli import main; "
            "main(['run', '--out', sys.argv[1], '--max-pulses', sys.argv[2], '--chunk-pulses', '10000', "
            "'--no-render', '--quiet']); "
            "print(re.search(r'VmHWM:\\s+(\\d+) kB', Path('/proc/self/status').read_text())[1])")
    rss = [int(subprocess.run([sys.executable, "-c", code, str(tmp_path / n), n], check=True, capture_output=True,
                              text=True).stdout.strip().splitlines()[-1]) for n in ("20000", "200000")]
    assert rss[1] < 1.25 * rss[0], rss


@pytest.mark.parametrize("scene", ["real_site", "cable_survey", "pool_panel"])
def test_a_chunk_holds_about_chunk_pulses_pulses_whatever_share_of_slots_fires(scene):
    """survey.chunk_pulses is the pulses a chunk holds: a sector scan fires a share of its slots (real_site's 90 deg
    a quarter), so its chunks span that many more slots. Each chunk but the last holds chunk_pulses within the
    rounding of a slot on the sector's edge, whatever the scan; it was a quarter of it on real_site when the key
    counted slots, which made a sector scan's chunks carry four times the per-chunk overhead per pulse."""
    setup = PassSetup.build(load_scene(scene), PassOptions(max_pulses=9000, chunk_pulses=2000, fidelity="fast"))
    sizes = [slots.size for slots in setup.slot_chunks()]
    assert sum(sizes) == 9000 and len(sizes) >= 5
    assert all(abs(n - 2000) <= 0.01 * 2000 for n in sizes[:-1]), (setup.scanner.active_fraction, sizes)
