"""The trim stage: a packing cut at h0 = a r0 becomes the column of aspect ratio a (the spheres with
z + R <= h0 stay)."""
from __future__ import annotations

import numpy as np

from ..engine.state import ParticleState
from .pour_geometry import column_height


def trim(state: ParticleState, h0: float) -> ParticleState:
    """Keep the spheres that stay below h0 (z + R <= h0): the column's top then reads at most h0."""
    return state.subset(kept_by_trim(state, h0))


def kept_by_trim(state: ParticleState, h0: float) -> np.ndarray:
    """(n,) bool: the spheres of the packing `state` that a column of height h0 keeps.

    ValueError when the packing is too short for h0, or when the cut keeps fewer spheres than half
    the packing's bottom layer (those within half the smallest diameter of the floor): below that
    it is not a column."""
    if h0 <= 0:
        raise ValueError(f"column height h0 must be positive, got {h0}")
    top = float(np.max(state.position[:, 2] + state.radius, initial=0.0))
    if column_height(state) < h0:
        raise ValueError(f"the packing (height {column_height(state):.3f}, top {top:.3f}) is too short "
                         f"for a column of height h0 = {h0:.3f}")
    kept = state.position[:, 2] + state.radius <= h0
    d_min, d_max = 2.0 * float(state.radius.min()), 2.0 * float(state.radius.max())
    layer = int(np.count_nonzero(state.position[:, 2] - state.radius < 0.5 * d_min))
    n_kept = int(np.count_nonzero(kept))
    if n_kept == 0 or 2 * n_kept < layer:
        raise ValueError(f"h0 = {h0:g} leaves {n_kept} spheres, less than half a layer ({layer} lie on the "
                         f"packing's floor; smallest diameter {d_min:.3g}, largest {d_max:.3g}): cut at h0 >= "
                         f"the largest diameter")
    return kept
