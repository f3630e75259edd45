"""Brent's root finder on a bracket, in plain Python: :func:`brentq`.

The same steps, in the same floating-point operations, as SciPy's ``scipy.optimize.brentq`` (its C routine
``brentq.c``, after Brent 1973, ch. 4), so it returns the same bits (tests/muls/infra/test_roots.py checks it against
SciPy); here because importing ``scipy.optimize`` took 0.3 to 0.8 s of every process that imports the water model,
whose phase-function family solves four roots at import.
"""

from __future__ import annotations

import math

#: SciPy's default relative tolerance: four machine epsilons.
RTOL = 4.0 * 2.220446049250313e-16
MAX_ITERATIONS = 100


def brentq(f, a: float, b: float, xtol: float = 2e-12, rtol: float = RTOL, maxiter: int = MAX_ITERATIONS) -> float:
    """A root of ``f`` in [a, b], where ``f(a)`` and ``f(b)`` differ in sign, to within ``xtol + rtol * |x|``;
    ValueError when they do not, RuntimeError when ``maxiter`` steps do not converge."""
    xpre, xcur = float(a), float(b)
    fpre, fcur = float(f(xpre)), float(f(xcur))
    if fpre == 0.0:
        return xpre
    if fcur == 0.0:
        return xcur
    if math.copysign(1.0, fpre) == math.copysign(1.0, fcur):
        raise ValueError("f(a) and f(b) must have different signs")
    xblk = fblk = spre = scur = 0.0
    for _ in range(maxiter):
        if fpre != 0.0 and fcur != 0.0 and math.copysign(1.0, fpre) != math.copysign(1.0, fcur):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2.0
        sbis = (xblk - xcur) / 2.0
        if fcur == 0.0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:  # interpolate
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:  # extrapolate
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2.0 * abs(stry) < min(abs(spre), 3.0 * abs(sbis) - delta):  # good short step
                spre, scur = scur, stry
            else:  # bisect
                spre = scur = sbis
        else:  # bisect
            spre = scur = sbis
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0 else -delta)
        fcur = float(f(xcur))
    raise RuntimeError(f"brentq: no convergence in {maxiter} iterations")
