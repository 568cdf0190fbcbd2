"""How many spheres a pour creates: plain arithmetic on the cylinder and the diameters, light enough
for the workflow's planning (a dry run) to import without the engine."""
from __future__ import annotations

import numpy as np

#: A cloud holds the spheres of this solid fraction of the cylinder over the height it must fill:
#: above the 0.61-0.63 the pours settle to at r0 = 2-4, so that one cloud fills the whole height.
#: With 0.58 the first cloud settled short (r0 = 3 and 4) and a second one fell onto the settled
#: packing, whose impacts strike the whole column at once (docs/performance.md, "Packings").
CLOUD_SOLID_FRACTION = 0.64


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
