"""A triangle mesh handed to an embreex scene in one copy per buffer, instead of one Python index per element.

embreex's ``TriangleMesh`` fills Embree's vertex and index buffers in Cython loops over untyped arrays, so every
coordinate and every face row goes through Python indexing: 0.40 to 0.46 s for `cable_survey`'s 177,139 vertices
and 352,488 faces on the Intel machine, the largest part of a warm run's set-up, and 1.7 s of the 2.1 s the
caster of a 1.9 M-triangle seabed took (each window of a site's tiles pays it too).
:func:`embree_scene` asks Embree for the same two buffers in the same layout (float3 vertices at a 16-byte stride,
uint3 indices, Embree allocating and padding them as ``TriangleMesh`` has it do) and fills each with one numpy copy,
through Embree's C API called with ctypes on the very library embreex loaded. The scene stays embreex's and is
queried as before: the same geometry, the same BVH, the same hits.

embreex keeps the scene's and the device's handles in its Cython objects without exposing them. Their layout is
checked on every scene before a handle is read: the instance sizes, the public ``is_committed`` found at its offset,
the device object found at its own, and Embree's ``rtcGetSceneDevice`` naming the device read. Where the library or
that layout is not what this module knows (another embreex, another platform), the mesh goes in through
``TriangleMesh``, as before.
"""

from __future__ import annotations

import ctypes
import functools

import numpy as np

_PTR = ctypes.sizeof(ctypes.c_void_p)
#: Offsets in embreex 4.4's Cython objects: ``EmbreeScene`` {PyObject_HEAD; RTCScene scene_i; int is_committed;
#: EmbreeDevice device}, ``EmbreeDevice`` {PyObject_HEAD; RTCDevice device}.
_SCENE_HANDLE, _IS_COMMITTED, _DEVICE_OBJECT = 2 * _PTR, 3 * _PTR, 4 * _PTR
_SCENE_SIZE, _DEVICE_SIZE = 5 * _PTR, 3 * _PTR
_DEVICE_HANDLE = 2 * _PTR
_SENTINEL = 0x5A17E

# Embree 4's rtcore_common.h, rtcore_buffer.h and rtcore_geometry.h.
_GEOMETRY_TYPE_TRIANGLE = 0
_BUFFER_TYPE_INDEX, _BUFFER_TYPE_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_VERTEX_STRIDE = 16  # bytes, as TriangleMesh asks for: x, y, z and a pad Embree's 16-byte loads may read


def embree_scene(vertices: np.ndarray, faces: np.ndarray):
    """A new embreex ``EmbreeScene`` (robust, uncommitted) holding the mesh as its geometry 0: ``vertices``
    (n_vertices, 3) float32 [m, local frame], ``faces`` (n_faces, 3) int32 indices into them."""
    from embreex import rtcore, rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    device = rtcore.EmbreeDevice()
    scene = rtcore_scene.EmbreeScene(device=device)
    api = _embree_api()
    handles = _handles(scene, device, api) if api is not None and faces.shape[0] > 0 else None
    if handles is None:
        TriangleMesh(scene=scene, vertices=vertices, indices=faces)
    else:
        _attach(api, *handles, vertices, faces)
    return scene


