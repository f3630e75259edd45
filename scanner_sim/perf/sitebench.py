"""``scanner-sim bench-site``: a survey pass over a site-scale seabed (1 km x 200 m at 0.25 m, 6.4 million
triangles, tiled: :mod:`scanner_sim.world.site`) beside the same survey over a small seabed, in one run.

The seabed is a bathymetry raster (``--seabed raster``, the default) or the procedural one (``--seabed
procedural``). The raster is a GeoTIFF in UTM zone 31N (EPSG:32631) of 1 m pixels, generated into a temporary folder
(:func:`write_site_raster`) and read through the scene's ``seabed.raster`` keys, refined bilinearly to 0.25 m with
seeded micro-relief, as a real site's would be.

Each case runs in a fresh process, so its peak resident memory (``ru_maxrss``) is its own; the small scene's pass runs
before and after the site's, and its rates are the mean of the two (on a shared machine the load drifts). Beside
pulses per second of wall time, the bench gives pulses per CPU second of the process (less moved by other
processes' load) and the cores the pass kept busy. The site's pass follows a
lawnmower along the site's length for :data:`SITE_MINUTES` minutes of survey; the resident memory is read as the
pass reaches each of :data:`RSS_MINUTES` minutes. Both passes fire :data:`PULSE_RATE_HZ` pulses a second, half the
instrument's 5 kHz, so that an hour of survey runs in a few minutes: every other pulse of the real survey is left
out, the track, scan and seabed stay the survey's (the pulse rate is the scene's ``scanner.pulse_rate_hz``). The
points are counted and dropped, not written.
"""

from __future__ import annotations

import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from scanner_sim.perf.bench import _in_fresh_process

#: [m] The site: its size and node spacing (1 km x 200 m at 0.25 m: 4001 x 801 nodes, 6.4 million triangles).
SITE_SIZE_M = (1000.0, 200.0)
SITE_SPACING_M = 0.25
#: [m] The small scene's seabed: the same relief, untiled (256,000 triangles at 0.25 m).
SMALL_SIZE_M = (200.0, 40.0)
#: [Hz] Pulses fired per second in both passes (half the instrument's 5 kHz; module doc).
PULSE_RATE_HZ = 2500.0
#: [min] Survey time of the site's pass, and the times its resident memory is read.
SITE_MINUTES = 60
RSS_MINUTES = (10, 60)
#: [s] Survey time of the small scene's pass.
SMALL_SECONDS = 360.0  # 225,000 pulses
#: The generated raster's CRS, the map position of its south-west pixel centre [m] (a place in the North Sea) and
#: its pixel [m]: the site's 1 km x 200 m between the first and last pixel centres is 1001 x 201 pixels.
RASTER_CRS = "EPSG:32631"
RASTER_ORIGIN_M = (500_000.0, 5_600_000.0)
RASTER_CELL_M = 1.0
#: [m] The micro-relief added on the refined grid (seeded; the outputs report it as synthetic): the sand's
#: roughness below the raster's 1 m pixels, about the procedural seabed's 4 cm ripples (0.028 m rms).
MICRO_RELIEF_RMS_M = 0.03


def write_site_raster(path, size_m) -> None:
    """A GeoTIFF at ``path``: the bathymetry (elevation, up) of a seabed ``size_m`` [m] between its first and last
    pixel centres, at :data:`RASTER_CELL_M` pixels in :data:`RASTER_CRS`, north up: 20 m deep with the procedural
    seabed's seeded fractal relief (0.5 m rms, 30 m wavelength, Hurst 0.8), float32."""
    import rasterio
    from rasterio.transform import from_origin

    from scanner_sim.world.terrain import generate_heightfield

    sx, sy = size_m
    centre = (RASTER_ORIGIN_M[0] + 0.5 * sx, RASTER_ORIGIN_M[1] + 0.5 * sy)
    hf = generate_heightfield(centre, size_m, RASTER_CELL_M, 20.0, 0.5, 30.0, 0.8, 0.0, 1.0, 0.0, 0.0,
                              np.random.default_rng(7))
    heights = hf.heights_m[::-1].astype(np.float32)  # row 0 the northern row
    ny, nx = heights.shape
    c = RASTER_CELL_M
    transform = from_origin(hf.x0_m - 0.5 * c, hf.y0_m + (ny - 1) * c + 0.5 * c, c, c)
    with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=1, dtype="float32", crs=RASTER_CRS,
                       transform=transform) as ds:
        ds.write(heights, 1)


