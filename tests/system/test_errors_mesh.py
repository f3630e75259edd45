"""Mesh files (docs/errors.md): mesh files that are empty, unreadable or garbage, with NaN or infinite vertices, faces
that index missing vertices, or only degenerate triangles, are one-line ConfigErrors naming the object (its key
``objects[i]`` and name) and the file, never a traceback or a scene with silently missing triangles.

The property tests hand ``load_mesh_file`` whatever Hypothesis makes of OBJ text and of raw bytes in every
format trimesh reads by suffix; a mesh that loads has finite vertices and faces that index them.
"""

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scanner_sim.cli import main
from scanner_sim.config import SCENES_DIR, ConfigError, MeshObject, load_scene
from scanner_sim.world.mesh_file import load_mesh_file
from scanner_sim.world.scene import build_scene

PROPERTY = settings(max_examples=60, derandomize=True, deadline=3000,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _mesh_object(path, name="wreck") -> MeshObject:
    return MeshObject.model_validate({"type": "mesh", "name": name, "file": str(path)})


def _check(path, index=3, name="wreck"):
    """load_mesh_file's result, or its one-line error naming the object and the file (None then)."""
    try:
        v, f = load_mesh_file(_mesh_object(path, name), index)
    except ConfigError as exc:
        text = str(exc)
        assert "\n" not in text and f"objects[{index}]" in text and repr(name) in text and path.name in text, text
        return None
    assert v.ndim == 2 and v.shape[1] == 3 and np.isfinite(v).all()
    assert f.ndim == 2 and f.shape[1] == 3 and len(f) and f.min() >= 0 and f.max() < len(v)
    return v, f


CASES = {
    "empty.obj": ("", "no triangles"),
    "empty.stl": ("", "no triangles"),
    "points_only.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles"),
    "garbage.ply": (b"\x00\xff" * 700, "not a mesh file trimesh can read"),
    "garbage.stl": (bytes(range(256)) * 4, "no triangles"),
    "text.off": ("this is not a mesh\n", "not a mesh file trimesh can read"),
    "unknown.xyz": ("1 2 3\n", "not a mesh file trimesh can read"),
    "nan.obj": ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "not finite"),
    "inf.obj": ("v 0 0 0\nv 1 inf 0\nv 0 1 0\nf 1 2 3\n", "not finite"),
    "missing_vertex.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "not a mesh file trimesh can read"),
    "missing_vertex.ply": ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                           "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                           "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "refers to vertex"),
    "huge_header.ply": ("ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\nproperty float x\n"
                        "property float y\nproperty float z\nend_header\n", "not a mesh file trimesh can read"),
    "degenerate.obj": ("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\nf 1 1 2\n", "degenerate"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_mesh_file_is_one_line_naming_object_and_file(name, tmp_path):
    content, piece = CASES[name]
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(ConfigError) as exc:
        load_mesh_file(_mesh_object(path), 3)
    text = str(exc.value)
    assert "\n" not in text and piece in text, text
    assert text.startswith(f"objects[3].file = {str(path)!r} (object 'wreck')"), text


def test_unreadable_mesh_file(tmp_path):
    path = tmp_path / "gone.obj"
    path.write_text("v 0 0 0\n")
    obj = _mesh_object(path)
    path.unlink()  # validated, then gone before the scene is built
    with pytest.raises(ConfigError, match="not a mesh file trimesh can read"):
        load_mesh_file(obj, 0)


def test_a_good_mesh_loads_as_before():
    """The shipped mooring block loads to the same arrays trimesh's own processing gives."""
    import trimesh

    path = SCENES_DIR / "assets" / "mooring_block.obj"
    v, f = _check(path)
    ref = trimesh.load(path, force="mesh")
    assert np.array_equal(v, ref.vertices) and np.array_equal(f, ref.faces)


def test_bad_mesh_stops_validate_build_with_exit_2(tmp_path, capsys):
    """End to end: a NaN vertex in mine_field's mooring block is exit 2 and one line naming objects[3]."""
    data = yaml.safe_load((SCENES_DIR / "mine_field.yaml").read_text())
    (tmp_path / "assets").mkdir()
    (tmp_path / "assets" / "mooring_block.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 nan 1\nf 1 2 3\n")
    scene = tmp_path / "mine_field.yaml"
    scene.write_text(yaml.safe_dump(data))
    assert main(["validate", "--build", str(scene)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "objects[3].file = 'assets/mooring_block.obj' (object 'mooring_block')" in err and "not finite" in err


def test_transform_to_non_finite_coordinates_is_refused(tmp_path):
    data = yaml.safe_load((SCENES_DIR / "mine_field.yaml").read_text())
    data["objects"][3].update(scale=1e308, translate_m=[0.0, 0.0, -10.0])
    (tmp_path / "assets").mkdir()
    (tmp_path / "assets" / "mooring_block.obj").write_text((SCENES_DIR / "assets" / "mooring_block.obj").read_text())
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"objects\[3\] \(.mooring_block.\): .* not finite or beyond"):
        build_scene(load_scene(tmp_path / "s.yaml"))


# -- properties ---------------------------------------------------------------------------------------------
_coordinate = st.one_of(st.floats(min_value=-1e6, max_value=1e6), st.sampled_from(["nan", "inf", "-inf", "1e400"]),
                        st.integers(-5, 5))
_vertex = st.tuples(_coordinate, _coordinate, _coordinate).map(lambda c: "v " + " ".join(map(str, c)))
_face = st.lists(st.integers(-3, 12), min_size=3, max_size=4).map(lambda ix: "f " + " ".join(map(str, ix)))


@PROPERTY
@given(lines=st.lists(st.one_of(_vertex, _face, st.just("# comment"), st.text(max_size=12)), max_size=30))
def test_any_obj_text_loads_clean_or_is_one_line(lines, tmp_path_factory):
    path = tmp_path_factory.mktemp("obj") / "any.obj"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8", errors="surrogatepass")
    _check(path)


@PROPERTY
@given(suffix=st.sampled_from(["obj", "stl", "ply", "off", "glb", "gltf", "dae", "3mf", "xyz"]),
       content=st.binary(max_size=1500))
def test_any_bytes_in_any_mesh_format_load_clean_or_are_one_line(suffix, content, tmp_path_factory):
    path = tmp_path_factory.mktemp("bytes") / f"any.{suffix}"
    path.write_bytes(content)
    _check(path, index=0, name="any")


@PROPERTY
@given(vertices=st.lists(st.tuples(*[st.floats(allow_nan=True, allow_infinity=True, width=32)] * 3), max_size=12),
       faces=st.lists(st.tuples(*[st.integers(0, 14)] * 3), max_size=12), binary=st.booleans())
def test_any_ply_loads_clean_or_is_one_line(vertices, faces, binary, tmp_path_factory):
    """Well-formed PLY files with any numbers and any indices: the content checks, not the parser, decide."""
    import struct

    header = (f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\nelement vertex {len(vertices)}\n"
              "property float x\nproperty float y\nproperty float z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    if binary:
        body = b"".join(struct.pack("<3f", *v) for v in vertices) + b"".join(struct.pack("<B3i", 3, *f) for f in faces)
    else:
        body = ("".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in vertices)
                + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces)).encode()
    path = tmp_path_factory.mktemp("ply") / "any.ply"
    path.write_bytes(header + body)
    _check(path)
