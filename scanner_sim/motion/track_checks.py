"""Checks of a pass's track: what a pass refuses before it runs (:class:`ConfigError` naming the key) or warns
about (:class:`SetupWarning` naming it), the built track against the water surface, the seabed and the objects.
``docs/errors.md`` lists them. :func:`build_trajectory` builds a scene's trajectory and checks its track.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from muls.water.properties import MAX_ATTENUATION_EXPONENT
from scanner_sim.config.errors import ConfigError, SetupWarning, config_value
from scanner_sim.motion.trajectory import PATH_STEP_M, Trajectory, trajectory_of
from scanner_sim.world.raster import lawnmower_area


def build_trajectory(config, scene=None) -> Trajectory:
    """The :class:`Trajectory` of a :class:`scanner_sim.config.SceneConfig` over its built ``scene``, its track
    checked against the water surface, the seabed and the objects (:func:`check_track`). Raises
    :class:`ConfigError` naming the key; warns (:class:`SetupWarning`) about set-ups that run but likely not as
    meant. The pass's size is checked before, by :func:`scanner_sim.survey.sizing.check_pass_budget`."""
    trajectory = trajectory_of(config, scene)
    check_track(config, scene, trajectory)
    return trajectory


#: Faster than survey vehicles go [m/s]; a faster speed is likely in km/h or knots (warned about).
MAX_PLAUSIBLE_SPEED_M_S = 10.0
#: Largest number of track samples tested against one object's mesh.
MAX_CONTAINS_SAMPLES = 20_000



def track_length_m(platform, seabed=None) -> tuple[float, int]:
    """(length [m], legs) of a platform's track in plan, by arithmetic on the scene keys (nothing allocated but,
    for a lawnmower that leaves its area to a raster ``seabed`` section, the raster's valid pixels)."""
    if platform.mode == "static":
        return 0.0, 1
    if platform.mode == "lawnmower":
        lm = platform.lawnmower
        size = lm.size_m if lm.size_m is not None else lawnmower_area(lm, seabed)[1]
        n_lines = math.floor(size[1] / lm.line_spacing_m + 1e-9) + 1
        return n_lines * size[0] + (n_lines - 1) * lm.line_spacing_m, 2 * n_lines - 1
    seg = np.linalg.norm(np.diff(np.asarray(platform.waypoints_m, float)[:, :2], axis=0), axis=1)
    return float(seg.sum()), int(np.count_nonzero(seg > 1e-9))


def track_span_s(config) -> tuple[float, float]:
    """(track_s, pass_s) [s] of a moving platform, by arithmetic on the scene keys: the time to run its whole
    track at its speed, and the pass's length (``survey.duration_s``, else the track's)."""
    track_s = track_length_m(config.platform, config.seabed)[0] / config.platform.speed_m_s
    return track_s, (config.survey.duration_s if config.survey.duration_s is not None else track_s)


def _vertical_key(config) -> str:
    p = config.platform
    if p.mode == "static" and len(p.position_m) == 3:
        return "platform.position_m"
    return "platform.altitude_m" if p.altitude_m is not None else "platform.depth_m"


def _plan_key(config) -> str:
    return {"static": "platform.position_m", "lawnmower": "platform.lawnmower"}.get(config.platform.mode,
                                                                                   "platform.waypoints_m")


def _at(x, y, z=None) -> str:
    return f"x = {x:.1f}, y = {y:.1f}" + (f", z = {z:+.2f}" if z is not None else "") + " m"


