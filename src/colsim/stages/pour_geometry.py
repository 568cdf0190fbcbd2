"""The pour's geometry: where a cloud's spheres start (a jittered cubic lattice inside the
cylinder), how many spheres a pour creates, and the height and solid fraction of a packing. Plain
arithmetic on the cylinder and the diameters, light enough for the workflow's planning (a dry run)
to import without the engine."""
from __future__ import annotations

import numpy as np

#: A cloud holds the spheres of this solid fraction of the cylinder over the height it must fill:
#: above the 0.61-0.63 the pours settle to at r0 = 2-4, so that one cloud fills the whole height.
#: With 0.58 the first cloud settled short (r0 = 3 and 4) and a second one fell onto the settled
#: packing, whose impacts strike the whole column at once (the change is in CHANGELOG.md).
CLOUD_SOLID_FRACTION = 0.64
#: the lattice spacing of a cloud, in largest diameters: room for each sphere to move in its cell
LATTICE_FACTOR = 1.04


def mean_sphere_volume(diameter_range) -> float:
    """Mean volume (length^3) of a sphere with diameter uniform in diameter_range."""
    d_min, d_max = diameter_range
    if d_max > d_min:
        return np.pi / 6.0 * (d_max**4 - d_min**4) / (4.0 * (d_max - d_min))
    return np.pi / 6.0 * d_max**3


def cloud_spheres(r0: float, thickness: float, diameter_range) -> float:
    """How many spheres a cloud holds that is to settle into `thickness` (length) of the cylinder of
    radius r0: CLOUD_SOLID_FRACTION of that volume."""
    return CLOUD_SOLID_FRACTION * np.pi * r0**2 * thickness / mean_sphere_volume(diameter_range)


def expected_spheres(r0: float, height: float, diameter_range) -> float:
    """How many spheres the pour of radius r0 to height `height` creates: one cloud for the
    height and two largest diameters more (:func:`cloud_spheres`)."""
    return cloud_spheres(r0, height + 2 * diameter_range[1], diameter_range)


def lattice_layer(r0: float, spacing: float) -> np.ndarray:
    """(k, 2) centres of the lattice cells of side `spacing` that lie whole inside radius r0."""
    ticks = np.arange(-r0 + spacing / 2, r0, spacing)
    gx, gy = np.meshgrid(ticks, ticks, indexing="ij")
    inside = np.hypot(gx, gy) + spacing / np.sqrt(2.0) <= r0
    return np.c_[gx[inside], gy[inside]]


def lattice_cloud(r0: float, n_target: int, z_bottom: float, diameter_range, rng) -> tuple[np.ndarray, np.ndarray]:
    """About n_target non-overlapping spheres (positions (k, 3), radii (k,)) inside radius r0 above z_bottom.

    Whole layers of :func:`lattice_layer` (spacing 1.04 d_max), bottom layer first, so k >= n_target;
    the radii are drawn first, then each sphere's place inside its own cell. The generator of
    starting positions of the pack stage, and through :func:`colsim.stages.pack.starting_cloud` of the tests and the
    benchmarks."""
    d_min, d_max = diameter_range
    spacing = LATTICE_FACTOR * d_max
    layer = lattice_layer(r0, spacing)
    if not len(layer):
        raise ValueError(f"cylinder radius r0 = {r0} is too small for particles of diameter up to {d_max}")
    n_layers = int(np.ceil(n_target / len(layer)))
    z = z_bottom + spacing / 2 + spacing * np.arange(n_layers)
    sites = np.c_[np.tile(layer, (n_layers, 1)), np.repeat(z, len(layer))]
    radius = 0.5 * rng.uniform(d_min, d_max, len(sites))
    room = 0.5 * (spacing - 2 * radius)[:, None]
    position = sites + rng.uniform(-1.0, 1.0, sites.shape) * room
    return position, radius


def column_height(state) -> float:
    """Height (length) of a settled packing: the 95th percentile of z + R (robust to a loose top grain)."""
    return float(np.percentile(state.position[:, 2] + state.radius, 95)) if state.n else 0.0


def solid_fraction(state, r0: float, height: float) -> float:
    """Volume fraction of spheres (clipped to z in [0, height]) in the cylinder of radius r0."""
    z, r = state.position[:, 2], state.radius
    lo = np.clip(0.0 - z, -r, r)
    hi = np.clip(height - z, -r, r)
    def volume_below(h):
        """Volume of a sphere of radius r below height h relative to its centre, less half a sphere."""
        return np.pi * (r**2 * h - h**3 / 3.0)

    return float(np.sum(volume_below(hi) - volume_below(lo)) / (np.pi * r0**2 * height))
