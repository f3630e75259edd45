"""Scene files: YAML read strictly and within bounds, found by shipped name or by path.

The loader refuses, with one line naming the file, what a scene never needs and a hostile or broken file
could use to exhaust the machine (``docs/errors.md``): a file larger than :data:`MAX_SCENE_BYTES`, bytes that
are not UTF-8 text, nesting deeper than :data:`MAX_DEPTH`, aliases that expand to more than
:data:`MAX_NODES` nodes (the "billion laughs"), recursive aliases, explicit tags (``!!binary``,
``!!python/object``), keys that are not text (but the integer codes of a class raster's ``materials``), duplicate
keys, and a document that is not a mapping.
"""

import difflib
from pathlib import Path

import yaml

from scanner_sim.config.errors import ConfigError
from scanner_sim.config.scene_config import SceneConfig, parse_scene

#: The shipped scenes, loaded by name.
SCENES_DIR = Path(__file__).resolve().parents[2] / "scenes"

#: Largest scene file read [bytes]; the shipped scenes are a few kilobytes, 256 KiB holds a track of
#: about 10,000 waypoints and loads in about a second.
MAX_SCENE_BYTES = 256 << 10
#: Deepest nesting of collections (a scene needs 4: objects, an object, its points, a point).
MAX_DEPTH = 32
#: Most values (scalars and collections) a document may hold once its aliases are expanded.
MAX_NODES = 1_000_000

#: libyaml's loader when PyYAML was built with it (several times faster), else the pure-Python one.
_BaseLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class StrictLoader(_BaseLoader):
    """SafeLoader whose mappings refuse duplicate keys (PyYAML silently keeps the last one) and keys that are
    not text, and which refuses the hazards of the document's shape (:func:`_check_events`) before composing
    it, whoever loads with it (scene and campaign files)."""

    def __init__(self, stream):
        if hasattr(stream, "read"):
            stream = stream.read()
        _check_events(stream)
        super().__init__(stream)
        self.code_keyed: set[int] = set()  # ids of the mapping nodes keyed by integer codes (CODE_KEYED)


class _Refused(yaml.YAMLError):
    """A hazard the loader refuses; ``problem`` says what, ``problem_mark`` where."""

    def __init__(self, problem: str, mark):
        super().__init__(problem)
        self.problem, self.problem_mark = problem, mark


def _refused(event_or_node, problem: str) -> _Refused:
    return _Refused(problem, event_or_node.start_mark)


_NODE_EVENTS = (yaml.ScalarEvent, yaml.SequenceStartEvent, yaml.MappingStartEvent)
_END_EVENTS = (yaml.SequenceEndEvent, yaml.MappingEndEvent)


def _check_events(text: str) -> None:
    """Refuse, from the parser's events and before anything is composed, explicit tags, nesting deeper than
    :data:`MAX_DEPTH`, recursive aliases and more than :data:`MAX_NODES` values with aliases expanded (each
    alias counts as the values of its anchor, so a "billion laughs" stops at once, in bounded memory)."""
    nodes = 0
    open_collections: list[tuple[str | None, int]] = []  # (anchor, nodes before it) of each open collection
    expanded: dict[str, int] = {}  # anchor -> values under it, aliases expanded
    for event in yaml.parse(text, Loader=_BaseLoader):
        if isinstance(event, yaml.AliasEvent):
            if any(anchor == event.anchor for anchor, _ in open_collections):
                raise _refused(event, f"alias *{event.anchor} is recursive (it refers to a node that contains it)")
            if event.anchor not in expanded:
                raise _refused(event, f"alias *{event.anchor} has no anchor &{event.anchor} before it")
            nodes += expanded[event.anchor]
        elif isinstance(event, _NODE_EVENTS):
            if event.tag not in (None, "!"):
                shown = event.tag.replace("tag:yaml.org,2002:", "!!")
                raise _refused(event, f"tag {shown} is not allowed in scene files (write plain values)")
            if isinstance(event, yaml.ScalarEvent):
                nodes += 1
                if event.anchor is not None:
                    expanded[event.anchor] = 1
            elif len(open_collections) >= MAX_DEPTH:
                raise _refused(event, f"nested deeper than {MAX_DEPTH} levels")
            else:
                open_collections.append((event.anchor, nodes))
        elif isinstance(event, _END_EVENTS):
            anchor, before = open_collections.pop()
            nodes += 1
            if anchor is not None:
                expanded[anchor] = nodes - before
        if nodes > MAX_NODES:
            raise _refused(event, f"more than {MAX_NODES:,} values once anchors and aliases are expanded")


#: Keys whose value is a mapping keyed by integer codes: a class raster's ``materials`` (code -> material).
CODE_KEYED = frozenset({"materials"})


