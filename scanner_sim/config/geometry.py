"""What the rays see: the procedural seabed and the objects (a discriminated union on ``type``).

Every surface has a material (or a reflectance at 532 nm, which wins) and a class label, from
:mod:`scanner_sim.config.materials`; :func:`surface` makes the base model that carries them with a kind's defaults.
Objects placed by [x, y] rest on the seabed; [x, y, z] gives the ground level z directly.
"""

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

from pydantic import (
    BeforeValidator,
    Field,
    PlainSerializer,
    PrivateAttr,
    ValidationInfo,
    WithJsonSchema,
    model_validator,
)

from scanner_sim.config.base import (
    Choice,
    Fraction,
    Fractions,
    Integer,
    NonNegative,
    Number,
    Points,
    Positive,
    Real,
    StrictModel,
    Vector,
    choice_check,
)
from scanner_sim.config.errors import checked_at, invalid
from scanner_sim.config.materials import LABELS, MATERIALS
from scanner_sim.config.sections import MAX_SEED, check_depth_m

#: A seabed above 2,000,000 triangles is tiled (scanner_sim.world.site): the pass holds its heights (8 bytes a node,
#: about 4 a triangle) and meshes only windows of it; generating the relief takes about five times the heights.
MAX_SEABED_TRIANGLES = 32_000_000


def surface(default_material: str, default_label: str) -> type[StrictModel]:
    """A base model with ``material``, ``reflectance`` and ``label``, defaulting to this material and label."""

    class Surface(StrictModel):
        material: Choice(*MATERIALS) | None = default_material
        """Material from the table (its reflectance at 532 nm)."""
        reflectance: Fraction | None = None
        """Lambertian reflectance at 532 nm; wins over material."""
        label: Choice(*LABELS) = default_label
        """Ground-truth class (its LAS 1.4 classification code)."""

        @model_validator(mode="after")
        def _reflects(self):
            if self.material is None and self.reflectance is None:
                raise invalid(f"give a material ({', '.join(MATERIALS)}) or a reflectance in [0, 1]")
            return self

    return Surface


def reflectance_of(section) -> float:
    """Reflectance at 532 nm of a seabed, rocks or object section: ``reflectance`` if given, else the
    material's."""
    return section.reflectance if section.reflectance is not None else MATERIALS[section.material].reflectance


class ReliefConfig(StrictModel):
    """Fractal relief by spectral synthesis."""

    rms_m: NonNegative = 0.2
    """RMS height [m]."""
    wavelength_m: Positive = 10.0
    """Largest feature wavelength [m]."""
    hurst: Number(gt=0.0, le=1.0) = 0.7
    """Hurst exponent (roughness)."""


class RipplesConfig(StrictModel):
    """Sand ripples."""

    amplitude_m: NonNegative = 0.0
    """Half the trough-to-crest height [m]."""
    wavelength_m: Positive = 0.6
    crest_deg: Real = 0.0
    """Crest direction from +x, counter-clockwise [deg]."""
    sinuosity: NonNegative = 0.15
    """Crest meander [wavelengths]."""


class RocksConfig(surface("rock", "rock")):
    """Rocks scattered on the seabed."""

    count: Integer(ge=0, le=10000) = 0
    radius_min_m: Positive = 0.1
    radius_max_m: Positive = 0.4

    @model_validator(mode="after")
    def _radius_order(self):
        if self.radius_max_m < self.radius_min_m:
            raise invalid(f"must be >= radius_min_m ({self.radius_min_m!r})", key="radius_max_m",
                          value=self.radius_max_m)
        return self


