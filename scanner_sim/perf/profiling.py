"""Where a pass spends its time: CPU seconds per stage of the flow, from a profile of one pass run stage after
stage on one numba thread (so that each stage's seconds are its own), beside the cores the ordinary pass keeps
busy. ``scanner-sim bench --profile`` prints it; docs/performance.md holds the tables.

A stage is the cumulative time of the functions :func:`stages` lists for it (a function's time includes
what it calls); ``other`` is the rest of the chunk loop (poses, mirror directions, chunk bookkeeping).
"""

from __future__ import annotations

import cProfile
import pstats
import tempfile
import time


def stages() -> dict[str, tuple]:
    """Stage -> the functions whose cumulative times make it up; "ray stage" (``balanced``'s cast or the ``auto``
    level's) minus "rays (Embree)" is the sub-ray set-up, hit attributes and receiver check. The functions
    themselves, not their names: one that moves or is renamed fails here, loudly."""
    from muls.optics.optical_model import OpticalModel
    from muls.ranging.returns import range_batch
    from muls.receiver.digitiser import digitise
    from scanner_sim.rays.auto import cast_auto
    from scanner_sim.rays.cast import cast_beams
    from scanner_sim.rays.caster import EmbreeCaster
    from scanner_sim.survey.chunk import lines_of_sight
    from scanner_sim.survey.georeference import georeference
    from scanner_sim.survey.handoff import pulse_batch
    from scanner_sim.survey.sinks import CoverageSink, LasSink
    from scanner_sim.survey.tpu_calibration import checked_errors
    from scanner_sim.survey.uncertainty import TpuModel, with_uncertainty

    return {
        "rays (Embree)": (EmbreeCaster.first_hits_raw, EmbreeCaster.occluded_raw),
        "ray stage": (cast_beams, cast_auto),
        "waveform input": (pulse_batch, OpticalModel.echoes),
        "digitise": (digitise,),
        "ranging": (range_batch,),
        "truth": (lines_of_sight,),
        "georeference": (georeference,),
        "uncertainty": (TpuModel.predict, with_uncertainty, checked_errors),
        "coverage": (CoverageSink.add,),
        "LAS": (LasSink.add,),
    }


def _cumulative(stats: pstats.Stats, function) -> float:
    """Cumulative seconds of ``function`` in the profile ``stats``."""
    code = function.__code__
    return sum(row[3] for (path, lineno, name), row in stats.stats.items()
               if path == code.co_filename and lineno == code.co_firstlineno and name == code.co_name)


def stage_profile(scene_name: str = "cable_survey", fidelity: str = "balanced", pulses: int = 60000) -> dict:
    """CPU seconds per stage [s] and per pulse [us] of a ``pulses``-pulse pass on one numba thread, with the
    chunk loop's total; then the cores the ordinary (overlapped, multi-threaded) pass keeps busy."""
    import numba

    from scanner_sim.config import load_scene
    from scanner_sim.survey.pipeline import pass_facts, run_pass, stream_pass
    from scanner_sim.survey.setup import PassOptions, PassSetup
    from scanner_sim.survey.sinks import LasSink

    config = load_scene(scene_name)
    options = PassOptions(fidelity=fidelity, max_pulses=pulses, progress=False, render=False, write_scene=False)
    with tempfile.TemporaryDirectory(prefix="muls-profile-") as out:
        run_pass(config, out, PassOptions(fidelity=fidelity, max_pulses=2000, progress=False, render=False))  # warm
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        setup = PassSetup.build(config, options)
        chunks = (setup.simulate_chunk(slots) for slots in setup.slot_chunks())
        with tempfile.TemporaryDirectory(prefix="muls-profile-") as out, LasSink(
                f"{out}/points.las", setup.scene.local_origin, pass_facts(setup, options).metadata()) as las:
            profile = cProfile.Profile(time.process_time)
            profile.enable()
            stream_pass(setup, chunks, [las], options, sink_threads=False)  # the sinks' CPU on this thread
            profile.disable()
    finally:
        numba.set_num_threads(threads)
    stats = pstats.Stats(profile)
    total = sum(row[2] for row in stats.stats.values())  # own times add up to the whole
    seconds = {}
    for stage, functions in stages().items():
        times = [_cumulative(stats, f) for f in functions]
        # the ray stage is one of two entry points, the auto level's calling the other where it cannot help
        seconds[stage] = max(times) if stage == "ray stage" else sum(times)
    seconds["ray stage"] -= seconds["rays (Embree)"]
    seconds = {("sub-rays, hits, receiver check" if k == "ray stage" else k): v for k, v in seconds.items()}
    seconds["other"] = total - sum(seconds.values())
    with tempfile.TemporaryDirectory(prefix="muls-profile-") as out:
        wall0, cpu0 = time.perf_counter(), time.process_time()
        summary = run_pass(config, out, options).summary
        cores = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
    n = summary["pulses"]
    return {"scene": scene_name, "fidelity": fidelity, "pulses": n, "cpu_s_one_thread": round(total, 3),
            "stages": {k: {"cpu_s": round(v, 3), "us_per_pulse": round(1e6 * v / n, 2), "share": round(v / total, 3)}
                       for k, v in seconds.items()},
            "pass_pulses_per_s": summary["pulses_per_s"], "pass_cores_used": round(cores, 2)}
