"""scene.ply: the truth meshes as one binary PLY with a class label and object id per face.

Written with numpy in one block per element and read with ``plyfile``. trimesh's PLY exporter stores
vertices as float32 (0.5 m steps at UTM northings), and plyfile's binary writer loops over faces in
Python (about 3 s for the 248,000 faces of ``seabed_lawnmower``); plyfile's reader memory-maps the
same layout and accepts any standard PLY that carries the properties.
"""

from __future__ import annotations

import numpy as np
import plyfile

from muls.infra.atomic import PathLike, atomic_open

__all__ = ["read_scene_ply", "write_scene_ply"]

_HEADER = (
    "ply\n"
    "format binary_little_endian 1.0\n"
    "comment muls-scanner truth scene; label = class code (docs/scene-format.md)\n"
    "element vertex {n_vertices}\n"
    "property double x\nproperty double y\nproperty double z\n"
    "element face {n_faces}\n"
    "property list uchar int vertex_indices\n"
    "property uchar label\n"
    "property int object_id\n"
    "end_header\n"
)
#: One binary face record: the list length (always 3), three vertex indices, label, object id.
_FACE_DTYPE = np.dtype([("count", "u1"), ("index", "<i4", (3,)), ("label", "u1"), ("object_id", "<i4")])


def write_scene_ply(path: PathLike, vertices, faces, face_label, face_object_id) -> None:
    """Write the truth meshes as one labelled binary PLY, atomically.

    Parameters
    ----------
    vertices : (n_vertices, 3) float [m]
        World coordinates; stored as ``double`` x, y, z (no float32 rounding of world coordinates).
    faces : (n_faces, 3) int
        Vertex indices of each triangle.
    face_label : (n_faces,) int
        Ground-truth class code per face (0..255, the scene label table), PLY ``uchar label``.
    face_object_id : (n_faces,) int
        Scene object id per face, PLY ``int object_id``.

    The file is ``binary_little_endian 1.0`` with ``element face`` properties
    ``list uchar int vertex_indices``, ``uchar label``, ``int object_id``: plyfile, trimesh, Open3D
    (geometry only), CloudCompare and MeshLab read it; ``trimesh.load(path, process=False)`` keeps
    the labels in ``mesh.metadata["_ply_raw"]["face"]["data"]["label"]`` (and ``"object_id"``).
    """
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices: shape {v.shape} is not allowed; expected (n_vertices, 3)")
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and f.dtype.kind not in "iu"):
        raise ValueError(f"faces: shape {f.shape} dtype {f.dtype} is not allowed; expected (n_faces, 3) integers")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"faces: indices span [{f.min()}, {f.max()}], outside 0..{len(v) - 1}")
    labels = np.asarray(face_label)
    if labels.shape != (len(f),):
        raise ValueError(f"face_label: shape {labels.shape} is not allowed; expected ({len(f)},)")
    if labels.size and (labels.min() < 0 or labels.max() > 255):
        raise ValueError(f"face_label: values span [{labels.min()}, {labels.max()}], allowed 0..255")
    oid = np.asarray(face_object_id)
    if oid.shape != (len(f),):
        raise ValueError(f"face_object_id: shape {oid.shape} is not allowed; expected ({len(f)},)")
    info = np.iinfo(np.int32)
    if oid.size and (oid.min() < info.min or oid.max() > info.max):
        raise ValueError("face_object_id: values do not fit int32")

    records = np.zeros(len(f), dtype=_FACE_DTYPE)
    records["count"] = 3
    records["index"] = f
    records["label"] = labels
    records["object_id"] = oid
    with atomic_open(path) as fh:
        fh.write(_HEADER.format(n_vertices=len(v), n_faces=len(f)).encode("ascii"))
        fh.write(v.astype("<f8").tobytes())
        fh.write(records.tobytes())


def read_scene_ply(path: PathLike) -> dict[str, np.ndarray]:
    """Read a labelled triangle PLY such as :func:`write_scene_ply` writes.

    Returns ``vertices`` (n_vertices, 3) float64 [m], ``faces`` (n_faces, 3) int64, ``face_label``
    (n_faces,) uint8 and ``face_object_id`` (n_faces,) int32. Raises ValueError if the file is not a
    PLY of triangles with ``label`` and ``object_id`` face properties.
    """
    try:
        ply = plyfile.PlyData.read(path, known_list_len={"face": {"vertex_indices": 3}})
    except plyfile.PlyParseError as exc:
        raise ValueError(f"{path}: not a readable PLY ({exc})") from None
    names = {element.name: {p.name for p in element.properties} for element in ply.elements}
    if not (names.get("vertex", set()) >= {"x", "y", "z"}
            and names.get("face", set()) >= {"vertex_indices", "label", "object_id"}):
        raise ValueError(f"{path}: not a labelled scene PLY (needs face properties label and object_id)")
    v, f = ply["vertex"].data, ply["face"].data
    faces = f["vertex_indices"]
    if faces.dtype == object:  # an ASCII PLY: one array per face
        if any(len(face) != 3 for face in faces):
            raise ValueError(f"{path}: not a triangle mesh (a face has other than 3 vertices)")
        faces = np.array(faces.tolist(), dtype=np.int64).reshape(-1, 3)
    return {
        "vertices": np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64),
        "faces": faces.astype(np.int64),
        "face_label": f["label"].astype(np.uint8),
        "face_object_id": f["object_id"].astype(np.int32),
    }
