"""Procedural seabed: a height field with fractal relief and sand ripples, and scattered rock meshes.

Everything is generated deterministically from one seed (``numpy.random.default_rng(seed)``): the same file
gives the same seabed, triangle for triangle. World frame: x east, y north, z up [m]; the seabed's mean
level is ``z = -depth_m``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from scanner_sim.world.icosphere import icosphere


@dataclass(frozen=True)
class HeightField:
    """A regular grid of seabed heights and its triangulation.

    x0_m, y0_m: world position of node (0, 0) [m]; spacing_m: node spacing [m]; heights_m: (ny, nx) float64
    world z of each node [m], row i at y0 + i dy, column j at x0 + j dx. Cell (i, j) is split into the
    triangles (a, b, d) and (a, d, c) with a = (i, j), b = (i, j+1), c = (i+1, j), d = (i+1, j+1); the height
    query interpolates on exactly those triangles, so it agrees with the mesh the rays see.

    valid: (ny-1, nx-1) bool, the cells that hold seabed (a raster's nodata leaves gaps: their cells have no
    triangles), or None where every cell does (the procedural seabed). Heights under a gap are filled from the
    nearest valid node, so a track over the gap still has a seabed to follow; the rays find nothing there.
    """

    x0_m: float
    y0_m: float
    spacing_m: float
    heights_m: np.ndarray
    valid: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights_m.shape

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) [m]."""
        ny, nx = self.shape
        return (self.x0_m, self.x0_m + (nx - 1) * self.spacing_m, self.y0_m, self.y0_m + (ny - 1) * self.spacing_m)

    def height(self, x_m, y_m) -> np.ndarray:
        """Seabed z [m] at world (x, y) (any matching shapes), on the mesh's own triangles; clamped at the edge."""
        x = np.asarray(x_m, dtype=float)
        y = np.asarray(y_m, dtype=float)
        ny, nx = self.shape
        fx = np.clip((x - self.x0_m) / self.spacing_m, 0.0, nx - 1 - 1e-9)
        fy = np.clip((y - self.y0_m) / self.spacing_m, 0.0, ny - 1 - 1e-9)
        j = np.minimum(fx.astype(np.int64), nx - 2)
        i = np.minimum(fy.astype(np.int64), ny - 2)
        u, v = fx - j, fy - i
        h = self.heights_m
        ha, hb, hc, hd = h[i, j], h[i, j + 1], h[i + 1, j], h[i + 1, j + 1]
        lower = ha + u * (hb - ha) + v * (hd - hb)  # triangle (a, b, d): u >= v
        upper = ha + v * (hc - ha) + u * (hd - hc)  # triangle (a, d, c): v > u
        return np.where(u >= v, lower, upper)

    def covers(self, x_m, y_m) -> np.ndarray:
        """bool (shape of x_m): (x, y) [m] lies in a cell that holds seabed (inside the extent, not a gap)."""
        x, y = np.asarray(x_m, dtype=float), np.asarray(y_m, dtype=float)
        ny, nx = self.shape
        fx, fy = (x - self.x0_m) / self.spacing_m, (y - self.y0_m) / self.spacing_m
        inside = (fx >= 0) & (fx <= nx - 1) & (fy >= 0) & (fy <= ny - 1)
        if self.valid is None:
            return inside
        j = np.clip(np.nan_to_num(fx).astype(np.int64), 0, nx - 2)
        i = np.clip(np.nan_to_num(fy).astype(np.int64), 0, ny - 2)
        return inside & self.valid[i, j]

    # The two figures below are built on first use and kept with the height field, which a process's passes of one
    # scene share (survey.setup_cache.cached_scene): a pass's sinks read them for its no_hit dropouts aimed down.
    @functools.cached_property
    def lowest_m(self) -> float:
        """[m] The lowest height of the nodes at the corners of the cells that hold seabed."""
        h = self.heights_m
        return float(np.min(h if self.valid is None else h[:-1, :-1][self.valid]))

    @functools.cached_property
    def inner_cells(self) -> np.ndarray:
        """(ny - 1, nx - 1) bool: the cells that hold seabed and whose eight neighbours hold seabed too."""
        from scipy import ndimage

        cells = np.ones(np.subtract(self.shape, 1), bool) if self.valid is None else self.valid
        return ndimage.binary_erosion(cells, np.ones((3, 3), bool), border_value=0)

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """Vertices (ny nx, 3) float64 world and faces (2 (ny-1)(nx-1), 3) int64, normals pointing up (the faces
        of the cells that are not ``valid`` left out)."""
        ny, nx = self.shape
        xs = self.x0_m + self.spacing_m * np.arange(nx)
        ys = self.y0_m + self.spacing_m * np.arange(ny)
        gx, gy = np.meshgrid(xs, ys)
        vertices = np.c_[gx.ravel(), gy.ravel(), self.heights_m.ravel()]
        idx = np.arange(ny * nx).reshape(ny, nx)
        a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
        c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
        faces = np.concatenate([np.c_[a, b, d], np.c_[a, d, c]])
        if self.valid is not None:
            faces = faces[np.tile(self.valid.ravel(), 2)]
        return vertices, faces