class SeabedConfig(surface("terrigenous_sand", "seabed")):
    """A procedural seabed over a rectangle: mean depth, relief, ripples, rocks; generated from its seed."""

    size_m: Vector(2, element=Positive)
    """x, y extent [m]."""
    center_m: Vector(2) = (0.0, 0.0)
    resolution_m: Positive = 0.1
    """Node spacing [m]; at most 32,000,000 triangles (above 2,000,000 the seabed is tiled)."""
    depth_m: NonNegative = 20.0
    """Mean level z = -depth_m [m]."""
    seed: Integer(ge=0, le=MAX_SEED) = 0
    relief: ReliefConfig = ReliefConfig()
    ripples: RipplesConfig = RipplesConfig()
    rocks: RocksConfig = RocksConfig()

    @model_validator(mode="after")
    def _triangle_budget(self):
        check_depth_m(self.depth_m, "depth_m")
        nx, ny = (s / self.resolution_m + 1 for s in self.size_m)
        if nx < 2 or ny < 2:
            raise invalid(f"must be at most the seabed size {list(self.size_m)}", key="resolution_m",
                          value=self.resolution_m)
        triangles = 2 * (nx - 1) * (ny - 1)
        if triangles > MAX_SEABED_TRIANGLES:
            raise invalid(f"gives {triangles:,.0f} triangles over {list(self.size_m)} m, more than the "
                          f"{MAX_SEABED_TRIANGLES:,} allowed; use a coarser resolution or a smaller seabed",
                          key="resolution_m", value=self.resolution_m)
        return self


def scene_object(tag: str, default_material: str, default_label: str) -> type[StrictModel]:
    """The base model of the objects of type ``tag``: the tag, a ``name`` and the surface fields."""

    class ObjectBase(surface(default_material, default_label)):
        kind: ClassVar[str] = tag
        type: Literal[tag]
        name: str = tag

        @property
        def rests_on_seabed(self) -> bool:
            """Placed by [x, y]: the object needs a seabed to stand on."""
            return False

    return ObjectBase


class OnSeabed(StrictModel):
    """An object standing at ``position_m``."""

    position_m: Vector(2, 3)
    """[x, y] on the seabed, or [x, y, z] with the ground level z given [m]."""

    @property
    def rests_on_seabed(self) -> bool:
        return len(self.position_m) == 2


class CableObject(scene_object("cable", "polyethylene", "cable")):
    """A tube swept along a natural cubic spline through ``points_m``, lying on the seabed, partly buried."""

    points_m: Points(2, 3)
    """[x, y] points on the seabed, or [x, y, z] [m]."""
    diameter_m: Positive = 0.05
    burial_fraction: Fractions = 0.3
    """Share of the diameter below the seabed: one number, or one per point."""
    sides: Integer(ge=3, le=64) = 12
    """Tube facets."""
    step_m: Positive = 0.05
    """Centreline resampling [m]."""
    stiffness_length_m: NonNegative = 0.5
    """The seabed height is low-passed over this length along the cable (it bridges ripple troughs) [m]."""

    @model_validator(mode="after")
    def _burial_per_point(self):
        if len({tuple(p[:2]) for p in self.points_m}) < 2:
            raise invalid("the points coincide in plan; a cable needs two distinct [x, y] points", key="points_m",
                          value=[list(p) for p in self.points_m])
        if isinstance(self.burial_fraction, tuple) and len(self.burial_fraction) != len(self.points_m):
            raise invalid(f"must be one number or one per point ({len(self.points_m)})", key="burial_fraction",
                          value=list(self.burial_fraction))
        return self

    @property
    def rests_on_seabed(self) -> bool:
        return len(self.points_m[0]) == 2


class MooredMineObject(OnSeabed, scene_object("moored_mine", "painted_steel", "mine")):
    """A sphere moored on a tether, its centre ``height_m`` above the seabed."""

    radius_m: Positive = 0.5
    height_m: Positive = 2.0
    """Height of the sphere's centre above the seabed [m]."""
    tether_diameter_m: Positive = 0.02

    @model_validator(mode="after")
    def _above_seabed(self):
        if self.height_m <= self.radius_m:
            raise invalid(f"must be > radius_m ({self.radius_m!r})", key="height_m", value=self.height_m)
        return self


class CylinderMineObject(OnSeabed, scene_object("cylinder_mine", "painted_steel", "mine")):
    """A cylinder lying on the seabed, its axis horizontal along a compass heading."""

    radius_m: Positive = 0.27
    length_m: Positive = 1.8
    heading_deg: Real = 0.0
    """Compass direction of the axis [deg]."""
    burial_fraction: Fraction = 0.0
    """Share of the diameter below the seabed."""


class ConeMineObject(OnSeabed, scene_object("cone_mine", "painted_steel", "mine")):
    """A truncated cone standing on the seabed (a bottom mine)."""

    bottom_radius_m: Positive = 0.5
    top_radius_m: NonNegative = 0.2
    height_m: Positive = 0.4
    burial_fraction: Fraction = 0.0
    """Share of the height below the seabed."""


