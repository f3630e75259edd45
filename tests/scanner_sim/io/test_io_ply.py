"""scene.ply: labelled truth meshes read back by plyfile, trimesh and read_scene_ply."""

from __future__ import annotations

import numpy as np
import plyfile
import pytest
import trimesh

from scanner_sim import io

OFFSET = (500_000.0, 6_000_000.0, -40.0)  # a UTM-like local origin: large world coordinates


@pytest.fixture
def labelled_box():
    box = trimesh.creation.box(extents=(2.0, 3.0, 1.0))
    labels = np.arange(len(box.faces)) % 4 + 2
    oids = np.arange(len(box.faces)) * 10 - 1
    return box.vertices + np.asarray(OFFSET), box.faces, labels, oids


def test_scene_ply_round_trip_with_trimesh(tmp_path, labelled_box):
    vertices, faces, labels, oids = labelled_box
    path = tmp_path / "scene.ply"
    io.write_scene_ply(path, vertices, faces, labels, oids)
    mesh = trimesh.load(path, process=False)
    np.testing.assert_array_equal(mesh.vertices, vertices)  # doubles: no float32 rounding
    np.testing.assert_array_equal(mesh.faces, faces)
    face_data = mesh.metadata["_ply_raw"]["face"]["data"]
    np.testing.assert_array_equal(face_data["label"], labels)
    np.testing.assert_array_equal(face_data["object_id"], oids)
    back = io.read_scene_ply(path)
    np.testing.assert_array_equal(back["vertices"], vertices)
    np.testing.assert_array_equal(back["faces"], faces)
    np.testing.assert_array_equal(back["face_label"], labels)
    np.testing.assert_array_equal(back["face_object_id"], oids)
    with pytest.raises(ValueError, match="face_label: values span"):
        io.write_scene_ply(tmp_path / "x.ply", vertices, faces, labels + 300, oids)


def test_scene_ply_is_standard_ply(tmp_path, labelled_box):
    """plyfile parses the header and every element without knowing the layout in advance."""
    vertices, faces, labels, oids = labelled_box
    io.write_scene_ply(tmp_path / "scene.ply", vertices, faces, labels, oids)
    ply = plyfile.PlyData.read(tmp_path / "scene.ply")
    assert not ply.text and ply.byte_order == "<"
    assert [(p.name, p.val_dtype) for p in ply["vertex"].properties] == [("x", "f8"), ("y", "f8"), ("z", "f8")]
    assert str(ply["face"].ply_property("vertex_indices")) == "property list uchar int vertex_indices"
    np.testing.assert_array_equal(np.stack(ply["face"]["vertex_indices"]), faces)
    np.testing.assert_array_equal(ply["face"]["label"], labels)
    np.testing.assert_array_equal(ply["face"]["object_id"], oids)


def test_read_scene_ply_reads_an_ascii_ply_from_another_writer(tmp_path, labelled_box):
    vertices, faces, labels, oids = labelled_box
    v = np.zeros(len(vertices), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("red", "u1")])
    v["x"], v["y"], v["z"] = vertices.T
    f = np.zeros(len(faces), dtype=[("object_id", "i4"), ("vertex_indices", "i4", (3,)), ("label", "u1")])
    f["vertex_indices"], f["label"], f["object_id"] = faces, labels, oids
    elements = [plyfile.PlyElement.describe(v, "vertex"), plyfile.PlyElement.describe(f, "face")]
    plyfile.PlyData(elements, text=True).write(tmp_path / "other.ply")
    back = io.read_scene_ply(tmp_path / "other.ply")
    np.testing.assert_allclose(back["vertices"], vertices, rtol=1e-15)
    np.testing.assert_array_equal(back["faces"], faces)
    np.testing.assert_array_equal(back["face_label"], labels)
    np.testing.assert_array_equal(back["face_object_id"], oids)


def test_read_scene_ply_refuses_unlabelled_or_broken_files(tmp_path):
    trimesh.creation.box().export(tmp_path / "plain.ply")
    with pytest.raises(ValueError, match="label and object_id"):
        io.read_scene_ply(tmp_path / "plain.ply")
    (tmp_path / "broken.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n")
    with pytest.raises(ValueError, match="not a readable PLY"):
        io.read_scene_ply(tmp_path / "broken.ply")
