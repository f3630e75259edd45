"""End-to-end benchmark of survey passes per fidelity level, beside raw embreex on the same rays, in one run.

Each level runs in a fresh process (so its peak memory is its own, and no level inherits another's caches):
a warm-up pass of one chunk per worker (:func:`warm_up_pulses`), then ``repeat`` timed passes of ``pulses``
pulses with their LAS and dropout files. Beside the pulses per second, the bench reports the cores the pass kept
busy (its process CPU seconds over wall seconds) and the process's peak resident memory. The large-seabed case
rebuilds the scene's seabed at about two million triangles and times the scene build, the BVH and a balanced pass
over it. The JSON has the same keys in the same order every run.
"""

from __future__ import annotations

import multiprocessing
import os
import resource
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

from scanner_sim.fidelity import FIDELITY_LEVELS

#: Triangles of the large-seabed case (the scene format's limit is 2,000,000).
LARGE_SEABED_TRIANGLES = 1_900_000


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux reports KiB


def _level_figures(scene_name: str, fidelity: str, pulses: int, repeat: int, overrides: dict) -> dict:
    """In a fresh process: best and median pulses/s of ``repeat`` passes, cores used (of the best), set-up seconds
    and peak RSS."""
    from muls.infra.runtime import configure_process
    from scanner_sim.config import load_scene
    from scanner_sim.survey.pipeline import run_pass
    from scanner_sim.survey.setup import PassOptions
    from scanner_sim.world.scene import build_scene

    configure_process()  # as scanner-sim does at start: this process is spawned afresh
    config = load_scene(scene_name).with_overrides(overrides)
    t0 = time.perf_counter()
    scene = build_scene(config)
    scene_s = time.perf_counter() - t0
    quiet = dict(fidelity=fidelity, progress=False, render=False, write_scene=False)
    with tempfile.TemporaryDirectory(prefix="muls-bench-") as out:  # numba's cache; a whole chunk per worker
        run_pass(config, out, PassOptions(max_pulses=warm_up_pulses(config, pulses), **quiet), scene=scene)
    best, cores, setup_s, rates = 0.0, 0.0, 0.0, []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory(prefix="muls-bench-") as out:
            wall0, cpu0 = time.perf_counter(), time.process_time()
            summary = run_pass(config, out, PassOptions(max_pulses=pulses, **quiet), scene=scene).summary
            wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        rates.append(summary["pulses_per_s"])
        if summary["pulses_per_s"] > best:
            best, cores, setup_s = summary["pulses_per_s"], cpu / wall, summary["setup_s"]
    return {"pulses_per_s": round(best, 1), "median_pulses_per_s": round(statistics.median(rates), 1),
            "cores_used": round(cores, 2), "setup_s": round(setup_s, 2),
            "scene_build_s": round(scene_s, 2), "triangles": int(scene.n_faces), "peak_rss_mb": round(_peak_rss_mb(), 1)}


def warm_up_pulses(config, pulses: int) -> int:
    """Pulses of the untimed pass before timed passes of ``pulses``: a whole chunk for every worker (no more than
    the timed pass), so that each worker's memory has grown to a chunk's size (the first chunk a thread runs pays
    its page faults) and every kernel is loaded."""
    from scanner_sim.survey.pipeline import chunk_workers

    return min(pulses, chunk_workers() * config.survey.chunk_pulses)


def _in_fresh_process(fn, *args):
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(fn, *args).result()


def _large_seabed_overrides(scene_name: str) -> dict:
    """The scene's seabed at the node spacing that gives about :data:`LARGE_SEABED_TRIANGLES` triangles."""
    from scanner_sim.config import load_scene

    sx, sy = load_scene(scene_name).seabed.size_m
    return {"seabed.resolution_m": round((2.0 * sx * sy / LARGE_SEABED_TRIANGLES) ** 0.5, 5)}


def _large_seabed_figures(scene_name: str, overrides: dict) -> dict:
    """In a fresh process: scene build and BVH build [s] of the large seabed."""
    from scanner_sim.config import load_scene
    from scanner_sim.rays.caster import RayCaster
    from scanner_sim.world.scene import build_scene

    config = load_scene(scene_name).with_overrides(overrides)
    t0 = time.perf_counter()
    scene = build_scene(config)
    t1 = time.perf_counter()
    RayCaster.for_scene(scene)
    t2 = time.perf_counter()
    return {"triangles": int(scene.n_faces), "scene_build_s": round(t1 - t0, 2), "bvh_build_s": round(t2 - t1, 2)}


def bench_pass(scene_name: str = "cable_survey", pulses: int = 60000, repeat: int = 5, large_seabed: bool = True
               ) -> dict:
    """Per fidelity level: pulses/s of :func:`scanner_sim.survey.pipeline.run_pass` (chunk loop and LAS/dropout writing,
    best of ``repeat``, and their median: on a shared machine the best is the pass the neighbours disturbed least),
    cores used, peak RSS, and the raw embreex rate for the same scene's rays as pulses/s.

    ``ratio_to_raw_rays``: end-to-end pulses/s over the pulses/s raw embreex reaches casting the same primary
    and shadow rays (``scanner-sim bench-rays``) with the level's sub-ray count. ``large_seabed`` (unless
    False): the same for ``balanced`` on the scene's seabed at about two million triangles, with its build times.
    """
    from scanner_sim.perf.raybench import bench_rays

    result = {"scene": scene_name, "pulses": pulses, "repeat": repeat, "cpu_count": os.cpu_count(),
              "load_avg_1min": round(os.getloadavg()[0], 2)}
    for fidelity, level in FIDELITY_LEVELS.items():
        figures = _in_fresh_process(_level_figures, scene_name, fidelity, pulses, repeat, {})
        result[fidelity] = {**figures, "subrays": level.subrays, "shadow_rays": level.shadow_rays,
                            **_raw_rate(bench_rays(scene_name, min(pulses, 20000), level.subrays, repeat=3), level,
                                        figures["pulses_per_s"])}
    if large_seabed:
        overrides = _large_seabed_overrides(scene_name)
        level = FIDELITY_LEVELS["balanced"]
        figures = _in_fresh_process(_level_figures, scene_name, "balanced", pulses, repeat, overrides)
        result["large_seabed"] = {
            **overrides, **_in_fresh_process(_large_seabed_figures, scene_name, overrides), "balanced": {
                **figures, **_raw_rate(bench_rays(scene_name, min(pulses, 20000), level.subrays, 3, overrides), level,
                                       figures["pulses_per_s"])}}
    result["load_avg_1min_after"] = round(os.getloadavg()[0], 2)
    return result


def _raw_rate(rays: dict, level, pulses_per_s: float) -> dict:
    """Raw embreex's rate for a level's rays (``bench_rays`` output) as rays/s and pulses/s, and the ratio."""
    rays_per_pulse = (rays["primary_rays"] + (rays["shadow_rays"] if level.shadow_rays else 0)) / rays["pulses"]
    raw_pulses_per_s = rays["raw_embreex_rays_per_s"] / rays_per_pulse
    return {"raw_embreex_rays_per_s": rays["raw_embreex_rays_per_s"],
            "raw_embreex_pulses_per_s": round(raw_pulses_per_s, 1),
            "ratio_to_raw_rays": round(pulses_per_s / raw_pulses_per_s, 3)}
