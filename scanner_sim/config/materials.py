"""Materials (Lambertian reflectance at 532 nm, each with its source) and class labels (LAS 1.4 codes).

Scene files name a material and a label for every surface; the reflectance and the classification code of
its triangles come from these tables (``docs/scene-format.md`` lists them with the reasons).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Material:
    """Diffuse (Lambertian) reflectance at 532 nm and where the value comes from."""

    reflectance: float
    source: str


# The project's design gives these four reflectances at 532 nm without the measurements behind them. For
# comparison only: the bottom spectra of Maritorena, Morel & Gentili (1994, Limnol. Oceanogr. 39(7), Fig. 6)
# read 0.42 for coral sand, 0.23 for a green alga (Boodlea) and 0.041 for brown algae at 525 nm, rising
# towards 532 nm.
MATERIALS: dict[str, Material] = {
    "carbonate_sand": Material(0.43, "design value for carbonate sand at 532 nm; primary measurement not recorded in "
                                     "this project"),
    "terrigenous_sand": Material(0.14, "design value for terrigenous sand at 532 nm; primary measurement not recorded "
                                       "in this project"),
    "green_algae": Material(0.25, "design value for green algae at 532 nm; primary measurement not recorded in this "
                                  "project"),
    "brown_algae": Material(0.045, "design value for brown algae at 532 nm; primary measurement not recorded in this "
                                   "project"),
    "black_painted_aluminium": Material(0.10, "MULS paper sections 4.2 and 4.3: the target panel, reflectance 0.1"),
    # Named assumptions (docs/scene-format.md gives the reason for each):
    "mud": Material(0.08, "assumption: dark fine silt, darker than terrigenous sand"),
    "rock": Material(0.20, "assumption: bare grey rock with light fouling"),
    "polyethylene": Material(0.30, "assumption: weathered black/yellow polyethylene cable sheath, partly fouled"),
    "painted_steel": Material(0.15, "assumption: painted steel with fouling and corrosion (mines, wrecks)"),
    "concrete": Material(0.35, "assumption: grey concrete with light fouling"),
}

#: Class labels -> LAS 1.4 classification codes. 40 (bathymetric point, seafloor) and 43 (submerged object,
#: not otherwise specified) are ASPRS standard codes of the topo-bathy domain profile; 64-255 are user
#: definable, used here for the object classes.
LABELS: dict[str, int] = {
    "seabed": 40,
    "object": 43,
    "cable": 64,
    "mine": 65,
    "panel": 66,
    "wreck": 67,
    "rock": 68,
    "pipeline": 69,
    "debris": 70,
}

#: LAS class of a return that no echo explains (noise, a false alarm on the water column): ASPRS class 7,
#: "low point (noise)", which LAS tools treat as noise. It is not a label a scene can give a surface.
NOISE_CLASS = 7

#: Class code -> name, for legends: the labels and noise.
CLASS_NAMES: dict[int, str] = {code: name for name, code in LABELS.items()} | {NOISE_CLASS: "noise"}
