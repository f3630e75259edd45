"""Ray casting behind one small backend interface: :class:`RayCaster` answers first-hit and occlusion queries of
float32 rays in the scene's local frame.

``embree`` (embreex, Embree 4) is the fast backend; ``numpy`` (trimesh's pure-python triangle test) is a slow
fallback for machines without embreex. ``auto`` picks embree when it imports and otherwise warns once and falls
back; asking for ``embree`` explicitly when embreex is missing raises at once. The backend is chosen at
construction, and the methods do not branch on a name per call but on the one attribute set there.
"""

from __future__ import annotations

import math
import threading
import warnings

import numpy as np

from muls.infra.errors import ParameterError

BACKENDS = ("auto", "embree", "numpy")


def embree_available() -> bool:
    try:
        import embreex.rtcore_scene  # noqa: F401
    except Exception:  # pragma: no cover - depends on the machine
        return False
    return True


def ray_caster(vertices_local: np.ndarray, faces: np.ndarray, backend: str = "auto") -> RayCaster:
    """The caster over a mesh: vertices_local (n_vertices, 3) float [m], already shifted near the origin (the scene
    does this); faces (n_faces, 3) int; ``backend`` one of :data:`BACKENDS`."""
    if backend not in BACKENDS:
        raise ParameterError(f"raycast backend = {backend!r}: must be one of {', '.join(map(repr, BACKENDS))}")
    if backend == "auto":
        backend = "embree" if embree_available() else "numpy"
        if backend == "numpy":
            warnings.warn("embreex is not importable: ray casting falls back to trimesh's numpy "
                          "intersector, about 100 times slower", RuntimeWarning, stacklevel=2)
    return (EmbreeCaster if backend == "embree" else NumpyCaster)(vertices_local, faces)


class RayCaster:
    """First-hit and occlusion queries against one triangle mesh in a local frame (the interface; a backend
    implements :meth:`first_hits_raw` and :meth:`occluded_raw`). Rays passed in are float32 in the mesh's local
    frame (converted if needed). Build one with :func:`ray_caster` or :meth:`for_scene`."""

    backend = ""

    def __init__(self, vertices_local: np.ndarray, faces: np.ndarray):
        self._local = threading.local()
        self.vertices = np.ascontiguousarray(vertices_local, dtype=np.float32)
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)

    @classmethod
    def for_scene(cls, scene, backend: str = "auto") -> RayCaster:
        """The caster over a :class:`scanner_sim.world.scene.Scene`'s mesh in its local frame (builds the BVH)."""
        return ray_caster(scene.vertices - scene.local_origin, scene.faces, backend=backend)

    def workspace(self, name: str, shape: tuple, dtype) -> np.ndarray:
        """A reusable scratch array (per thread) for temporaries that never leave the ray stage.

        Fresh multi-megabyte arrays per chunk cost page faults comparable to the ray casting itself here;
        the stage's float32 ray buffers are reused instead (grown when a chunk is larger).
        """
        pool = self._local.__dict__.setdefault("pool", {})
        size = math.prod(shape)
        buf = pool.get(name)
        if buf is None or buf.size < size or buf.dtype != np.dtype(dtype):
            buf = np.empty(max(size, 1), dtype)
            pool[name] = buf
        return buf[:size].reshape(shape)

    def first_hits_raw(self, origins: np.ndarray, directions: np.ndarray):
        """Per-ray answer, no compaction: ``(tri_index (n,) int32, -1 for a miss; distance_m (n,) float32)``."""
        raise NotImplementedError

    def occluded_raw(self, origins, directions, max_distance_m) -> np.ndarray:
        """Per-ray occlusion answer as Embree gives it: (n,) int, >= 0 when something lies on the ray."""
        raise NotImplementedError

    def first_hits(self, origins: np.ndarray, directions: np.ndarray):
        """First hit of each ray.

        origins, directions: (n, 3) float32 local frame, directions unit. Returns ``(ray_index (k,) int64,
        tri_index (k,) int64, distance_m (k,) float32)`` for the k rays that hit, in ray (scan) order;
        distance is along the unit direction.
        """
        origins = np.ascontiguousarray(origins, dtype=np.float32)
        directions = np.ascontiguousarray(directions, dtype=np.float32)
        if origins.shape[0] == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float32)
        prim, tfar = self.first_hits_raw(origins, directions)
        ray_index = np.flatnonzero(prim >= 0)
        return ray_index, prim[ray_index].astype(np.int64), tfar[ray_index]

    def occluded(self, origins: np.ndarray, directions: np.ndarray, max_distance_m: np.ndarray) -> np.ndarray:
        """(n,) bool: does any triangle lie on each ray between 0 and ``max_distance_m`` (n,)?

        Rays with ``max_distance_m`` <= 0 are empty: never occluded (Embree skips them).
        """
        origins = np.ascontiguousarray(origins, dtype=np.float32)
        directions = np.ascontiguousarray(directions, dtype=np.float32)
        max_distance_m = np.ascontiguousarray(max_distance_m, dtype=np.float32)
        if origins.shape[0] == 0:
            return np.zeros(0, bool)
        return (self.occluded_raw(origins, directions, max_distance_m) >= 0) & (max_distance_m > 0.0)


