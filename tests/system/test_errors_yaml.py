"""Scene files (docs/errors.md): scene files that are not text, not YAML, not a mapping, nested too deep, aliased without
bound, tagged, keyed by non-text or twice, are refused fast, in bounded memory, with one line naming the file.

The property tests feed the loader whatever Hypothesis makes of bytes, of YAML documents and of a valid scene
with one value replaced; the one outcome allowed besides a valid scene is a one-line ConfigError.
"""

import copy
import time
import tracemalloc

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scanner_sim.config import SCENES_DIR, ConfigError, SceneConfig, load_scene, parse_scene
from scanner_sim.config.loading import MAX_DEPTH, MAX_NODES, MAX_SCENE_BYTES

#: Bounded, repeatable property runs: CI runs the same examples every time, well inside a minute in total.
PROPERTY = settings(max_examples=60, derandomize=True, deadline=2000,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
#: A refused file is refused within this time [s] and this much Python memory [bytes].
FAST_S = 2.0
BOUNDED_BYTES = 50 << 20


def _one_line(exc: ConfigError, name: str | None = None) -> str:
    text = str(exc)
    assert "\n" not in text and text.strip(), text
    assert len(text) < 600, text
    if name is not None:
        assert name in text, text
    return text


def _refused(path, *pieces) -> str:
    with pytest.raises(ConfigError) as exc:
        load_scene(path)
    text = _one_line(exc.value, path.name)
    for piece in pieces:
        assert piece in text, text
    return text


def _write(tmp_path, content, name="scene.yaml"):
    path = tmp_path / name
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    else:
        path.write_bytes(content)
    return path


BILLION_LAUGHS = "\n".join(["a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
                           + [f"{chr(98 + i)}: &{chr(98 + i)} [" + ", ".join([f"*{chr(97 + i)}"] * 9) + "]"
                              for i in range(9)]) + "\n"

HAZARDS = {
    "binary": (b"\x7fELF\x02\x01\x01\x00" + bytes(range(256)), ["binary data", "NUL byte"]),
    "not_utf8": ("format_version: 1\nname: caf\xe9\n".encode("latin-1"), ["not UTF-8"]),
    "not_yaml": ("format_version: 1\nname: [unclosed\nplatform: {", ["YAML syntax error", "line"]),
    "control_char": ("name: a\x07b\n", ["YAML syntax error"]),
    "empty": ("", ["empty"]),
    "comment_only": ("# nothing here\n", ["empty"]),
    "a_list": ("- format_version: 1\n- name: x\n", ["a list, not a mapping"]),
    "a_scalar": ("just some words", ["a str, not a mapping"]),
    "two_documents": ("name: a\n---\nname: b\n", ["YAML syntax error"]),
    "deep_flow": ("[" * 100_000 + "]" * 100_000, ["nested deeper than 32"]),
    "deep_block": ("a:\n" + "".join("  " * i + f"k{i}:\n" for i in range(1, 200)), ["nested deeper than 32"]),
    "billion_laughs": (BILLION_LAUGHS, [f"more than {MAX_NODES:,} values"]),
    "recursive_alias": ("platform: &p {mode: static, attitude: *p}\n", ["recursive"]),
    "undefined_alias": ("name: *nowhere\n", ["alias"]),
    "python_tag": ("name: !!python/object/apply:os.system ['echo hi']\n", ["tag !!python/object/apply:os.system"]),
    "binary_tag": ("name: !!binary aGVsbG8=\n", ["tag !!binary"]),
    "custom_tag": ("name: !secret x\n", ["tag !secret"]),
    "int_key": ("format_version: 1\n7: seven\n", ["key 7 is not text", "line 2"]),
    "null_key": ("null: x\n", ["key None is not text"]),
    "list_key": ("? [a, b]\n: c\n", ["key a sequence is not text"]),
    "duplicate_key": ("format_version: 1\nname: a\nname: b\n", ["name: duplicate key", "line 3"]),
    "too_large": ("# " + "x" * MAX_SCENE_BYTES + "\n", [f"larger than {MAX_SCENE_BYTES:,} bytes"]),
}


@pytest.mark.parametrize("case", sorted(HAZARDS))
def test_hazard_refused_fast_in_bounded_memory_with_one_line(case, tmp_path):
    content, pieces = HAZARDS[case]
    path = _write(tmp_path, content)
    tracemalloc.start()
    started = time.perf_counter()
    try:
        _refused(path, *pieces)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.perf_counter() - started < FAST_S
    assert peak < BOUNDED_BYTES + 4 * len(content), peak


def test_limits_leave_room_for_real_scenes():
    """The shipped scenes are far inside every limit: the deepest is 4 levels, the largest a few kB."""
    assert MAX_DEPTH >= 8 and MAX_NODES >= 100_000
    for path in SCENES_DIR.glob("*.yaml"):
        assert path.stat().st_size < MAX_SCENE_BYTES // 16
        assert isinstance(load_scene(path), SceneConfig)


def test_harmless_anchors_and_merge_keys_still_load(tmp_path):
    """Aliases are counted, not banned: a scene may reuse a section with an anchor or a merge key."""
    text = (SCENES_DIR / "pool_panel.yaml").read_text()
    text = text.replace("platform:\n", "platform: &vehicle\n") + "\n# reuse\n"
    text = text.replace("objects:\n  - type: panel", "objects:\n  - &panel\n    type: panel")
    path = _write(tmp_path, text)
    assert load_scene(path).name == "pool_panel"


def test_a_directory_a_device_and_nothing_are_refused(tmp_path):
    for scene, piece in ((tmp_path, "a folder"), ("/dev/null", "not a regular file"), ("", "empty"),
                         (tmp_path / "missing.yaml", "file not found")):
        with pytest.raises(ConfigError) as exc:
            load_scene(scene)
        assert piece in _one_line(exc.value)


# -- properties ---------------------------------------------------------------------------------------------
@PROPERTY
@given(content=st.binary(max_size=2000))
def test_any_bytes_give_a_scene_or_one_line_naming_the_file(content, tmp_path_factory):
    path = _write(tmp_path_factory.mktemp("bytes"), content, "any.yaml")
    try:
        load_scene(path)
    except ConfigError as exc:
        _one_line(exc)


#: YAML values: what a scene file could hold, keys of every scalar kind included.
_scalars = st.one_of(st.none(), st.booleans(), st.integers(min_value=-(2**70), max_value=2**70),
                     st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=20))
_values = st.recursive(_scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4),
    st.dictionaries(st.one_of(st.text(max_size=12), st.integers(), st.booleans(), st.none()), inner, max_size=4)),
    max_leaves=30)


