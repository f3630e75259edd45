"""The ray-cast overlap of beam and receiver on a flat plate, beside MULS Eq. 11 (``scanner-sim overlap``)."""

from __future__ import annotations

import numpy as np

from scanner_sim.rays.beams import beam_pattern
from scanner_sim.rays.cast import CastScene, cast_beams
from scanner_sim.world.scene import plate_scene


def raycast_overlap(distances_m, geometry, subrays_count: int = 61, profile: str = "top_hat",
                    origin_m=(0.0, 0.0, 0.0), shadow_rays: bool = True) -> np.ndarray:
    """Ray-cast overlap at each distance: a plate perpendicular to the beam, ``distance_m`` away.

    One pulse per distance, beam straight down (nadir) from ``origin_m`` with the shaft along +x, so the
    receiver sits ``geometry.offset_m`` along x. Returns (n,) the share of beam energy hitting the plate
    inside the receiver's FOV cone and seen from the aperture: it converges to MULS Eq. 11 as sub-rays grow.
    """
    pattern = beam_pattern(subrays_count, profile)
    out = []
    o = np.asarray(origin_m, float)
    for z in np.asarray(distances_m, float):  # one small scene per distance
        scene = plate_scene(float(z), size_m=max(4.0, 4.0 * z), origin_m=o)
        down = np.array([[0.0, 0.0, -1.0]])
        hits = cast_beams(CastScene.build(scene), o[None, :], down, np.array([[1.0, 0.0, 0.0]]),
                          o[None, :] + [geometry.offset_m, 0, 0], down, pattern, geometry, shadow_rays=shadow_rays)
        out.append(hits.seen_fraction()[0])
    return np.array(out)
