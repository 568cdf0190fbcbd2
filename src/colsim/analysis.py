"""Stage 4: what is measured on a deposit (SPEC section 4).

- Contact graph: particle pairs with gap <= `contact_tolerance` (floor contacts do not link
  particles). The main mass is its largest connected component.
- h_inf: highest point of the main mass, max(z + R).
- r_inf: the outmost grain connected to the main mass, max over it of sqrt(x^2 + y^2) + R,
  measured from the column axis.
- Normalised: h_inf / r0 and (r_inf - r0) / r0, against a = h0 / r0.

The edge of a deposit is a sparse layer of grains on the floor, a few hundredths of a diameter
apart, so r_inf depends on the contact tolerance. Two checks come with it: r_inf at looser
tolerances, and :func:`mass_front`, the radius that holds a given share of the mass (no contacts).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .contacts import touching_pairs
from .state import ParticleState

DEFAULT_CONTACT_TOLERANCE = 0.01  # fraction of the smallest diameter


@dataclass
class Deposit:
    """Final height and run-out (length) and the main mass (boolean mask (n,))."""

    main_mass: np.ndarray
    h_inf: float
    r_inf: float


def main_mass(state: ParticleState, tolerance: float) -> np.ndarray:
    """(n,) bool: the largest connected component of the particle contact graph (gap <= tolerance)."""
    if state.n == 0:
        return np.zeros(0, dtype=bool)
    i, j = touching_pairs(state, tolerance)
    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(state.n, state.n))
    _, label = connected_components(graph, directed=False)
    return label == np.argmax(np.bincount(label))


def contact_tolerance(state: ParticleState, fraction: float = DEFAULT_CONTACT_TOLERANCE) -> float:
    return fraction * 2.0 * float(state.radius.min())


def measure_deposit(state: ParticleState, tolerance: float | None = None) -> Deposit:
    """h_inf and r_inf of `state` as defined in the module docstring."""
    tolerance = contact_tolerance(state) if tolerance is None else tolerance
    mass = main_mass(state, tolerance)
    top = state.position[mass, 2] + state.radius[mass]
    reach = np.hypot(state.position[mass, 0], state.position[mass, 1]) + state.radius[mass]
    return Deposit(mass, float(top.max()), float(reach.max()))


def mass_front(state: ParticleState, share: float) -> float:
    """Radius (length) from the axis, sqrt(x^2 + y^2) + R, within which `share` (0-1) of the mass lies."""
    if not 0.0 < share <= 1.0:
        raise ValueError(f"mass share must be in (0, 1], got {share}")
    reach = np.hypot(state.position[:, 0], state.position[:, 1]) + state.radius
    order = np.argsort(reach)
    cumulative = np.cumsum(state.mass[order]) / state.mass.sum()
    return float(reach[order][np.searchsorted(cumulative, share - 1e-12)])


def deposit_profile(state: ParticleState, mask: np.ndarray, bin_width: float, r_max: float):
    """(bin centres, height): max z + R of the selected particles in radial bins (NaN where empty)."""
    edges = np.arange(0.0, r_max + bin_width, bin_width)
    rho = np.hypot(state.position[mask, 0], state.position[mask, 1])
    top = state.position[mask, 2] + state.radius[mask]
    which = np.clip(np.digitize(rho, edges) - 1, 0, len(edges) - 2)
    height = np.full(len(edges) - 1, -np.inf)
    np.maximum.at(height, which, top)
    height[~np.isfinite(height)] = np.nan
    return 0.5 * (edges[1:] + edges[:-1]), height


def undisturbed_top_radius(initial: ParticleState, final: ParticleState, h0: float,
                           tolerance: float) -> float:
    """Radius (length) of the top disc that stayed in place: grains of the top layer
    (initial z + R > h0 - d_max) that moved less than `tolerance`; 0 when none did."""
    top_layer = initial.position[:, 2] + initial.radius > h0 - 2.0 * initial.radius.max()
    moved = np.linalg.norm(final.position - initial.position, axis=1)
    still = top_layer & (moved < tolerance)
    if not still.any():
        return 0.0
    return float(np.percentile(np.hypot(initial.position[still, 0], initial.position[still, 1]), 95))