def _attach(api, scene_handle: int, device_handle: int, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Give the scene a triangle geometry with Embree-allocated buffers filled from ``vertices`` and ``faces``."""
    geometry = api.rtcNewGeometry(device_handle, _GEOMETRY_TYPE_TRIANGLE)
    if not geometry:
        raise RuntimeError(f"Embree could not create a triangle geometry (error {api.rtcGetDeviceError(device_handle)})")
    try:
        vertex_buffer = _new_buffer(api, geometry, _BUFFER_TYPE_VERTEX, _FORMAT_FLOAT3, _VERTEX_STRIDE,
                                    vertices.shape[0], ctypes.c_float, 4)
        vertex_buffer[:, :3] = vertices
        index_buffer = _new_buffer(api, geometry, _BUFFER_TYPE_INDEX, _FORMAT_UINT3, 3 * 4, faces.shape[0],
                                   ctypes.c_uint32, 3)
        index_buffer[:] = faces
        api.rtcCommitGeometry(geometry)
        api.rtcAttachGeometry(scene_handle, geometry)
    finally:
        api.rtcReleaseGeometry(geometry)  # the scene holds its own reference
    error = api.rtcGetDeviceError(device_handle)
    if error:
        raise RuntimeError(f"Embree refused the mesh's buffers (error {error})")


def _new_buffer(api, geometry: int, kind: int, fmt: int, stride: int, count: int, ctype, columns: int) -> np.ndarray:
    """(count, columns) numpy view of a buffer Embree allocates for ``geometry`` (valid while the geometry lives)."""
    address = api.rtcSetNewGeometryBuffer(geometry, kind, 0, fmt, stride, count)
    if not address:
        raise RuntimeError(f"Embree could not allocate a buffer of {count} items")
    return np.ctypeslib.as_array((ctype * (columns * count)).from_address(address)).reshape(count, columns)


def _handles(scene, device, api) -> tuple[int, int] | None:
    """(RTCScene, RTCDevice) of an embreex scene made on ``device``, or None where its layout is not the one known."""
    if type(scene).__basicsize__ != _SCENE_SIZE or type(device).__basicsize__ != _DEVICE_SIZE:
        return None
    base = id(scene)
    was = scene.is_committed
    scene.is_committed = _SENTINEL
    at_offset = ctypes.c_int.from_address(base + _IS_COMMITTED).value
    scene.is_committed = was
    if at_offset != _SENTINEL or ctypes.c_void_p.from_address(base + _DEVICE_OBJECT).value != id(device):
        return None
    scene_handle = ctypes.c_void_p.from_address(base + _SCENE_HANDLE).value
    device_handle = ctypes.c_void_p.from_address(id(device) + _DEVICE_HANDLE).value
    if not scene_handle or not device_handle:
        return None
    named = api.rtcGetSceneDevice(scene_handle)  # a reference Embree counts: given back at once
    api.rtcReleaseDevice(named)
    return (scene_handle, device_handle) if named == device_handle else None


@functools.cache
def _embree_api():
    """ctypes functions of the Embree library embreex's extension loaded, or None when it cannot be named (the
    library is found among the process's mapped files, so it is embreex's own and not another copy)."""
    import embreex.rtcore_scene  # noqa: F401  (maps the library)

    path = _mapped_library("libembree4")
    if path is None:
        return None
    lib = ctypes.CDLL(path)
    ptr, uint, size = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
    signatures = {
        "rtcNewGeometry": (ptr, [ptr, ctypes.c_int]),
        "rtcSetNewGeometryBuffer": (ptr, [ptr, ctypes.c_int, uint, ctypes.c_int, size, size]),
        "rtcCommitGeometry": (None, [ptr]),
        "rtcAttachGeometry": (uint, [ptr, ptr]),
        "rtcReleaseGeometry": (None, [ptr]),
        "rtcGetSceneDevice": (ptr, [ptr]),
        "rtcReleaseDevice": (None, [ptr]),
        "rtcGetDeviceError": (ctypes.c_int, [ptr]),
    }
    for name, (restype, argtypes) in signatures.items():
        function = getattr(lib, name)
        function.restype, function.argtypes = restype, argtypes
    return lib


def _mapped_library(stem: str) -> str | None:
    """Path of the shared library whose file name starts with ``stem`` among this process's mappings (Linux), or
    None."""
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:  # address, permissions, offset, device, inode and, for a file, its path
                fields = line.split(maxsplit=5)
                if len(fields) == 6 and fields[5].rstrip().rsplit("/", 1)[-1].startswith(stem):
                    return fields[5].rstrip()
    except OSError:
        return None
    return None
