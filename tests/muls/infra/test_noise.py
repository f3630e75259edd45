"""Counter-based noise (muls/infra/noise.py): standard, independent normals keyed by (seed, pulse, stream, sample),
the inverse normal CDF, block draws, the table bound, the seed keys."""

import numpy as np
import pytest

from muls.infra.noise import standard_normal


def test_counter_based_normals_are_standard_and_independent():
    x = standard_normal(7, np.repeat(np.arange(200), 500), 3, np.tile(np.arange(500), 200))
    assert abs(x.mean()) < 0.01
    assert x.var() == pytest.approx(1.0, abs=0.02)
    assert abs(np.corrcoef(x[:-1], x[1:])[0, 1]) < 0.01
    assert not np.array_equal(x, standard_normal(8, np.repeat(np.arange(200), 500), 3, np.tile(np.arange(500), 200)))



def test_inverse_normal_cdf_is_the_exact_one_to_acklams_accuracy_tails_included():
    """The draws' map from a uniform p to a normal (Acklam's rational approximation, a central and a tail
    formula) agrees with the exact inverse normal CDF (scipy's ndtri) to his stated 1.15e-9 relative, from
    1e-10 to 1 - 1e-10: both tails and the switch between the formulas at p = 0.02425 and 0.97575."""
    from scipy.special import ndtri

    from muls.infra.noise import _inverse_normal_cdf

    tail = np.logspace(-10.0, -1.3, 60)
    p = np.concatenate([tail, np.linspace(0.02, 0.98, 97), [0.02424, 0.02426, 0.97574, 0.97576], 1.0 - tail])
    x = np.array([_inverse_normal_cdf(v) for v in p])
    np.testing.assert_allclose(x, ndtri(p), rtol=1.2e-9, atol=1e-12)



def test_the_uniforms_behind_the_normals_stay_inside_0_1_and_are_symmetric():
    """Each 32-bit half of a draw maps to the centre of one of 2^32 equal cells of (0, 1): the extreme halves
    give 2^-33 and 1 - 2^-33 (never 0 or 1, where the inverse normal CDF is infinite), and k and 2^32 - 1 - k
    give p and 1 - p exactly, so the normals are symmetric. Cases sampling cannot reach (4e9 draws apart)."""
    from muls.infra.noise import centred_unit

    top = 2**32 - 1
    assert centred_unit(np.uint64(0)) == 2.0**-33 and centred_unit(np.uint64(top)) == 1.0 - 2.0**-33
    for k in (0, 1, 12345, 2**31 - 1, top):
        assert centred_unit(np.uint64(k)) + centred_unit(np.uint64(top - k)) == 1.0



