"""End-to-end benchmark of survey passes per fidelity, beside raw embreex on the same rays, in one run."""

from __future__ import annotations

import os
import tempfile

from .fidelity import FIDELITY_LEVELS


def bench_pass(scene_name: str = "cable_survey", pulses: int = 60000, repeat: int = 2) -> dict:
    """Pulses per second of :func:`scanner_sim.survey.run_pass` (chunk loop and LAS/dropout writing, best of
    ``repeat``) for each fidelity, and the raw embreex rate for the same scene's rays as pulses per second.

    ``ratio_to_raw_rays``: end-to-end pulses/s over the pulses/s raw embreex reaches casting the same
    primary and shadow rays (``scanner-sim bench-rays``) with the fidelity's sub-ray count.
    """
    from .config import load_scene
    from .raybench import bench_rays
    from .survey import PassOptions, run_pass

    config = load_scene(scene_name)
    result = {"scene": scene_name, "pulses": pulses, "cpu_count": os.cpu_count(), "load_avg": os.getloadavg()[0]}
    for fidelity, level in FIDELITY_LEVELS.items():
        best = None
        options = PassOptions(fidelity=fidelity, max_pulses=pulses, progress=False, render=False)
        run_pass(config, tempfile.mkdtemp(prefix="muls-bench-"), PassOptions(
            fidelity=fidelity, max_pulses=2000, progress=False, render=False))  # compile and warm up
        for _ in range(repeat):
            with tempfile.TemporaryDirectory(prefix="muls-bench-") as out:
                summary = run_pass(config, out, options).summary
            best = max(best or 0.0, summary["pulses_per_s"])
        rays = bench_rays(scene_name, min(pulses, 20000), level.subrays, repeat=3)
        rays_per_pulse = (rays["primary_rays"] + (rays["shadow_rays"] if level.shadow_rays else 0)) / rays["pulses"]
        raw_pulses_per_s = rays["raw_embreex_rays_per_s"] / rays_per_pulse
        result[fidelity] = {
            "pulses_per_s": round(best, 1),
            "subrays": level.subrays,
            "shadow_rays": level.shadow_rays,
            "raw_embreex_rays_per_s": rays["raw_embreex_rays_per_s"],
            "raw_embreex_pulses_per_s": round(raw_pulses_per_s, 1),
            "ratio_to_raw_rays": round(best / raw_pulses_per_s, 3),
        }
    return result
