"""Colours of points: by class, by detection channel, or by a scalar field through its colour map.

Class colours (:data:`CLASS_COLOURS`) are keyed by the scene's label *names*; the codes come from
the class table (``scanner_sim.config.materials.CLASS_NAMES``: the scene labels of ``docs/scene-format.md``, and
noise):

=================  =========================  ==========
label name         colour                     RGB
=================  =========================  ==========
seabed, sand, mud  sand                       214 189 133
rock               grey                       128 128 128
cable              orange                     255 140   0
pipeline           yellow                     240 215  30
mine               red                        230  25  25
tether             dark pink                  170  40 110
panel, target      white                      245 245 245
wreck              brown                      140  85  40
object             light blue                 110 180 230
debris             olive                      150 140  90
vegetation, algae  green                       60 160  60
unlabelled, none   dark grey                   70  70  70
noise (LAS 7)      magenta                    255   0 255
=================  =========================  ==========

Other names take a colour from a fixed qualitative cycle indexed by their code.

A seabed is coloured by height (:func:`shaded_height_rgb`): its z through :data:`HEIGHT_COLOUR_MAP`, hill-shaded by
the surface's normals, so that its relief reads at a glance.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from scanner_sim.config.materials import CLASS_NAMES

#: Label name -> RGB colour (0..255).
CLASS_COLOURS: dict[str, tuple[int, int, int]] = {
    "seabed": (214, 189, 133),
    "ground": (214, 189, 133),
    "sand": (214, 189, 133),
    "mud": (150, 120, 80),
    "rock": (128, 128, 128),
    "cable": (255, 140, 0),
    "pipeline": (240, 215, 30),
    "mine": (230, 25, 25),
    "tether": (170, 40, 110),
    "panel": (245, 245, 245),
    "target": (245, 245, 245),
    "wreck": (140, 85, 40),
    "object": (110, 180, 230),
    "debris": (150, 140, 90),
    "vegetation": (60, 160, 60),
    "algae": (60, 160, 60),
    "unlabelled": (70, 70, 70),
    "none": (70, 70, 70),
    "noise": (255, 0, 255),
}

_CYCLE = [(31, 119, 180), (44, 160, 44), (148, 103, 189), (23, 190, 207), (188, 189, 34),
          (227, 119, 194), (255, 187, 120), (152, 223, 138), (197, 176, 213), (158, 218, 229)]

#: ``color_by`` value -> (matplotlib colour map, scalar bar title, symmetric limits?).
SCALAR_COLOUR_MAPS: dict[str, tuple[str, str, bool]] = {
    "depth": ("viridis_r", "depth [m] (-z)", False),
    "intensity": ("viridis", "intensity", False),
    "tvu": ("plasma", "TVU 95 % [m]", False),
    "range_error": ("coolwarm", "range error [m]", True),
    "snr": ("magma", "SNR", False),
    "amplitude": ("viridis", "amplitude [LSB]", False),
    "incidence": ("plasma", "incidence [deg]", False),
}

#: Colour map of a seabed's heights: perceptually uniform, dark (deep) to light (shallow), readable in grey and by
#: colour-blind readers.
HEIGHT_COLOUR_MAP = "viridis"
#: Hill-shading light: from the north-west (azimuth 315 deg clockwise from north), 45 deg above the horizon, the
#: cartographers' convention (light from the top left of a north-up map makes relief read raised, not sunken).
HILLSHADE_AZIMUTH_DEG = 315.0
HILLSHADE_ALTITUDE_DEG = 45.0
#: Detection channels 1, 2, 3... (RGB), the colours of the waveform plots: blue, orange, red, then green, purple.
CHANNEL_COLOURS: tuple[tuple[int, int, int], ...] = ((31, 119, 180), (255, 127, 14), (214, 39, 40), (44, 160, 44),
                                                     (148, 103, 189))



def class_table(class_names: Mapping[int, str] | None = None) -> dict[int, str]:
    """Class code -> name: ``class_names`` when given, else the scene labels and noise
    (:data:`scanner_sim.config.materials.CLASS_NAMES`)."""
    if class_names is not None:
        return {int(k): str(v) for k, v in class_names.items()}
    return dict(CLASS_NAMES)


def _class_colour(code: int, name: str | None) -> tuple[int, int, int]:
    if name is not None and name.lower() in CLASS_COLOURS:
        return CLASS_COLOURS[name.lower()]
    return _CYCLE[code % len(_CYCLE)]


def categorical_rgb(values, color_by: str, class_names: Mapping[int, str] | None = None):
    """Colours of categories: ``color_by`` "class" (the class table's colours) or "channel" (CH1 blue, CH2
    orange, CH3 red...). Returns ((n, 3) uint8 RGB, {code: (RGB, legend label)})."""
    codes = np.asarray(values).astype(np.int64)
    if color_by == "class":
        table = class_table(class_names)
        lut = {int(c): (_class_colour(int(c), table.get(int(c))), f"{table.get(int(c), 'class')}, class {c}")
               for c in np.unique(codes)}
    else:
        lut = {int(c): (CHANNEL_COLOURS[(int(c) - 1) % len(CHANNEL_COLOURS)], f"CH{c}") for c in np.unique(codes)}
    rgb = np.zeros((len(codes), 3), dtype=np.uint8)
    for c, (col, _) in lut.items():
        rgb[codes == c] = col
    return rgb, lut


def point_rgb(values, color_by: str, class_names: Mapping[int, str] | None = None) -> np.ndarray:
    """(n, 3) float RGB in [0, 1] of points coloured by ``color_by``: categories as :func:`categorical_rgb`,
    other fields through their colour map (:data:`SCALAR_COLOUR_MAPS`) between their 1st and 99th
    percentiles (symmetric about 0 for the range error)."""
    if color_by in ("class", "channel"):
        return categorical_rgb(values, color_by, class_names)[0] / 255.0
    from matplotlib import colormaps

    cmap, _, symmetric = SCALAR_COLOUR_MAPS.get(color_by, ("viridis", color_by, False))
    v = np.asarray(values, float)
    good = v[np.isfinite(v)]
    if symmetric:
        m = float(np.percentile(np.abs(good), 99)) if good.size else 1.0
        lo, hi = -m, m
    else:
        lo, hi = np.percentile(good, [1, 99]) if good.size else (0.0, 1.0)
    level = np.clip((v - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    return np.where(np.isfinite(v)[:, None], colormaps[cmap](level)[:, :3], [1.0, 0.0, 1.0])


def shaded_height_rgb(z, normals, clim: tuple[float, float]) -> np.ndarray:
    """(n, 3) float RGB in [0, 1]: heights ``z`` (n,) [m] through :data:`HEIGHT_COLOUR_MAP` between ``clim`` (lo, hi)
    [m], hill-shaded by the surface's unit ``normals`` (n, 3) under the light of :data:`HILLSHADE_AZIMUTH_DEG` and
    :data:`HILLSHADE_ALTITUDE_DEG` (matplotlib's :class:`~matplotlib.colors.LightSource`, soft-light blend)."""
    from matplotlib import colormaps
    from matplotlib.colors import LightSource

    lo, hi = clim
    level = np.clip((np.asarray(z, float) - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    rgb = colormaps[HEIGHT_COLOUR_MAP](level)[:, :3]
    if not len(rgb):
        return rgb
    light = LightSource(azdeg=HILLSHADE_AZIMUTH_DEG, altdeg=HILLSHADE_ALTITUDE_DEG)
    intensity = light.shade_normals(np.asarray(normals, float), fraction=1.0)
    return light.blend_soft_light(rgb[:, None, :], intensity[:, None, None])[:, 0, :]