def survey_scene(size_m, spacing_m: float, fidelity: str, duration_s: float, raster: str | None = None) -> dict:
    """A scene mapping: a seabed of ``size_m`` [m] at ``spacing_m``: the GeoTIFF ``raster`` (:func:`write_site_raster`)
    refined with :data:`MICRO_RELIEF_RMS_M` of micro-relief, in its CRS, or (None) the procedural one (seeded
    fractal relief with ripples, 20 m deep); a lawnmower along its length at 5 m altitude (lines 20 m apart, 1 m/s,
    15 Hz scan over 90 deg), ``duration_s`` of survey at :data:`PULSE_RATE_HZ`, seed fixed."""
    sx, sy = size_m
    if raster is None:
        centre, crs = (0.0, 0.0), {}
        seabed = {"size_m": [sx, sy], "center_m": [0.0, 0.0], "resolution_m": spacing_m, "depth_m": 20.0, "seed": 7,
                  "material": "carbonate_sand", "relief": {"rms_m": 0.5, "wavelength_m": 30.0, "hurst": 0.8},
                  "ripples": {"amplitude_m": 0.04, "wavelength_m": 0.8, "crest_deg": -30.0}}
    else:
        centre, crs = (RASTER_ORIGIN_M[0] + 0.5 * sx, RASTER_ORIGIN_M[1] + 0.5 * sy), {"crs": RASTER_CRS}
        seabed = {"raster": raster, "resolution_m": spacing_m, "material": "carbonate_sand",
                  "micro_relief": {"rms_m": MICRO_RELIEF_RMS_M, "seed": 7}}
    return {
        "format_version": 1, "name": f"site_{sx:g}x{sy:g}", "water": "clean_ocean", "instrument": {"preset": "mul2023"},
        **crs, "seabed": seabed,
        "platform": {"mode": "lawnmower", "lawnmower": {"center_m": list(centre), "size_m": [sx - 20.0, sy - 20.0],
                                                        "heading_deg": 90.0, "line_spacing_m": 20.0},
                     "speed_m_s": 1.0, "altitude_m": 5.0, "follow_length_m": 4.0, "turn_length_m": 5.0},
        "scanner": {"mode": "continuous", "scan_rate_hz": 15.0, "sector_deg": 90.0, "pulse_rate_hz": PULSE_RATE_HZ},
        "survey": {"seed": 3, "fidelity": fidelity, "duration_s": duration_s},
        "output": {"las": False},
    }


def _resident_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


class _ResidentProbe:
    """A chunk sink that reads the process's resident memory [MB] as the pass first reaches each of ``minutes``."""

    def __init__(self, pulse_rate_hz: float, start_slot: int, minutes):
        self.rate, self.start, self.pending, self.found = pulse_rate_hz, start_slot, sorted(minutes), {}

    def add(self, chunk) -> None:
        reached_s = (int(chunk.slots[-1]) + 1 - self.start) / self.rate
        while self.pending and reached_s >= 60.0 * self.pending[0] - 1e-6:
            self.found[str(self.pending.pop(0))] = round(_resident_mb(), 1)

    def finish(self, duration_s: float) -> None:
        """The pass has ended at ``duration_s`` of survey: read the memory for the minutes it reached (the last fired
        pulse comes before the end of the scan's last turn)."""
        while self.pending and duration_s >= 60.0 * self.pending[0] - 1e-6:
            self.found[str(self.pending.pop(0))] = round(_resident_mb(), 1)


