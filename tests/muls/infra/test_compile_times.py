"""muls/infra/compile_times.py: each kernel's own compile time from numba's compile events."""

import numba
import pytest
from conftest import cold_compiled_kernels, string_formatting
from numba.core import event

from muls.infra.compile_times import CompileTimes


def test_each_kernel_is_charged_its_own_compilation_once_per_signature_and_none_on_a_second_call():
    """A kernel that calls another is listed beside it, each with the signatures it compiled (two for the callee
    called with an int and a float), the caller's time without the callee's (the parts sum to the total); calling
    them again compiles nothing."""

    @numba.njit
    def inner(x):
        return x + 1

    @numba.njit
    def outer(x):
        return inner(x) * 2

    times = CompileTimes()
    with event.install_listener("numba:compile", times):
        assert outer(1) == 4 and outer(1.5) == 5.0
        assert outer(2) == 6  # compiled already: no event
    names = {name.rsplit(".", 1)[-1]: name for name in times.own_s}
    assert set(names) == {"inner", "outer"}
    assert times.signatures[names["inner"]] == 2 and times.signatures[names["outer"]] == 2
    assert all(seconds > 0.0 for seconds in times.own_s.values())
    table = times.table()
    assert table.splitlines()[-1].split()[1:] == ["4", "total,", "2", "kernels", "compiled"]


@pytest.mark.slow
def test_regression_the_physics_kernels_compile_no_string_formatting(tmp_path):
    """A cold simulation of flat targets (windows, channels decided, only what the ranging reads, as a pass runs them)
    compiles no string formatting. Root cause: an array assigned to an array slice inside a kernel
    (``base_w[:] = baselines[w]``) compiles numba's shape-mismatch error, which formats the shapes: its unicode,
    repr and str helpers, 18 kernels and 37 signatures, about 1.5 s more of the first run's compile, for a message
    no valid input can raise. Copy in a loop, or pass the row itself."""
    names = _cold_flat_targets("deciding_only=True, ranging_only=True", tmp_path)
    assert any(name.endswith("._digitise") for name in names) and any(name.endswith("._peaks") for name in names)
    assert any(name.endswith(".deciding_channels.deciding_channels") for name in names)
    assert not string_formatting(names)


@pytest.mark.slow
def test_regression_a_simulation_that_decides_no_channels_compiles_no_deciding_test(tmp_path):
    """A cold simulation with every channel synthesised (``balanced`` and ``reference``, the main job's pass) compiles
    neither the deciding test nor its noise bounds, which the one above (``deciding_only``) does compile. Root cause:
    the test sat in the digitiser's window behind a runtime flag, so numba typed and compiled it in every first run,
    1.4 s of CPU, and 2.9 s once it bounded draws from their hashes, for a pass that never runs it. Its branch now
    hangs on an argument that is None where no channel is decided, a branch numba drops before typing."""
    names = _cold_flat_targets("ranging_only=True", tmp_path)
    assert any(name.endswith("._digitise") for name in names)
    assert not any(".deciding_channels." in name for name in names)


def _cold_flat_targets(options: str, tmp_path) -> list:
    """The kernels a cold ``simulate`` of 50 flat targets in coastal water compiles, called with ``options``."""
    return cold_compiled_kernels(
        "import numpy as np\n"
        "from muls import mul2023, water_preset\n"
        "from muls.optics.optical_model import OpticalModel, PulseBatch\n"
        "from muls.simulate import simulate\n"
        "model = OpticalModel.build(mul2023(60e-9, 400e-9), water_preset('coastal_ocean'))\n"
        "batch = PulseBatch.flat_target(model.instrument, np.linspace(2.0, 20.0, 50))\n"
        "def run():\n"
        f"    simulate(model, batch, 1, {options})\n", tmp_path)


@pytest.mark.slow
def test_regression_the_ranging_table_compiles_no_dropout_spans(tmp_path):
    """A cold measurement of the set-up's ranging-precision table in turbid harbour water, where some panel shots are
    lost to the column (their causes need the span), compiles no ``_span_terms`` and no ``echo_range_m``. Root
    causes: the table reads the shots' returns only, but its ranging explained every lost shot too, so every first run
    compiled the span kernel, 2 s of CPU, even for a pass that loses no pulse (the main job's); and it timed its
    panels by calling the ray kernels' ``echo_range_m`` on arrays, a signature no pass uses (0.2 to 0.3 s)."""
    names = cold_compiled_kernels(
        "from muls import mul2023\n"
        "from muls.optics.optical_model import OpticalModel\n"
        "from muls.presets import study_water\n"
        "from scanner_sim.survey.chunk import Physics\n"
        "from scanner_sim.survey.ranging_precision import measure_ranging_precision\n"
        "model = OpticalModel.build(mul2023(20e-9, 400e-9), study_water('turbid_harbor'))\n"
        "physics = Physics(model, 3, 'windowed', False)\n"
        "def run():\n"
        "    measure_ranging_precision(physics, model.instrument, (2.0, 4.0, 6.0))\n", tmp_path)
    assert any(name.endswith("._peaks") for name in names)
    assert not any(name.endswith("._span_terms") for name in names)
    assert not any(name.endswith(".echo_range_m") for name in names)
