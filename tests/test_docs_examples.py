"""The scene-format page's complete example is a valid scene file as it stands."""

import re
from pathlib import Path

import yaml

from scanner_sim.config import SCENES_DIR, parse_scene

DOCS = Path(__file__).resolve().parent.parent / "docs"


def test_the_complete_example_of_the_scene_format_validates():
    text = (DOCS / "scene-format.md").read_text()
    section = text[text.index("## Complete commented example"):]
    example = re.search(r"```yaml\n(.*?)```", section, flags=re.S).group(1)
    config = parse_scene(yaml.safe_load(example), base_dir=SCENES_DIR)
    assert config.name == "example_cable_survey" and config.objects and config.seabed is not None