def check_track(config, scene, trajectory: Trajectory) -> None:
    """Refuse a pass whose vehicle rises above the water surface (z > 0), goes under the seabed, passes
    through an object or a rock, or never passes over the seabed; warn (:class:`SetupWarning`) when part of
    the track lies off the seabed, the speed is implausible, the pass runs past the end of the track, or the
    seabed lies beyond where any echo returns. ``trajectory``'s precomputed path is tested (every PATH_STEP_M),
    over the part the pass runs."""
    p, sv = config.platform, config.survey
    track_s, pass_s = track_span_s(config) if not trajectory.static else (0.0, 0.0)
    s, xyz = trajectory.path()
    if trajectory.static:
        xyz = xyz[:1]
    else:
        s0, s1 = sv.start_s * trajectory.speed_m_s, (sv.start_s + pass_s) * trajectory.speed_m_s
        xyz = xyz[(s >= s0 - PATH_STEP_M) & (s <= s1 + PATH_STEP_M)]
    vertical = _vertical_key(config)
    top = int(np.argmax(xyz[:, 2]))
    if xyz[top, 2] > 0.0:
        raise ConfigError(f"{vertical} = {config_value(config, vertical)}: the vehicle rises above the water surface (z = 0 "
                          f"in scene files) to {_at(*xyz[top])}; altitude_m is metres above the seabed")
    hf = scene.heightfield if scene is not None else None
    if hf is not None:
        x0, x1, y0, y1 = hf.extent_m
        over = (xyz[:, 0] >= x0) & (xyz[:, 0] <= x1) & (xyz[:, 1] >= y0) & (xyz[:, 1] <= y1)
        plan = _plan_key(config)
        if not over.any():
            raise ConfigError(f"{plan} = {config_value(config, plan)}: the track never passes over the seabed (x {x0:g} to "
                              f"{x1:g}, y {y0:g} to {y1:g} m)")
        if not over.all():
            warnings.warn(SetupWarning(f"{plan}: {1 - over.mean():.0%} of the track lies off the seabed (x {x0:g} to "
                                       f"{x1:g}, y {y0:g} to {y1:g} m); no bottom is seen there"), stacklevel=3)
        ground = hf.height(xyz[over, 0], xyz[over, 1])
        under = int(np.argmin(xyz[over, 2] - ground))
        if xyz[over][under, 2] < ground[under]:
            depth = ground[under] - xyz[over][under, 2]
            hint = (f" (the altitude follows the seabed smoothed over follow_length_m = {p.follow_length_m:g} m)"
                    if vertical == "platform.altitude_m" else "")
            raise ConfigError(f"{vertical} = {config_value(config, vertical)}: the vehicle goes {depth:.2f} m under the "
                              f"seabed at {_at(*xyz[over][under])}{hint}")
        reach = float(np.median(xyz[over, 2] - ground)) * 2.0 * config.water_model().two_way_attenuation_per_m
        if reach > MAX_ATTENUATION_EXPONENT:
            warnings.warn(SetupWarning(
                f"{vertical} = {config_value(config, vertical)}: the seabed lies about {np.median(xyz[over, 2] - ground):,.0f} m "
                f"below the vehicle, where the water leaves e^-{reach:.0f} of the light: expect no returns "
                "(lengths are in metres)"), stacklevel=3)
    _check_objects(config, scene, xyz)
    if not trajectory.static and p.speed_m_s > MAX_PLAUSIBLE_SPEED_M_S:
        warnings.warn(SetupWarning(f"platform.speed_m_s = {p.speed_m_s!r}: faster than survey vehicles go (about 0.5 "
                                   f"to 3 m/s, at most {MAX_PLAUSIBLE_SPEED_M_S:g}); speeds are in m/s, not km/h or "
                                   "knots"), stacklevel=3)
    past = sv.start_s + pass_s - track_s
    if not trajectory.static and past > 1e-6:
        key = "survey.duration_s" if sv.duration_s is not None else "survey.start_s"
        warnings.warn(SetupWarning(f"{key} = {config_value(config, key)}: the pass runs {past:,.1f} s past the end of the "
                                   f"track ({track_s:,.1f} s long), where the vehicle holds its last pose"),
                      stacklevel=3)


def _check_objects(config, scene, xyz: np.ndarray) -> None:
    """Refuse a track that passes through a closed mesh: an object's, or a rock's."""
    if scene is None:
        return
    first_object = len(scene.objects) - len(config.objects)  # the seabed and its rocks come first
    for obj in scene.objects:
        if obj.kind == "seabed" or obj.face_stop == obj.face_start:
            continue
        faces = scene.faces[obj.face_start:obj.face_stop]
        corners = scene.vertices[np.unique(faces)]
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        near = xyz[((xyz >= lo) & (xyz <= hi)).all(axis=1)]
        if not len(near):
            continue
        import trimesh  # here: a track that comes near no object (most) never pays its import, about a second

        used, local = np.unique(faces, return_inverse=True)
        mesh = trimesh.Trimesh(scene.vertices[used] - scene.local_origin, local.reshape(-1, 3), process=False)
        if not mesh.is_watertight:  # an open surface (a panel) has no inside
            continue
        near = near[:: max(1, len(near) // MAX_CONTAINS_SAMPLES)]
        hit = mesh.contains(near - scene.local_origin)
        if hit.any():
            where = _at(*near[int(np.argmax(hit))])
            name = ("a rock (seabed.rocks)" if obj.kind == "rocks" else
                    f"objects[{obj.object_id - first_object}] ({obj.name!r})")
            plan, vertical = _plan_key(config), _vertical_key(config)
            raise ConfigError(f"{plan}: the vehicle passes through {name} at {where}; move the track or raise "
                              f"{vertical.split('.')[-1]}")