class EmbreeCaster(RayCaster):
    """Embree 4 through embreex."""

    backend = "embree"

    def __init__(self, vertices_local: np.ndarray, faces: np.ndarray):
        super().__init__(vertices_local, faces)
        try:
            import embreex.rtcore_scene  # noqa: F401
        except Exception as exc:
            raise ImportError("raycast backend 'embree' was asked for but embreex does not import "
                              f"({exc}); install it with `pip install embreex` or use backend 'auto'") from exc
        from .embree_upload import embree_scene

        self._scene = embree_scene(self.vertices, self.faces)
        # embreex builds the BVH (commits the scene) on the first query, unguarded: build it now, in one
        # thread, before chunks running side by side can each start a build of the same scene.
        self._scene.run(np.zeros((1, 3), np.float32), np.array([[0.0, 0.0, 1.0]], np.float32))

    @property
    def committed(self) -> bool:
        """Whether Embree has built the BVH."""
        return self._scene.is_committed == 1

    def first_hits_raw(self, origins: np.ndarray, directions: np.ndarray):
        result = self._scene.run(origins, directions, output=1)
        return result["primID"], result["tfar"]

    def occluded_raw(self, origins, directions, max_distance_m) -> np.ndarray:
        return self._scene.run(origins, directions, dists=max_distance_m, query="OCCLUDED")


class NumpyCaster(RayCaster):
    """trimesh's pure-python triangle test: a slow fallback for machines without embreex."""

    backend = "numpy"

    def __init__(self, vertices_local: np.ndarray, faces: np.ndarray):
        super().__init__(vertices_local, faces)
        import trimesh
        from trimesh.ray.ray_triangle import RayMeshIntersector

        self._numpy = RayMeshIntersector(trimesh.Trimesh(self.vertices.astype(np.float64), self.faces, process=False))

    def first_hits_raw(self, origins: np.ndarray, directions: np.ndarray):
        prim = np.full(origins.shape[0], -1, np.int32)
        tfar = np.full(origins.shape[0], np.inf, np.float32)
        if origins.shape[0] == 0:
            return prim, tfar
        tri, ray, loc = self._numpy.intersects_id(np.asarray(origins, np.float64), np.asarray(directions, np.float64),
                                                  multiple_hits=False, return_locations=True)
        dist = np.einsum("ij,ij->i", loc - origins[ray], directions[ray])
        prim[ray], tfar[ray] = tri, dist
        return prim, tfar

    def occluded_raw(self, origins, directions, max_distance_m) -> np.ndarray:
        prim, tfar = self.first_hits_raw(origins, directions)
        return np.where((prim >= 0) & (tfar < max_distance_m), 0, -1)
