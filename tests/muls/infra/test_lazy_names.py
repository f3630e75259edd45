"""A package's public names load on first use: importing the package imports none of the modules behind them, a
name imports its own module once, and a name that is not public is an AttributeError naming it."""

import subprocess
import sys

import pytest
from conftest import ROOT

PROBE = """
import sys
import {package} as package
before = {module!r} in sys.modules
value = getattr(package, {name!r})
print(before, {module!r} in sys.modules, {name!r} in vars(package), {name!r} in dir(package))
"""


@pytest.mark.parametrize("package, name, module", [
    ("muls", "Water", "muls.water.properties"),
    ("scanner_sim", "run_pass", "scanner_sim.survey.pipeline"),
    ("scanner_sim.config", "load_scene", "scanner_sim.config.loading"),
])
def test_a_name_imports_its_module_on_first_use_only(package, name, module):
    printed = subprocess.run([sys.executable, "-c", PROBE.format(package=package, name=name, module=module)],
                             cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    assert printed == ["False", "True", "True", "True"]


def test_a_name_that_is_not_public_is_an_attribute_error():
    import muls

    with pytest.raises(AttributeError, match="'muls' has no attribute 'not_a_name'"):
        muls.not_a_name  # noqa: B018
    assert muls.__all__ == sorted(muls.__all__, key=str.lower) and "Water" in muls.__all__