@PROPERTY
@given(document=_values)
def test_any_yaml_document_gives_a_scene_or_one_line(document, tmp_path_factory):
    path = _write(tmp_path_factory.mktemp("doc"), yaml.safe_dump(document), "doc.yaml")
    try:
        load_scene(path)
    except ConfigError as exc:
        _one_line(exc)


def _leaves(node, path=()):
    """Every (path, value) of a nested mapping / list, sections included."""
    yield path, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _leaves(v, (*path, i))


_SCENES = {name: yaml.safe_load((SCENES_DIR / f"{name}.yaml").read_text())
           for name in ("pool_panel", "mine_field", "cable_survey")}
_PATHS = {name: [p for p, _ in _leaves(data) if p] for name, data in _SCENES.items()}


@PROPERTY
@given(data=st.data(), name=st.sampled_from(sorted(_SCENES)), value=_values)
def test_a_valid_scene_with_any_value_replaced_gives_a_scene_or_one_line(data, name, value):
    scene = copy.deepcopy(_SCENES[name])
    path = data.draw(st.sampled_from(_PATHS[name]), label="key")
    node = scene
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    try:
        parse_scene(scene, base_dir=SCENES_DIR)
    except ConfigError as exc:
        _one_line(exc)


@PROPERTY
@given(depth=st.integers(min_value=MAX_DEPTH + 1, max_value=5000), flow=st.booleans())
def test_any_nesting_past_the_limit_is_refused(depth, flow, tmp_path_factory):
    text = ("[" * depth + "]" * depth) if flow else "".join("  " * i + f"k{i}:\n" for i in range(depth)) + "  " * depth + "x"
    path = _write(tmp_path_factory.mktemp("deep"), text, "deep.yaml")
    with pytest.raises(ConfigError) as exc:
        load_scene(path)
    message = _one_line(exc.value, path.name)
    assert f"nested deeper than {MAX_DEPTH}" in message or "larger than" in message, message  # deep blocks are long


@PROPERTY
@given(fan=st.integers(min_value=2, max_value=12), levels=st.integers(min_value=1, max_value=40))
def test_alias_expansion_is_counted_not_followed(fan, levels, tmp_path_factory):
    """Each level refers to the previous ``fan`` times: fan**levels values once expanded. Past MAX_NODES the
    file is refused at once; below it, it loads (and then fails validation as an unknown key, in one line)."""
    lines = ["l0: &l0 x"] + [f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * fan) + "]" for i in range(1, levels + 1)]
    path = _write(tmp_path_factory.mktemp("alias"), "\n".join(lines) + "\n", "alias.yaml")
    expanded = sum(fan**i for i in range(levels + 1)) + sum(fan**i for i in range(1, levels + 1))
    started = time.perf_counter()
    with pytest.raises(ConfigError) as exc:
        load_scene(path)
    assert time.perf_counter() - started < FAST_S
    text = _one_line(exc.value)
    if expanded > 2 * MAX_NODES:
        assert f"more than {MAX_NODES:,} values" in text
