"""A water's phase function as a short text, and the family of phase functions a water's sensitivity runs over.

A water names its particle phase function by a spec: a name of :data:`muls.water.phase.PHASE_FUNCTIONS`, alone
(``petzold``) or with its parameters (``fournier_forand:mu=3.4,n=1.06``, ``henyey_greenstein:g=0.85``). The spec
is part of the key of the Monte Carlo's tables, so each phase function gets its own tables.

:data:`SENSITIVITY_FAMILY` is the stated family of ``muls sensitivity``: Petzold's average (the model's default),
Fournier-Forand over a published range of the backscatter ratio b_b/b of coastal and inland waters, and
Henyey-Greenstein over a range of g around Petzold's mean cosine; docs/studies.md gives the sources.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ..infra.errors import ParameterError
from ..infra.roots import brentq
from .phase import PHASE_FUNCTIONS, PhaseFunction, phase_function

#: The model's phase function (muls.water.properties.PHASE_FUNCTION names the same).
DEFAULT_PHASE = "petzold"

#: Fournier-Forand parameters along the line n = 1.01 + 0.1542 (mu - 3) of Mobley, Sundman and Boss (2002),
#: Appl. Opt. 41, 1035, which picks one phase function per backscatter ratio (it passes through n 1.10,
#: mu 3.5835, Petzold's 0.0183, and through the Ocean Optics Web Book's n 1.08, mu 3.483 for 0.01).
FF_LINE_N0 = 1.01
FF_LINE_SLOPE = 0.1542
#: The Junge slopes the line is searched over (Fournier-Forand needs 3 < mu < 5 and 1 < n < 1.5).
FF_MU_SEARCH = (3.0001, 4.9999)


def phase_spec(name: str, **params: float) -> str:
    """The spec of phase function ``name`` with ``params``: ``name`` alone, or ``name:k=v,...`` (keys sorted,
    values to 6 significant digits, so that equal phase functions give equal specs and equal table keys)."""
    if name not in PHASE_FUNCTIONS:
        raise ParameterError(f"phase function = {name!r}: must be one of {', '.join(PHASE_FUNCTIONS)}")
    if not params:
        return name
    return name + ":" + ",".join(f"{k}={float(v):.6g}" for k, v in sorted(params.items()))


def parse_phase_spec(spec: str) -> tuple[str, dict[str, float]]:
    """(name, parameters) of a spec (:func:`phase_spec`); a :class:`ParameterError` naming it if malformed."""
    if not isinstance(spec, str) or not spec:
        raise ParameterError(f"phase_function = {spec!r}: must be a phase function's name, e.g. 'petzold' or "
                             "'fournier_forand:mu=3.4,n=1.06'")
    name, _, rest = spec.partition(":")
    params: dict[str, float] = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        try:
            params[key.strip()] = float(value)
        except ValueError:
            eq = ""
        if not eq:
            raise ParameterError(f"phase_function = {spec!r}: parameter {item!r} must read name=number")
    if name not in PHASE_FUNCTIONS:
        raise ParameterError(f"phase_function = {spec!r}: must be one of {', '.join(PHASE_FUNCTIONS)}, "
                             "optionally with parameters after ':'")
    return name, params


def phase_from_spec(spec: str) -> PhaseFunction:
    """The phase function a spec names (tabulated once per spec: the constructors are cached)."""
    name, params = parse_phase_spec(spec)
    try:
        return phase_function(name, **params)
    except TypeError as exc:  # an unknown parameter name
        raise ParameterError(f"phase_function = {spec!r}: {exc}") from None


def fournier_forand_backscatter_ratio(n: float, mu: float) -> float:
    """b_b/b of the Fournier-Forand phase function, in closed form (Fournier and Jonasz 1999, as written by Mobley,
    Sundman and Boss 2002, Eq. 3): 1 - (1 - d90^(nu+1) - (1 - d90^nu) / 2) / ((1 - d90) d90^nu), d90 = delta at
    90 deg."""
    nu = 0.5 * (3.0 - mu)
    d90 = 4.0 / (3.0 * (n - 1.0) ** 2) * math.sin(math.pi / 4.0) ** 2
    return 1.0 - (1.0 - d90 ** (nu + 1.0) - 0.5 * (1.0 - d90**nu)) / ((1.0 - d90) * d90**nu)


def fournier_forand_for_backscatter(ratio: float) -> tuple[float, float]:
    """(n, mu) on Mobley, Sundman and Boss's line (:data:`FF_LINE_N0`) whose b_b/b is ``ratio``."""

    def n_of(mu: float) -> float:
        return FF_LINE_N0 + FF_LINE_SLOPE * (mu - 3.0)

    lo, hi = (fournier_forand_backscatter_ratio(n_of(m), m) for m in FF_MU_SEARCH)
    if not (lo < ratio < hi):
        raise ParameterError(f"backscatter ratio = {ratio!r}: Fournier-Forand on Mobley, Sundman and Boss's line "
                             f"reaches {lo:.2g} to {hi:.2g}")
    mu = brentq(lambda m: fournier_forand_backscatter_ratio(n_of(m), m) - ratio, *FF_MU_SEARCH, xtol=1e-10)
    return n_of(mu), mu