def _pass_figures(size_m, spacing_m: float, fidelity: str, duration_s: float, rss_minutes,
                  raster: str | None = None) -> dict:
    """In a fresh process: the pass over ``survey_scene(size_m, ..., raster)``: triangles, set-up seconds (scene
    and first tables: the raster read and refined, or the relief generated), pulses/s of the chunks (kernels
    compiled before, :func:`scanner_sim.survey.pipeline.warm_up`), peak RSS [MB] and the resident memory as the pass
    reached ``rss_minutes``."""
    from muls.infra.runtime import configure_process
    from scanner_sim.config import parse_scene
    from scanner_sim.survey.pipeline import pass_chunks, stream_pass, warm_up
    from scanner_sim.survey.setup import PassOptions, PassSetup

    configure_process()
    config = parse_scene(survey_scene(size_m, spacing_m, fidelity, duration_s, raster))
    options = PassOptions(progress=False, render=False, write_scene=False)
    t0 = time.perf_counter()
    setup = PassSetup.build(config, options)
    setup_s = time.perf_counter() - t0
    warm_up(setup, options)
    probe = _ResidentProbe(setup.scanner.pulse_rate_hz, setup.first_slot, rss_minutes)
    cpu0 = time.process_time()
    stats, _, wall_s = stream_pass(setup, pass_chunks(setup, options), [probe], options)
    cpu_s = time.process_time() - cpu0
    probe.finish(duration_s)
    return {"triangles": int(setup.scene.n_faces), "setup_s": round(setup_s, 2),
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
            "pulses_per_s": round(stats.pulses / wall_s, 1), "pulses_per_cpu_s": round(stats.pulses / cpu_s, 1),
            "cores_used": round(cpu_s / wall_s, 2), "pulses": int(stats.pulses),
            "windows_built": getattr(setup.target, "windows_built", 0), "rss_mb_by_minutes": probe.found}


def bench_site(fidelity: str = "balanced", minutes: int = SITE_MINUTES, seabed: str = "raster") -> dict:
    """The site's pass and the small scene's, each in a fresh process (module doc), over generated rasters
    (``seabed`` 'raster', the default) or procedural seabeds ('procedural'): ``{"site": {"triangles", "setup_s", "peak_rss_mb",
    "pulses_per_s", ...}, "small": {"pulses_per_s", ...}, "rss_mb_by_minutes": {"10", "60"}, ...}`` with the ratios
    the targets are judged on."""
    marks = [m for m in RSS_MINUTES if m <= minutes]
    with tempfile.TemporaryDirectory(prefix="bench-site-") as folder:
        rasters = {}
        for name, size in (("small", SMALL_SIZE_M), ("site", SITE_SIZE_M)):
            rasters[name] = None
            if seabed == "raster":
                rasters[name] = str(Path(folder) / f"{name}.tif")
                write_site_raster(rasters[name], size)
        before = _in_fresh_process(_pass_figures, SMALL_SIZE_M, SITE_SPACING_M, fidelity, SMALL_SECONDS, [],
                                   rasters["small"])
        site = _in_fresh_process(_pass_figures, SITE_SIZE_M, SITE_SPACING_M, fidelity, 60.0 * minutes, marks,
                                 rasters["site"])
        after = _in_fresh_process(_pass_figures, SMALL_SIZE_M, SITE_SPACING_M, fidelity, SMALL_SECONDS, [],
                                  rasters["small"])
    by_minutes = site.pop("rss_mb_by_minutes")
    small = {**after, **{k: round(0.5 * (before[k] + after[k]), 1) for k in ("pulses_per_s", "pulses_per_cpu_s")},
             "pulses_per_s_before_after": [before["pulses_per_s"], after["pulses_per_s"]]}
    small.pop("rss_mb_by_minutes")
    first, last = (by_minutes.get(str(m)) for m in (marks[0], marks[-1])) if marks else (None, None)
    return {"site": site, "small": small, "rss_mb_by_minutes": by_minutes,
            "site_over_small_pulses_per_s": round(site["pulses_per_s"] / small["pulses_per_s"], 3),
            "site_over_small_pulses_per_cpu_s": round(site["pulses_per_cpu_s"] / small["pulses_per_cpu_s"], 3),
            "rss_growth_last_over_first": round(last / first - 1.0, 3) if first and last else None,
            "fidelity": fidelity, "seabed": seabed, "pulse_rate_hz": PULSE_RATE_HZ,
            "subsampling": f"pulses fired at {PULSE_RATE_HZ:g} Hz, half the instrument's 5 kHz: the survey's track, "
                           "scan and seabed with every other pulse left out; points counted, not written"}
