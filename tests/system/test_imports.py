"""The package layering (pyproject.toml's import-linter contracts): each package of muls and of scanner_sim
imports only its own modules and the layers below it, lazy imports inside functions included, so no package-level
import cycle can form; and the physics never imports the mission."""

import shutil
import subprocess
import sys
from pathlib import Path

import grimp

ROOT = Path(__file__).resolve().parents[2]
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")


def _lint_imports(root: Path) -> subprocess.CompletedProcess:
    """lint-imports on the tree at ``root`` (its pyproject.toml's contracts, its packages)."""
    return subprocess.run([str(LINT_IMPORTS), "--no-cache"], cwd=root, capture_output=True, text=True,
                          env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"})


def test_the_layers_hold():
    proc = _lint_imports(ROOT)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-2000:]
    assert proc.stdout.count("KEPT") == 3


def test_an_upward_lazy_import_breaks_the_layers(tmp_path):
    """A copy of the tree with one import inside a function of config (the lowest stage but the records) that reaches
    up to survey: the contract sees it, though the import would run only when the function is called."""
    for package in ("muls", "scanner_sim"):
        shutil.copytree(ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__", "data"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    base = tmp_path / "scanner_sim" / "config" / "base.py"
    base.write_text(base.read_text() + "\n\ndef _upward():\n    from scanner_sim.survey import pipeline\n\n"
                    "    return pipeline\n")
    proc = _lint_imports(tmp_path)
    assert proc.returncode == 1
    assert "scanner_sim stages, top down BROKEN" in proc.stdout
    assert "scanner_sim.config.base -> scanner_sim.survey.pipeline" in proc.stdout


def test_the_contracts_hold_without_exceptions():
    """No contract ignores an import: the optical model once fetched the Monte Carlo's tables by a lazy import upwards,
    excused in the contract; the Monte Carlo, which knows nothing of the lidar equation, now sits below the model."""
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert pyproject.count("[[tool.importlinter.contracts]]") == 3
    assert "ignore_imports" not in pyproject and "unmatched_ignore_imports_alerting" not in pyproject


def test_the_montecarlo_sits_below_the_model_it_validates():
    """The Monte Carlo (transport, runs, the tables) imports nothing of optics, the receiver, ranging or validation;
    optics imports the tables from it, and validation sets the two side by side."""
    graph = grimp.build_graph("muls", cache_dir=None)
    above = ("muls.optics", "muls.receiver", "muls.ranging", "muls.validation", "muls.studies", "muls.presets")
    assert not [a for a in above if graph.chain_exists("muls.montecarlo", a, as_packages=True)]
    assert graph.chain_exists("muls.optics", "muls.montecarlo", as_packages=True)
    assert graph.chain_exists("muls.validation", "muls.montecarlo", as_packages=True)


def test_the_physics_never_imports_the_mission():
    graph = grimp.build_graph("muls", "scanner_sim", cache_dir=None)
    physics = graph.find_children("muls") | {m for c in graph.find_children("muls") for m in graph.find_descendants(c)}
    reached = {t for m in physics for t in graph.find_modules_directly_imported_by(m)}
    assert len(physics) > 50 and not {t for t in reached if t.startswith("scanner_sim")}