def test_block_draws_equal_the_draws_one_by_one_tails_included():
    """The digitiser draws a window's normals a block at once (``fill_normal_pairs``: the central formula on SIMD
    lanes, then the tails patched); each must equal the draw-by-draw ``normal_half_at`` bit for bit, in both
    halves, with the low half skipped or not, at any first index: else records would depend on the blocking."""
    from muls.infra.noise import fill_hashes, fill_normal_pairs, fill_normals_of, normal_half_at, seed_key, stream_base

    n = 5000
    for pulse, stream, first in ((0, 2, 0), (17, 3, 123), (2**40, 4, 999_983)):
        base = np.uint64(stream_base(seed_key(11), pulse, stream))
        expected = np.array([[normal_half_at(base, first + k, half) for k in range(n)] for half in (0, 1)])
        assert (np.abs(expected) > 1.97).sum() > 0.04 * expected.size  # the tail formula is exercised
        high, low, tails = np.empty(n), np.empty(n), np.empty(2 * n, np.int64)
        fill_normal_pairs(base, first, high, low, tails)
        assert np.array_equal(high, expected[0]) and np.array_equal(low, expected[1])
        only_high = np.empty(n)
        fill_normal_pairs(base, first, only_high, np.empty(0), tails)
        assert np.array_equal(only_high, expected[0])
        # the normals of listed positions from their hashes (full records drawn only where read)
        hashes = np.empty(n, np.uint64)
        fill_hashes(base, first, hashes)
        listed = np.sort(np.random.default_rng(pulse).choice(n, n // 3, replace=False))
        for half in (0, 1):
            some, flags = np.empty(listed.size), np.empty(2 * listed.size, np.int64)
            fill_normals_of(hashes, half, listed, some, flags)
            assert np.array_equal(some, expected[half][listed])



def test_the_table_bound_on_a_normal_lies_above_it_and_close():
    """``normal_upper_bound`` (a table of 4,096 cells of the 32-bit half) is at least the normal of every half, checked
    at both ends of every cell and at random halves, and within 0.015 of it where |x| < 2.5: a bound below a draw would
    leave a code out of a full record that the peak search reads."""
    from muls.infra.noise import UPPER_BOUND_SHIFT, normal_of_bits, normal_upper_bound

    cells = np.arange(1 << (32 - int(UPPER_BOUND_SHIFT)), dtype=np.uint64)
    edges = np.concatenate([cells << UPPER_BOUND_SHIFT, ((cells + np.uint64(1)) << UPPER_BOUND_SHIFT) - np.uint64(1)])
    bits = np.concatenate([edges, np.random.default_rng(2).integers(0, 2**32, 200_000, dtype=np.uint64)])
    normal = np.array([normal_of_bits(b) for b in bits])
    bound = np.array([normal_upper_bound(b) for b in bits])
    assert (bound >= normal).all()
    central = np.abs(normal) < 2.5
    assert (bound - normal)[central].max() < 0.015


def test_the_bounds_on_a_normal_read_from_its_bits_bracket_it_both_ways():
    """``normal_bounds`` takes its lower bound from the complement's table cell, which is right only if the normals
    are antisymmetric to the bit (the complement of a half gives -x): checked on both ends of every cell and at random
    halves, with both bounds within 0.015 of the draw where |x| < 2.5. A lower bound above a draw would let the
    deciding test leave out a channel whose code could have started a run."""
    from muls.infra.noise import UPPER_BOUND_SHIFT, normal_bounds, normal_of_bits

    cells = np.arange(1 << (32 - int(UPPER_BOUND_SHIFT)), dtype=np.uint64)
    edges = np.concatenate([cells << UPPER_BOUND_SHIFT, ((cells + np.uint64(1)) << UPPER_BOUND_SHIFT) - np.uint64(1)])
    bits = np.concatenate([edges, np.random.default_rng(4).integers(0, 2**32, 200_000, dtype=np.uint64)])
    normal = np.array([normal_of_bits(b) for b in bits])
    complement = np.array([normal_of_bits(np.uint64(2**32 - 1) - b) for b in bits])
    np.testing.assert_array_equal(complement, -normal)
    lower, upper = np.array([normal_bounds(b) for b in bits]).T
    assert (lower <= normal).all() and (normal <= upper).all()
    central = np.abs(normal) < 2.5
    assert (normal - lower)[central].max() < 0.015 and (upper - normal)[central].max() < 0.015



def test_seed_key_accepts_ints_and_generators_and_names_what_it_refuses():
    """A seed is an integer from 0, or a numpy Generator, which is advanced once: its key is that of the integer
    the generator draws from [0, 2**63). Negative numbers, booleans and floats are refused, naming the seed."""
    from muls.infra.noise import seed_key

    assert seed_key(0) != seed_key(1)
    drawn = int(np.random.default_rng(7).integers(0, 2**63))
    assert seed_key(np.random.default_rng(7)) == seed_key(drawn)
    assert seed_key(np.random.default_rng(7)) != seed_key(np.random.default_rng(8))
    for bad in (-1, True, 1.5, "3"):
        with pytest.raises(ValueError, match="seed"):
            seed_key(bad)


def test_the_bound_table_built_in_numpy_is_the_kernels_normals_to_the_bit():
    """The table of :func:`normal_upper_bound` is built at import with numpy (no kernel to compile on a first run that
    never reads it): each cell's value is the compiled ``fill_normals_of``'s normal of the cell's last half, plus
    1e-6, bit for bit."""
    from muls.infra.noise import _NORMAL_UPPER, UPPER_BOUND_SHIFT, fill_normals_of

    cells = 1 << (32 - int(UPPER_BOUND_SHIFT))
    last = ((np.arange(1, cells + 1, dtype=np.uint64) << UPPER_BOUND_SHIFT) - np.uint64(1))
    normals = np.empty(cells)
    fill_normals_of(last, 1, np.arange(cells, dtype=np.int64), normals, np.empty(2 * cells, np.int64))
    assert np.array_equal(_NORMAL_UPPER, normals + 1e-6)
