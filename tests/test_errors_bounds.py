"""Reliability, bounded before it starts: every count and size a user gives is checked against what the machine can
do before anything is allocated, and refused with exit 2 and one line naming the option, its value and its limit
(docs/errors.md, "Command-line arguments").
"""

import pytest

from muls.cli import main as muls_main


@pytest.mark.parametrize("argv, option, limit", [
    (["multiscatter", "--water", "pond", "--range-m", "5", "--packets", str(10**20), "--no-plot"], "--packets",
     "461,168,601,842,738,780"),
    (["validate-pass", "--packets", str(10**20)], "--packets", "461,168,601,842,738,780"),
    (["mobley1993", "--photons", str(10**20), "--no-plot"], "--photons", "92,233,720,368,547,756"),
])
def test_monte_carlo_counts_beyond_64_bits_are_refused_not_an_internal_error(argv, option, limit, capsys):
    """``--packets 10**20`` ended with exit 1 and "internal error: TypingError: ... Int value is too large". Root
    cause: the compiled kernels number packets in 64-bit integers (a batch's share as batch x packets), and the
    count went to numba unchecked."""
    code = muls_main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert err == (f"muls {argv[0]}: error: {option} = {10**20}: at most {limit} (the Monte Carlo numbers its packets "
                   "in 64 bits)")