def fractal_relief(shape: tuple[int, int], spacing_m: float, rms_m: float, wavelength_m: float, hurst: float,
                   rng: np.random.Generator) -> np.ndarray:
    """(ny, nx) zero-mean fractal surface of rms ``rms_m`` [m] by spectral synthesis.

    Power spectrum flat below the wavenumber 1/``wavelength_m`` (the largest features) and falling as
    k^-(2 + 2 H) above it (H = ``hurst`` in (0, 1]; a self-affine surface of Hurst exponent H).
    """
    ny, nx = shape
    if rms_m == 0.0:
        return np.zeros(shape)
    noise = rng.standard_normal(shape)
    kx = np.fft.rfftfreq(nx, spacing_m)
    ky = np.fft.fftfreq(ny, spacing_m)
    k = np.hypot(kx[None, :], ky[:, None])
    k0 = 1.0 / wavelength_m
    amplitude = (1.0 + (k / k0) ** 2) ** (-(1.0 + hurst) / 2.0)
    amplitude[0, 0] = 0.0
    surface = np.fft.irfft2(np.fft.rfft2(noise) * amplitude, s=shape)
    std = surface.std()
    return surface * (rms_m / std) if std > 0 else surface


def sand_ripples(x_m: np.ndarray, y_m: np.ndarray, amplitude_m: float, wavelength_m: float, crest_deg: float,
                 sinuosity: float, rng: np.random.Generator) -> np.ndarray:
    """Sand ripples [m]: crests along the compass-free direction ``crest_deg`` (degrees from +x, CCW).

    Height amplitude_m sin(2 pi s / wavelength + phase), s across the crests, with crests that meander by
    ``sinuosity`` wavelengths over five wavelengths along them. Zero mean.
    """
    if amplitude_m == 0.0:
        return np.zeros_like(x_m)
    theta = math.radians(crest_deg)
    along = x_m * math.cos(theta) + y_m * math.sin(theta)
    across = -x_m * math.sin(theta) + y_m * math.cos(theta)
    phase0, phase1 = rng.uniform(0.0, 2.0 * math.pi, 2)
    meander = sinuosity * wavelength_m * np.sin(2.0 * math.pi * along / (5.0 * wavelength_m) + phase1)
    return amplitude_m * np.sin(2.0 * math.pi * (across + meander) / wavelength_m + phase0)


def rock_meshes(heightfield: HeightField, count: int, radius_range_m: tuple[float, float], rng: np.random.Generator,
                area: tuple[float, float, float, float] | None = None, subdivisions: int = 2):
    """``count`` rough rocks scattered over ``area`` (x_min, x_max, y_min, y_max) and partly embedded.

    Each rock is an icosphere with radii drawn in ``radius_range_m`` [m], flattened vertically, its radius
    perturbed by 15 % smooth noise, and sunk by 40 % of its height. Returns a list of (vertices, faces).
    """
    if count == 0:
        return []
    base_vertices, base_faces = icosphere(subdivisions)
    x_min, x_max, y_min, y_max = area if area is not None else heightfield.extent_m
    rocks = []
    for _ in range(count):  # a few dozen rocks at scene build time, not a hot path
        r = rng.uniform(*radius_range_m)
        scale = r * np.array([rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2), rng.uniform(0.45, 0.8)])
        bumps = rng.standard_normal(3)
        v = base_vertices
        perturb = 1.0 + 0.15 * np.tanh(v @ bumps)
        verts = v * perturb[:, None] * scale
        yaw = rng.uniform(0.0, 2.0 * math.pi)
        c, s = math.cos(yaw), math.sin(yaw)
        verts = verts @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        x, y = rng.uniform(x_min, x_max), rng.uniform(y_min, y_max)
        z = float(heightfield.height(x, y)) + 0.2 * scale[2]  # 40 % of the rock's height 2 r_z below the bed
        rocks.append((verts + np.array([x, y, z]), base_faces.copy()))
    return rocks


def generate_heightfield(center_xy_m, size_m, spacing_m: float, depth_m: float, relief_rms_m: float,
                         relief_wavelength_m: float, hurst: float, ripple_amplitude_m: float,
                         ripple_wavelength_m: float, ripple_crest_deg: float, ripple_sinuosity: float,
                         rng: np.random.Generator) -> HeightField:
    """The seabed height field: mean level -depth_m plus fractal relief plus ripples [m]."""
    nx = int(round(size_m[0] / spacing_m)) + 1
    ny = int(round(size_m[1] / spacing_m)) + 1
    x0 = center_xy_m[0] - 0.5 * (nx - 1) * spacing_m
    y0 = center_xy_m[1] - 0.5 * (ny - 1) * spacing_m
    relief = fractal_relief((ny, nx), spacing_m, relief_rms_m, relief_wavelength_m, hurst, rng)
    # Ripples in coordinates relative to the seabed's centre: a UTM-sized scene gets the same sand.
    gx, gy = np.meshgrid(np.arange(nx) * spacing_m, np.arange(ny) * spacing_m)
    ripples = sand_ripples(gx, gy, ripple_amplitude_m, ripple_wavelength_m, ripple_crest_deg, ripple_sinuosity, rng)
    return HeightField(x0, y0, spacing_m, -depth_m + relief + ripples)
