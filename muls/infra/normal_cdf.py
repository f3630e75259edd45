"""The standard normal distribution function Phi(x) inside compiled kernels: :func:`normal_cdf`.

The same steps, in the same floating-point operations, as SciPy's ``scipy.special.ndtr`` (Cephes' ``ndtr``, ``erf``
and ``erfc``, Moshier 1992, as SciPy's ``xsf`` library carries them: rational approximations of erf on |x| < 1 and of
erfc on [1, 8) and from 8), so it returns the same bits (tests/muls/infra/test_normal_cdf.py checks it against SciPy
over millions of arguments): a kernel cannot call a SciPy ufunc. It is called, not inlined, by the kernels that
use it: one compiled copy serves them all (a copy inlined twice took 1.5 s of a first run's compile).
"""

from __future__ import annotations

import math

import numpy as np

from muls.infra.runtime import kernel

# Cephes' coefficients, highest power first. erfc(x) = exp(-x^2) P(x) / Q(x) on [1, 8), R(x) / S(x) from 8; the
# denominators' leading 1 is left out (p1evl).
_P = np.array([2.46196981473530512524e-10, 5.64189564831068821977e-1, 7.46321056442269912687e0,
               4.86371970985681366614e1, 1.96520832956077098242e2, 5.26445194995477358631e2,
               9.34528527171957607540e2, 1.02755188689515710272e3, 5.57535335369399327526e2])
_Q = np.array([1.32281951154744992508e1, 8.67072140885989742329e1, 3.54937778887819891062e2,
               9.75708501743205489753e2, 1.82390916687909736289e3, 2.24633760818710981792e3,
               1.65666309194161350182e3, 5.57535340817727675546e2])
_R = np.array([5.64189583547755073984e-1, 1.27536670759978104416e0, 5.01905042251180477414e0,
               6.16021097993053585195e0, 7.40974269950448939160e0, 2.97886665372100240670e0])
_S = np.array([2.26052863220117276590e0, 9.39603524938001434673e0, 1.20489539808096656605e1,
               1.70814450747565897222e1, 9.60896809063285878198e0, 3.36907645100081516050e0])
# erf(x) = x T(x^2) / U(x^2) on |x| < 1:
_T = np.array([9.60497373987051638749e0, 9.00260197203842689217e1, 2.23200534594684319226e3,
               7.00332514112805075473e3, 5.55923013010394962768e4])
_U = np.array([3.35617141647503099647e1, 5.21357949780152679795e2, 4.59432382970980127987e3,
               2.26290000613890934246e4, 4.92673942608635921086e4])
#: Cephes' MAXLOG, ln of the largest double: exp(-x^2) underflows below -MAXLOG.
_MAXLOG = 7.09782712893383996843e2
_SQRT1_2 = 0.70710678118654752440


@kernel(inline="always")
def _polevl(x, c):
    """c[0] x^n + ... + c[n] by Horner's rule, as Cephes' polevl."""
    a = c[0]
    for i in range(1, c.shape[0]):
        a = a * x + c[i]
    return a


@kernel(inline="always")
def _p1evl(x, c):
    """x^(n+1) + c[0] x^n + ... + c[n], the leading coefficient 1, as Cephes' p1evl."""
    a = x + c[0]
    for i in range(1, c.shape[0]):
        a = a * x + c[i]
    return a


@kernel
def normal_cdf(a):
    """Phi(a), the standard normal distribution function at ``a``: the bits of ``scipy.special.ndtr(a)`` (NaN: NaN)."""
    x = a * _SQRT1_2
    z = abs(x)
    if z < 1.0:  # 0.5 + 0.5 erf(x); Cephes takes erf of |x| and turns its sign
        w = z * z
        erf = z * _polevl(w, _T) / _p1evl(w, _U)
        return 0.5 + 0.5 * (-erf if x < 0.0 else erf)
    if not z >= 1.0:  # NaN
        return a
    y = 0.0  # 0.5 erfc(z), erfc underflowing to 0 past MAXLOG
    if -z * z >= -_MAXLOG:
        e = math.exp(-z * z)
        if z < 8.0:
            y = 0.5 * ((e * _polevl(z, _P)) / _p1evl(z, _Q))
        else:
            y = 0.5 * ((e * _polevl(z, _R)) / _p1evl(z, _S))
    return 1.0 - y if x > 0.0 else y
