"""Scene files: YAML read strictly (duplicate keys are errors), found by shipped name or by path."""

import difflib
from pathlib import Path

import yaml

from .errors import ConfigError
from .scene_config import SceneConfig, parse_scene

#: The shipped scenes, loaded by name.
SCENES_DIR = Path(__file__).resolve().parents[2] / "scenes"


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that rejects duplicate keys (PyYAML silently keeps the last one)."""


def _construct_mapping(loader, node, deep=False):
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise ConfigError(f"{key}: duplicate key at line {key_node.start_mark.line + 1}")
        seen.add(key)
    return loader.construct_mapping(node, deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def shipped_scenes() -> dict[str, Path]:
    """Shipped scene names -> their files, from the top-level ``scenes/`` folder."""
    return {p.stem: p for p in sorted(SCENES_DIR.glob("*.yaml"))}


def resolve_scene_path(name_or_path: str | Path) -> Path:
    """A shipped scene's name, or a path to a YAML file."""
    text = str(name_or_path)
    path = Path(text)
    if path.suffix in (".yaml", ".yml") or path.exists():
        if not path.is_file():
            raise ConfigError(f"scene = {text!r}: file not found")
        return path
    scenes = shipped_scenes()
    if text in scenes:
        return scenes[text]
    hint = difflib.get_close_matches(text, list(scenes), n=1)
    raise ConfigError(f"scene = {text!r}: not a file nor a shipped scene; "
                      + (f"did you mean {hint[0]!r}? " if hint else "") + f"(shipped: {', '.join(scenes)})")


def load_scene(name_or_path: str | Path) -> SceneConfig:
    """Read and validate a scene file (by shipped name or path). Raises :class:`ConfigError` (one line)."""
    path = resolve_scene_path(name_or_path)
    try:
        data = yaml.load(path.read_text(), Loader=_StrictLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"{path.name}: YAML syntax error{where}: {problem}") from None
    return parse_scene(data, base_dir=path.parent, source_path=path)
