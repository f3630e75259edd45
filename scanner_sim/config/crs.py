"""The scene's coordinate reference system: the top-level ``crs`` key, checked with pyproj.

A scene with a ``crs`` has its world frame in that CRS's map coordinates (x easting, y northing, z up, metres),
so the CRS must be projected and in metres: a geographic CRS (degrees) or one in feet is refused with one line
naming ``crs``. A scene without ``crs`` keeps its local frame (docs/scene-format.md#conventions).
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BeforeValidator

from scanner_sim.config.errors import invalid

#: What the ``crs`` key takes, for its messages.
CRS_ALLOWED = ("must be a projected coordinate system in metres: an EPSG code (32631 or 'EPSG:32631'), another "
               "authority code, or its WKT")

def to_crs(value: int | str | None):
    """The :class:`pyproj.CRS` of a ``crs`` value (an EPSG code int, an authority code or WKT text), or None."""
    if value is None:
        return None
    from pyproj import CRS  # here only: most scenes have no CRS and need not import it

    return CRS.from_epsg(value) if isinstance(value, int) else CRS.from_user_input(value)


def horizontal_crs(crs):
    """The horizontal part of ``crs`` (a :class:`pyproj.CRS`): itself, or the first part of a compound CRS
    (projected + vertical, ``EPSG:32631+5703``)."""
    return crs.sub_crs_list[0] if crs.is_compound else crs


def crs_check(value: Any) -> int | str:
    """``value`` as given (an int, or text stripped of surrounding space) when pyproj reads it as a projected CRS
    whose horizontal axes are in metres; otherwise :func:`~.errors.invalid` with what is allowed."""
    from pyproj.exceptions import CRSError

    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise invalid(CRS_ALLOWED, value=value)
    if isinstance(value, str):
        value = value.strip()
    try:
        crs = to_crs(value)
    except (CRSError, ValueError, OverflowError):
        raise invalid(f"{CRS_ALLOWED}; pyproj does not know it", value=value) from None
    problem = not_metric(crs)
    if problem.endswith(("(degrees)", "not projected")):
        raise invalid(f"{problem}; the world frame must be projected, in metres (a UTM zone such as "
                      "'EPSG:32631'): give waypoints in its eastings and northings", value=value)
    if problem:
        raise invalid(f"{problem}; the world frame must be projected, in metres", value=value)
    return value


def not_metric(crs) -> str:
    """What keeps the CRS ``crs`` (a :class:`pyproj.CRS`) from being a world frame ("'WGS 84' is geographic
    (degrees)", "'...' is in US survey foot"), or '' for a projected CRS whose horizontal axes are in metres."""
    horizontal = horizontal_crs(crs)
    if not horizontal.is_projected:
        return f"{crs.name!r} is {'geographic (degrees)' if horizontal.is_geographic else 'not projected'}"
    axes = horizontal.axis_info[:2]
    if all(abs(axis.unit_conversion_factor - 1.0) < 1e-12 for axis in axes):  # metres, however named ('Meter')
        return ""
    return f"{crs.name!r} is in {', '.join(sorted({axis.unit_name for axis in axes}))}"


#: The ``crs`` key's type: an EPSG code or text pyproj reads as a projected CRS in metres.
Crs = Annotated[int | str, BeforeValidator(crs_check)]


def crs_label(value: int | str | None) -> str | None:
    """A short name of a ``crs`` value for summaries: its authority code (``'EPSG:32631'``) when pyproj finds one,
    else its name; None without a CRS."""
    crs = to_crs(value)
    if crs is None:
        return None
    code = crs.to_authority()
    return f"{code[0]}:{code[1]}" if code else crs.name


def crs_provenance(value: int | str | None) -> dict | None:
    """The provenance of a ``crs`` value: as given, its short label (:func:`crs_label`), its name and its WKT
    (WKT2:2019, as pyproj writes it); None without a CRS."""
    crs = to_crs(value)
    if crs is None:
        return None
    return {"given": value, "label": crs_label(value), "name": crs.name, "wkt": crs.to_wkt()}