class PhaseMember(NamedTuple):
    """One phase function of a sensitivity family: a short label, its spec, what it varies and its source."""

    label: str
    spec: str
    varies: str
    source: str


def fournier_forand_member(ratio: float, source: str) -> PhaseMember:
    n, mu = fournier_forand_for_backscatter(ratio)
    return PhaseMember(f"FF b_b/b {ratio:g}", phase_spec("fournier_forand", n=n, mu=mu), "b_b/b (Fournier-Forand)",
                       f"Fournier and Forand (1994), n {n:.4f}, mu {mu:.4f} on Mobley, Sundman and Boss (2002)'s line; "
                       + source)


def henyey_greenstein_member(g: float, source: str) -> PhaseMember:
    return PhaseMember(f"HG g {g:g}", phase_spec("henyey_greenstein", g=g), "g (Henyey-Greenstein)",
                       f"Henyey and Greenstein (1941), g {g:g}; " + source)


#: Published particle backscatter ratios of coastal waters: 0.004-0.0245 (mean 0.0082) in Daya Bay at 532 nm
#: (Zhou et al. 2010, J. Trop. Oceanogr. 29(2), 39), about 0.002-0.015 in contrasting ocean regimes (Antoine et al.
#: 2011, Limnol. Oceanogr. 56, 955); the family spans 0.005-0.025.
FF_RATIO_SOURCE = ("b_b/b of coastal waters 0.004-0.0245 (Zhou et al. 2010, Daya Bay, 532 nm) and 0.002-0.015 "
                   "(Antoine et al. 2011)")
#: Henyey-Greenstein's g: 0.924 has Petzold's mean cosine (Mobley, Ocean Optics Web Book, 'The Henyey-Greenstein
#: phase function'; MULS Eq. 5 uses it); 0.85-0.95 around it is a named assumption (docs/assumptions.md).
HG_G_SOURCE = ("g 0.924 has Petzold's mean cosine (Ocean Optics Web Book; MULS Eq. 5); 0.85 and 0.95 around it "
               "are a named assumption")

SENSITIVITY_FAMILY: tuple[PhaseMember, ...] = (
    PhaseMember("Petzold (default)", DEFAULT_PHASE, "default",
                "Petzold (1972) average particle phase function, b_b/b 0.0183 (Mobley 1994, Light and Water, "
                "Table 3.10): the model's default"),
    fournier_forand_member(0.005, FF_RATIO_SOURCE),
    fournier_forand_member(0.01, FF_RATIO_SOURCE),
    fournier_forand_member(0.0183, FF_RATIO_SOURCE + "; 0.0183 is Petzold's: same b_b/b, another shape"),
    fournier_forand_member(0.025, FF_RATIO_SOURCE),
    henyey_greenstein_member(0.85, HG_G_SOURCE),
    henyey_greenstein_member(0.924, HG_G_SOURCE),
    henyey_greenstein_member(0.95, HG_G_SOURCE),
)