class PanelObject(scene_object("panel", "black_painted_aluminium", "panel")):
    """A flat rectangle facing ``normal``; ``up`` gives its height direction."""

    center_m: Vector(3)
    """Centre [x, y, z] [m]."""
    size_m: Vector(2, element=Positive) = (1.0, 1.0)
    """Width and height [m]."""
    normal: Vector(3) = (0.0, 0.0, 1.0)
    up: Vector(3) = (0.0, 1.0, 0.0)

    @model_validator(mode="after")
    def _facing(self):
        if not any(self.normal):
            raise invalid("must be a non-zero vector", key="normal", value=list(self.normal))
        return self


def _path_or_mesh(value: Any) -> Any:
    if isinstance(value, str) or type(value).__name__ == "Trimesh":  # trimesh imported only where a mesh is loaded
        return value
    raise invalid("must be a path to a mesh file (relative to the scene file) or, from Python, a trimesh.Trimesh",
                  value=value)


def _mesh_json(value: Any) -> Any:
    """A mesh source as JSON: the path, or a mesh's digest (its vertices' and faces' bytes)."""
    if isinstance(value, str):
        return value
    import hashlib

    import numpy as np

    digest = hashlib.sha256(np.ascontiguousarray(value.vertices, np.float64).tobytes())
    digest.update(np.ascontiguousarray(value.faces, np.int64).tobytes())
    return {"in_memory_mesh_sha256": digest.hexdigest()}


#: A mesh file's path, or (from Python) a trimesh.Trimesh.
MeshSource = Annotated[Any, BeforeValidator(_path_or_mesh), PlainSerializer(_mesh_json, when_used="json"),
                       WithJsonSchema({"type": "string", "description": "Path relative to the scene file."})]


class MeshObject(scene_object("mesh", "painted_steel", "wreck")):
    """Any mesh file trimesh reads: scaled, rotated (about x, y, z) then translated."""

    file: MeshSource
    """Path relative to the scene file (from Python: a trimesh.Trimesh in memory)."""
    translate_m: Vector(2, 3) = (0.0, 0.0, 0.0)
    """[x, y] puts the mesh's lowest point on the seabed there; [x, y, z] places it exactly [m]."""
    rotate_deg: Vector(3) = (0.0, 0.0, 0.0)
    """Roll, pitch, yaw about x, y, z [deg]."""
    scale: Positive = 1.0
    _resolved_path: Path = PrivateAttr()

    @model_validator(mode="after")
    def _file_exists(self, info: ValidationInfo):
        if not isinstance(self.file, str):  # a mesh in memory
            self._resolved_path = None
            return self
        path = Path(self.file)
        path = path if path.is_absolute() else Path((info.context or {}).get("base_dir") or Path.cwd()) / path
        if not path.is_file():
            raise invalid(f"file not found (looked for {path}); give a path relative to the scene file", key="file",
                          value=self.file)
        self._resolved_path = path
        return self

    @property
    def resolved_path(self) -> Path | None:
        """The mesh file, resolved against the scene file's folder (None for a mesh in memory)."""
        return self._resolved_path

    @property
    def rests_on_seabed(self) -> bool:
        return len(self.translate_m) == 2


OBJECT_TYPES = {cls.kind: cls for cls in (CableObject, MooredMineObject, CylinderMineObject, ConeMineObject,
                                           PanelObject, MeshObject)}


def _object_list(value: Any) -> Any:
    """A list of mappings with a known ``type`` (checked here, for the message, before the union picks)."""
    if not isinstance(value, (list, tuple)):
        raise invalid("must be a list of objects, each with a 'type'", value=value)
    for i, item in enumerate(value):
        if not isinstance(item, Mapping) or "type" not in item:
            raise invalid(f"must be a mapping with a 'type' among {', '.join(OBJECT_TYPES)}", key=f"[{i}]",
                          value=item)
        checked_at(f"[{i}].type", choice_check(*OBJECT_TYPES), item["type"])
    return tuple(value)


#: One object: the union of the kinds, told apart by ``type``.
AnyObject = Annotated[CableObject | MooredMineObject | CylinderMineObject | ConeMineObject | PanelObject | MeshObject,
                      Field(discriminator="type")]
#: The ``objects`` list as written.
Objects = Annotated[tuple[AnyObject, ...], BeforeValidator(_object_list)]
