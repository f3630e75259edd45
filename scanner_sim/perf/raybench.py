"""Ray-throughput benchmark: the pipeline's ray stage against raw embreex on the same rays, in one run.

The rays are a scan-ordered chunk of a real pass (the middle of the scene's pass, ``pulses`` pulses with
``subrays`` sub-rays each), plus the shadow rays the receiver check casts for them (one slot per hit; hits
outside the FOV cone get an empty ray that Embree skips, in both timings). *Pipeline* times
:func:`scanner_sim.rays.cast.cast_beams` end to end: world beam rays in, :class:`Hits` out (sub-ray
generation, local-frame float32 conversion, first hits, hit attributes, FOV cone, shadow rays). *Raw* times
only embreex's two calls (first-hit query with distances, occlusion query), each once over the whole
chunk, on a separately built Embree scene of the same float32 mesh, with the very same float32 rays
prepared beforehand. Best of ``repeat``.
"""

from __future__ import annotations

import time

import numpy as np


def bench_rays(scene_name: str = "cable_survey", pulses: int = 20000, subrays: int = 19, repeat: int = 3,
               overrides: dict | None = None) -> dict:
    """Ray throughput of the scene ``scene_name`` (a shipped name or YAML path; ``overrides``: dotted scene keys
    to change first, e.g. a finer seabed)."""
    from scanner_sim.config import load_scene
    from scanner_sim.motion.scanner import Scanner
    from scanner_sim.rays import kernels as _raykernels
    from scanner_sim.rays.beams import beam_pattern
    from scanner_sim.rays.cast import CastScene, cast_beams, kernel_inputs
    from scanner_sim.rays.embree_upload import embree_scene
    from scanner_sim.rays.hits import empty_columns
    from scanner_sim.survey.setup import checked_trajectory
    from scanner_sim.world.scene import build_scene

    cfg = load_scene(scene_name).with_overrides(overrides or {})
    inst = cfg.instrument_model()
    scene = build_scene(cfg)
    traj = checked_trajectory(cfg, scene)
    scanner = Scanner.from_config(cfg.scanner, inst)
    mid = 0.5 * traj.duration_s
    span = pulses / (scanner.pulse_rate_hz * scanner.active_fraction)
    times = scanner.pulse_times(max(0.0, mid - 0.5 * span), mid + 0.5 * span + 1.0)[:pulses]
    rays = scanner.world_rays(traj.poses(times))
    pattern = beam_pattern(subrays)
    geometry = inst.geometry

    # The exact float32 rays the pipeline casts (primary and shadow), prepared outside the raw timing.
    pulse_rays, layout, faces, view = kernel_inputs(scene, *rays, pattern, geometry)
    n_pulses = len(times)
    o32 = np.empty((n_pulses * pattern.count, 3), np.float32)
    d32 = np.empty_like(o32)
    _raykernels.subrays_local32(pulse_rays, 0, n_pulses, layout, o32, d32)
    target = CastScene.build(scene, backend="embree")
    caster = target.caster
    prim, tfar = caster.first_hits_raw(o32, d32)
    n_sub = o32.shape[0]
    shadows = _raykernels.ShadowRays(np.empty((n_sub, 3), np.float32), np.empty((n_sub, 3), np.float32),
                                     np.empty(n_sub, np.float32))
    c = _raykernels.hit_block(prim, tfar, 0, 0, pulse_rays, layout, faces, view, empty_columns(n_sub), shadows)
    sh_o, sh_d, sh_len = shadows
    sh_o, sh_d, sh_len = sh_o[:c].copy(), sh_d[:c].copy(), sh_len[:c].copy()
    n_shadow = int(np.count_nonzero(sh_len > 0))
    n_rays = o32.shape[0] + n_shadow

    raw_scene = embree_scene(caster.vertices, caster.faces)

    def raw():
        raw_scene.run(o32, d32, output=1)
        raw_scene.run(sh_o, sh_d, dists=sh_len, query="OCCLUDED")

    def pipeline():
        return cast_beams(target, *rays, pattern, geometry, shadow_rays=True)

    raw()
    hits = pipeline()  # warm both (BVH build, numba compile)
    t_raw, t_pipe = [], []
    for _ in range(repeat):  # interleave so machine load hits both alike
        t0 = time.perf_counter()
        raw()
        t_raw.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        pipeline()
        t_pipe.append(time.perf_counter() - t0)
    best_raw, best_pipe = min(t_raw), min(t_pipe)
    return {
        "scene": scene_name,
        "triangles": scene.n_faces,
        "pulses": int(len(times)),
        "subrays": subrays,
        "primary_rays": int(o32.shape[0]),
        "shadow_rays": n_shadow,
        "hits": len(hits),
        "raw_embreex_rays_per_s": round(n_rays / best_raw),
        "pipeline_rays_per_s": round(n_rays / best_pipe),
        "pipeline_pulses_per_s": round(len(times) / best_pipe),
        "ratio": round(best_raw / best_pipe, 4),
        "required_ratio": 0.8,
        "repeat": repeat,
    }
