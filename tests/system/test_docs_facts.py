"""The docs cannot go stale: every module of both packages is in docs/design.md's module map and every module there
exists; every module's tests can be found by path; every module, file or name of the packages that a page of docs/
or the README names exists; the table of shipped scenes in docs/scene-format.md states what the scene files, the
built scenes and the pass estimate say."""

import importlib
import re
from pathlib import Path

import pytest

from scanner_sim.config import load_scene
from scanner_sim.survey.sizing import estimate_pass
from scanner_sim.world.scene import build_scene

ROOT = Path(__file__).resolve().parents[2]
PAGES = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]


def _table(page: str, heading: str) -> list[list[str]]:
    """The cells of the first Markdown table after ``heading`` in ``docs/page``, header and rule left out."""
    text = (ROOT / "docs" / page).read_text()
    rows, started = [], False
    for line in text[text.index(heading):].splitlines()[1:]:
        if line.startswith("|"):
            started = True
            rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
        elif started:
            break
    return rows[2:]


def test_the_module_map_lists_every_module_and_nothing_else():
    listed = {re.fullmatch(r"`(.+)`", row[0]).group(1) for row in _table("design.md", "### Module map")}
    modules = {str(p.relative_to(ROOT)) for pkg in ("muls", "scanner_sim") for p in (ROOT / pkg).rglob("*.py")}
    assert not modules - listed, f"modules missing from docs/design.md's module map: {sorted(modules - listed)}"
    assert not listed - modules, f"the module map names modules that do not exist: {sorted(listed - modules)}"


def test_every_module_has_its_tests_findable_by_path():
    """A module ``<package>/<stage>/<module>.py`` has ``tests/<package>/<stage>/test_<module>.py``, or its stage's
    tests README names it and says where its tests are (tests/README.md's rule)."""
    unplaced = []
    for package in ("muls", "scanner_sim"):
        for module in sorted((ROOT / package).rglob("*.py")):
            if module.name in ("__init__.py", "__main__.py"):
                continue
            tests = ROOT / "tests" / module.relative_to(ROOT).parent
            readme = tests / "README.md"
            if not (tests / f"test_{module.stem}.py").exists() and not (
                    readme.exists() and f"`{module.relative_to(ROOT)}`" in readme.read_text()):
                unplaced.append(str(module.relative_to(ROOT)))
    assert not unplaced, f"modules whose tests cannot be found by path: {unplaced}"


def test_every_test_file_the_docs_name_exists():
    """A page of docs/, the README or a stage's test README that names tests/.../test_x.py names a file that is there."""
    pages = PAGES + sorted((ROOT / "tests").rglob("README.md"))
    named = {(page.name, ref) for page in pages for ref in re.findall(r"tests/[\w/]*test_\w+\.py", page.read_text())}
    assert len(named) > 20
    assert not {(page, ref) for page, ref in named if not (ROOT / ref).exists()}


def _resolves(ref: str) -> bool:
    """Whether a file path (``scanner_sim/rays/cast.py``) or a dotted name (``scanner_sim.rays.cast.cast_beams``) of
    the packages exists."""
    if "/" in ref or ref.endswith(".py"):
        return (ROOT / ref).exists() or (ROOT / f"{ref}.py").exists()
    parts = ref.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for name in parts[i:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_module_and_name_the_docs_give_exists(page):
    refs = set(re.findall(r"(?<![\w/.])((?:scanner_sim|muls)(?:[/.][A-Za-z_]\w*)+/?)", page.read_text()))
    stale = sorted(ref for ref in refs if not _resolves(ref.rstrip("/")))
    assert not stale, f"{page.name} names what does not exist: {stale}"


def _number(text: str) -> float:
    return float(text.replace(",", ""))


@pytest.mark.parametrize("row", _table("scene-format.md", "## Shipped scenes"), ids=lambda row: row[0])
def test_the_shipped_scenes_table_states_what_the_scenes_are(row):
    name, _, water, platform, seabed, scanner, pulses = row
    config = load_scene(re.search(r"`(\w+)`", name).group(1))
    p, sc = config.platform, config.scanner
    assert water == config.water.preset
    if p.mode == "static":
        panel = next(o for o in config.objects if o.type == "panel")
        below = p.position_m[2] - panel.center_m[2]
        assert platform == f"static, panel {below:g} m below"
        assert scanner == "static"
    else:
        assert platform == f"{p.altitude_m:g} m altitude, {p.speed_m_s:g} m/s"
        assert scanner == f"{sc.mode}, {sc.scan_rate_hz:g} Hz, {sc.sector_deg:g}°"
    scene = build_scene(config)
    triangles = sum(o.face_stop - o.face_start for o in scene.objects if o.kind == "seabed")
    assert seabed == (f"{triangles:,} triangles" if triangles else "none")
    estimate = estimate_pass(config)
    stated = re.fullmatch(r"([\d,]+)(?: \(([\d.]+) s\))?", pulses)
    assert _number(stated.group(1)) == estimate.pulses
    if stated.group(2):
        assert _number(stated.group(2)) == pytest.approx(estimate.pass_s)
