"""What the tests share: the repository's root, the command lines run in process, a small scene in UTM coordinates,
the waters and models of the muls detection tests, the Chromium of the browser tests, a signal that Python drops.
Test files import these by name (``from conftest import run_cli``).

Where a test file goes: tests/muls/<stage>/ or tests/scanner_sim/<stage>/ for the module it tests, named
``test_<module>.py`` when it tests one module (a stage's README.md says where the others are); tests/system/ for
end-to-end passes, the command lines' error handling, the docs' facts and the package layering."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

#: The repository's root.
ROOT = Path(__file__).resolve().parent.parent
#: [m] Noise-free ranges within this of the truth.
RANGE_TOL_NOISE_FREE_M = 0.01


def run_cli(argv, main=None) -> tuple[int, str]:
    """``scanner-sim argv`` in process (or ``main(argv)``): its exit code and what it printed on stdout."""
    if main is None:
        from scanner_sim.cli import main
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(argv)
    return code, printed.getvalue()


class _SignalWhenCollected:
    def __init__(self, signum: int):
        self.signum = signum

    def __del__(self):
        signal.raise_signal(self.signum)
        sum(range(100))  # bytecode after the signal: the handler runs here, inside the finaliser


def drop_a_signal(signum: int = signal.SIGINT) -> list[type]:
    """Send this process ``signum`` from inside a finaliser, so that a guarded command's handler raises where Python
    cannot propagate it: the exception is dropped, as one raised in a ``__del__`` or a garbage-collector callback.
    Returns the types of the exceptions dropped (sys.unraisablehook is replaced while it runs)."""
    dropped, hook = [], sys.unraisablehook
    sys.unraisablehook = lambda unraisable: dropped.append(type(unraisable.exc_value))
    try:
        _SignalWhenCollected(signum)  # collected at once
    finally:
        sys.unraisablehook = hook
    return dropped


def cold_compiled_kernels(code: str, tmp_path: Path) -> list[str]:
    """The kernels numba compiles while ``code`` (Python source) runs its last statement in a fresh process with empty
    kernel caches under ``tmp_path``: ``code`` binds ``run``, a function of no arguments that calls them."""
    script = (code + "\nimport json\nfrom numba.core import event\nfrom muls.infra.compile_times import CompileTimes\n"
              "times = CompileTimes()\nwith event.install_listener('numba:compile', times):\n    run()\n"
              "print(json.dumps(sorted(times.own_s)))\n")
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(NUMBA_CACHE_DIR=str(tmp_path / "numba"), XDG_CACHE_HOME=str(tmp_path / "xdg"))
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def string_formatting(kernels: list[str]) -> list[str]:
    """The kernels of ``kernels`` (names) that format strings: numba compiles them for an error message, such as an
    array assigned to an array slice inside a kernel (its shape-mismatch error), and they cost a first run seconds."""
    return [name for name in kernels if "unicode" in name or "shape_context" in name or "str_generic" in name]


def run_muls(capsys, *argv) -> tuple[int, str, str]:
    """``muls argv`` in process: its exit code, stdout and stderr."""
    from muls.cli import main

    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def paper_water(name: str):
    """The preset water under the paper's Eq. 6 (k_lidar), single scattering."""
    from muls import water_preset

    return water_preset(name).with_models(attenuation_model="k_lidar")


def detection_model(water="pool", gate=(150e-9, 400e-9)):
    """The MUL (CH3 gated at ``gate`` [s]: delay, width) in ``water`` under the paper's Eq. 6."""
    from muls import mul2023
    from muls.optics.optical_model import OpticalModel

    return OpticalModel.build(mul2023(*gate), paper_water(water))


def dropout_causes(ranging) -> dict[str, int]:
    """How many pulses each dropout cause stopped, the causes that stopped none left out."""
    from muls.ranging.returns import DROPOUT_CAUSES

    counts = np.bincount(ranging.dropout_cause[ranging.dropout_cause >= 0], minlength=len(DROPOUT_CAUSES))
    return {name: int(n) for name, n in zip(DROPOUT_CAUSES, counts) if n}


def chromium() -> str:
    """The Chromium on PATH; the test is skipped without one, and fails without one under MULS_REQUIRE_CHROMIUM=1."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if browser is None:
        if os.environ.get("MULS_REQUIRE_CHROMIUM") == "1":
            pytest.fail("MULS_REQUIRE_CHROMIUM=1 but no chromium on PATH")
        pytest.skip("no chromium on PATH (CI installs it)")
    return browser



def page_pixels(page: Path, shot: Path, height: int) -> np.ndarray:
    """The RGB pixels (n, 3) uint8 of ``page`` drawn by headless Chromium 1400 px wide and ``height`` px tall, its
    screenshot kept at ``shot``."""
    import matplotlib.image as mpimg

    run = subprocess.run([chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                          f"--window-size=1400,{height}", f"--screenshot={shot}", page.as_uri()],
                         capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr[-2000:]
    return (mpimg.imread(shot)[..., :3] * 255).round().astype(np.uint8).reshape(-1, 3)

# Where the suite's time goes: ``--file-durations N`` adds a table of the N test files whose tests took longest, their
# setup, call and teardown summed (module fixtures are counted in the setup of their file's first test), beside
# pytest's own ``--durations`` per test. Under pytest-xdist the reports reach the controller, which sums them.
_file_seconds: dict[str, float] = {}


def pytest_addoption(parser):
    parser.addoption("--file-durations", type=int, default=0, metavar="N",
                     help="show the N test files whose tests took longest in all (setup, call and teardown)")


def pytest_runtest_logreport(report):
    path = report.nodeid.split("::", 1)[0]
    _file_seconds[path] = _file_seconds.get(path, 0.0) + report.duration


def pytest_terminal_summary(terminalreporter, config):
    n = config.getoption("--file-durations")
    if not n or not _file_seconds or hasattr(config, "workerinput"):  # an xdist worker: its controller reports
        return
    ranked = sorted(_file_seconds.items(), key=lambda item: -item[1])
    terminalreporter.write_sep("=", f"slowest {min(n, len(ranked))} test files (of {len(ranked)}, "
                                    f"{sum(_file_seconds.values()):.0f} s of tests in all)")
    for path, seconds in ranked[:n]:
        terminalreporter.write_line(f"{seconds:9.1f}s {path}")


#: A small seabed scene placed in UTM zone 31N (eastings near 500 km, northings near 5,700 km).
UTM_CENTRE = (500_000.0, 5_700_000.0)


def utm_scene_data(crs="EPSG:32631") -> dict:
    """The shipped seabed_lawnmower scene, made small and moved into UTM range, with ``crs``."""
    data = yaml.safe_load((ROOT / "scenes" / "seabed_lawnmower.yaml").read_text())
    data["seabed"].update(center_m=list(UTM_CENTRE), size_m=[24, 16], resolution_m=0.2)
    data["seabed"]["rocks"]["count"] = 3
    data["platform"]["lawnmower"].update(center_m=list(UTM_CENTRE), size_m=[12, 8], line_spacing_m=4)
    data["output"] = {"laz": False, "las": True}
    if crs is not None:
        data["crs"] = crs
    return data
