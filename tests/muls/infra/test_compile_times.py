"""muls/infra/compile_times.py: each kernel's own compile time from numba's compile events."""

import numba
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
