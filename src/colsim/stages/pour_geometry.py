"""The pour's geometry: where a cloud's spheres start (a jittered cubic lattice inside the
cylinder, or inside a channel's box), how many spheres a pour creates, and the height and solid
fraction of a packing. Plain arithmetic on the footprint and the diameters, light enough for the
workflow's planning (a dry run) to import without the engine.

A footprint is what the pour fills, seen from above: a cylinder's radius r0 (a number), or a
:class:`Channel`, whose box 0 < x < length, |y| < width/2 lies behind its gate."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: what a pour fills and a column collapses in
GEOMETRIES = ("cylinder", "channel")


@dataclass(frozen=True)
class Channel:
    """A channel along +x: back wall x = 0, sidewalls y = -width/2 and +width/2, floor z = 0, and the
    gate x = length that holds the box while it fills (lengths). length plays r0's role: h0 = a length."""

    length: float
    width: float


def footprint_area(footprint) -> float:
    """The area (length^2) a pour fills: pi r0^2 of a cylinder's radius, length x width of a Channel."""
    if isinstance(footprint, Channel):
        return footprint.length * footprint.width
    return np.pi * footprint**2


def geometry_of(attrs) -> str:
    """The geometry a file's attributes name ("cylinder" where the attribute is absent, as in every
    file written before channels existed); ValueError for any other name."""
    geometry = str(attrs.get("geometry", "cylinder"))
    if geometry not in GEOMETRIES:
        raise ValueError(f"geometry {geometry[:60]!r} is not one of {', '.join(GEOMETRIES)}")
    return geometry


def footprint_of(attrs) -> float | Channel:
    """The footprint a packing's or a column's file attributes record: a Channel where their geometry
    is channel (channel_length, channel_width), else the cylinder's r0."""
    if geometry_of(attrs) == "channel":
        return Channel(float(attrs["channel_length"]), float(attrs["channel_width"]))
    return float(attrs["r0"])


def geometry_attributes(footprint) -> dict:
    """A file's global attributes of its geometry: a channel's (geometry, channel_length,
    channel_width); none for a cylinder, whose files keep the attributes they had before channels."""
    if not isinstance(footprint, Channel):
        return {}
    return {"geometry": "channel", "channel_length": footprint.length, "channel_width": footprint.width}

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


def cloud_spheres(r0, thickness: float, diameter_range) -> float:
    """How many spheres a cloud holds that is to settle into `thickness` (length) of the cylinder of
    radius r0 (or the footprint r0, a Channel): CLOUD_SOLID_FRACTION of that volume."""
    return CLOUD_SOLID_FRACTION * footprint_area(r0) * thickness / mean_sphere_volume(diameter_range)


def expected_spheres(r0, height: float, diameter_range) -> float:
    """How many spheres the pour of radius r0 (or the footprint r0, a Channel) to height `height`
    creates: one cloud for the height and two largest diameters more (:func:`cloud_spheres`)."""
    return cloud_spheres(r0, height + 2 * diameter_range[1], diameter_range)


def lattice_layer(r0, spacing: float) -> np.ndarray:
    """(k, 2) centres of the lattice cells of side `spacing` that lie whole inside radius r0, or
    inside the box of the footprint r0 when it is a Channel."""
    if isinstance(r0, Channel):
        gx, gy = np.meshgrid(_ticks(0.0, r0.length, spacing), _ticks(-0.5 * r0.width, 0.5 * r0.width, spacing),
                             indexing="ij")
        return np.c_[gx.ravel(), gy.ravel()]
    ticks = np.arange(-r0 + spacing / 2, r0, spacing)
    gx, gy = np.meshgrid(ticks, ticks, indexing="ij")
    inside = np.hypot(gx, gy) + spacing / np.sqrt(2.0) <= r0
    return np.c_[gx[inside], gy[inside]]


def _ticks(low: float, high: float, spacing: float) -> np.ndarray:
    """The centres of the whole cells of side `spacing` from `low` to `high`, as many as fit, centred."""
    cells = int(np.floor((high - low) / spacing))
    return 0.5 * (low + high) + spacing * (np.arange(cells) - 0.5 * (cells - 1))


def lattice_cloud(r0, n_target: int, z_bottom: float, diameter_range, rng) -> tuple[np.ndarray, np.ndarray]:
    """About n_target non-overlapping spheres (positions (k, 3), radii (k,)) inside radius r0 (or the
    box of the footprint r0, a Channel) above z_bottom.

    Whole layers of :func:`lattice_layer` (spacing 1.04 d_max), bottom layer first, so k >= n_target;
    the radii are drawn first, then each sphere's place inside its own cell. The generator of
    starting positions of the pack stage, and through :func:`colsim.stages.pack.starting_cloud` of the tests and the
    benchmarks."""
    d_min, d_max = diameter_range
    spacing = LATTICE_FACTOR * d_max
    layer = lattice_layer(r0, spacing)
    if not len(layer):
        if isinstance(r0, Channel):
            raise ValueError(f"the channel's box ({r0.length:g} by {r0.width:g}) holds no lattice cell of side "
                             f"{spacing:g} (1.04 times the largest diameter {d_max:g})")
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


def solid_fraction(state, r0, height: float) -> float:
    """Volume fraction of spheres (clipped to z in [0, height]) in the cylinder of radius r0 (or the
    box of the footprint r0, a Channel)."""
    z, r = state.position[:, 2], state.radius
    lo = np.clip(0.0 - z, -r, r)
    hi = np.clip(height - z, -r, r)
    def volume_below(h):
        """Volume of a sphere of radius r below height h relative to its centre, less half a sphere."""
        return np.pi * (r**2 * h - h**3 / 3.0)

    return float(np.sum(volume_below(hi) - volume_below(lo)) / (footprint_area(r0) * height))