def _construct_mapping(loader, node, deep=False):
    seen = set()
    for key_node, value_node in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":  # ``<<: *defaults``, resolved by flatten_mapping
            continue
        key = loader.construct_object(key_node, deep=deep) if isinstance(key_node, yaml.ScalarNode) else None
        if key in CODE_KEYED and isinstance(value_node, yaml.MappingNode):
            loader.code_keyed.add(id(value_node))
        code = type(key) is int and id(node) in loader.code_keyed
        if not isinstance(key, str) and not code:
            shown = repr(key) if isinstance(key_node, yaml.ScalarNode) else f"a {key_node.id}"
            raise _refused(key_node, f"key {shown} is not text; keys are names such as format_version")
        if key in seen:
            raise _refused(key_node, f"{key}: duplicate key")
        seen.add(key)
    return loader.construct_mapping(node, deep)


StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def shipped_scenes() -> dict[str, Path]:
    """Shipped scene names -> their files, from the top-level ``scenes/`` folder."""
    return {p.stem: p for p in sorted(SCENES_DIR.glob("*.yaml"))}


def resolve_scene_path(name_or_path: str | Path) -> Path:
    """A shipped scene's name, or a path to a YAML file."""
    text = str(name_or_path)
    if not text.strip():
        raise ConfigError(f"scene = {text!r}: empty; give a shipped scene name or a YAML file")
    path = Path(text)
    if path.suffix in (".yaml", ".yml") or path.exists():
        if path.is_dir():
            raise ConfigError(f"scene = {text!r}: a folder, not a scene file")
        if not path.exists():
            raise ConfigError(f"scene = {text!r}: file not found")
        if not path.is_file():
            raise ConfigError(f"scene = {text!r}: not a regular file (a device or a pipe)")
        return path
    scenes = shipped_scenes()
    if text in scenes:
        return scenes[text]
    hint = difflib.get_close_matches(text, list(scenes), n=1)
    raise ConfigError(f"scene = {text!r}: not a file nor a shipped scene; "
                      + (f"did you mean {hint[0]!r}? " if hint else "") + f"(shipped: {', '.join(scenes)})")


def read_scene_text(path: Path, kind: str = "scene") -> str:
    """The text of a scene (or ``kind``, e.g. campaign) file: at most :data:`MAX_SCENE_BYTES`, UTF-8, no NUL bytes;
    else ConfigError naming the file."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_SCENE_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the {kind} file ({exc.strerror or exc})") from None
    if len(raw) > MAX_SCENE_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_SCENE_BYTES:,} bytes; a {kind} file is a few kilobytes of YAML")
    if b"\0" in raw:
        nul = raw.index(b"\0")
        raise ConfigError(f"{path}: binary data (a NUL byte at offset {nul:,}); a {kind} file is YAML text")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start:,}); "
                          f"save the {kind} file as UTF-8") from None


def load_strict_yaml(text: str):
    """The value a YAML text holds, read by :class:`StrictLoader` (its refusals raise ``yaml.YAMLError``)."""
    return yaml.load(text, Loader=StrictLoader)


def parse_yaml_text(text: str, path: Path, kind: str = "scene", keys: str = "format_version, name, platform, ...") -> dict:
    """The mapping a scene (or ``kind``) file's text holds, ``keys`` an example of its keys; raises a one-line
    ConfigError naming ``path`` for anything else."""
    try:
        data = load_strict_yaml(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        if isinstance(exc, yaml.reader.ReaderError):
            where = f" at offset {exc.position:,}"
        problem = getattr(exc, "problem", None) or (str(exc).splitlines() or ["unreadable"])[0]
        problem = " ".join(str(problem).split())
        if "nesting depth" in problem:
            # PyYAML (6.0.4 here) has a nesting limit of its own (1,000), which its scanner may reach before the parser
            # hands us the 33rd level: the user hears the project's limit either way.
            problem = f"nested deeper than {MAX_DEPTH} levels"
        if isinstance(exc, _Refused) or problem == f"nested deeper than {MAX_DEPTH} levels":
            raise ConfigError(f"{path}:{where}: {problem}") from None
        raise ConfigError(f"{path}: YAML syntax error{where}: {problem}") from None
    if data is None:
        raise ConfigError(f"{path}: empty; a {kind} file starts with 'format_version: 1'")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the document is a {type(data).__name__}, not a mapping of {kind} keys ({keys})")
    return data


def load_scene(name_or_path: str | Path) -> SceneConfig:
    """Read and validate a scene file (by shipped name or path). Raises :class:`ConfigError` (one line)."""
    path = resolve_scene_path(name_or_path)
    data = parse_yaml_text(read_scene_text(path), path)
    return parse_scene(data, base_dir=path.parent, source_path=path)
