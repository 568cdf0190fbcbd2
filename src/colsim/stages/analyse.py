"""Stage 4: what is measured on a deposit (SPEC section 4), for a cylinder's column or a channel's.

- Contact graph: particle pairs with gap <= `contact_tolerance` (floor and wall contacts do not link
  particles). The main mass is its largest connected component (:func:`main_mass`, one rule for
  both geometries).
- Reach of a grain (:func:`reach`), the distance of its far edge from the column's origin:
  cylinder sqrt(x^2 + y^2) + R from the column axis; channel x + R from the back wall (the channel
  runs along +x from its back wall at x = 0; the gate stood at x = L0).
- r_inf: the outmost grain connected to the main mass, the largest reach over it.
- h_inf: cylinder, the highest point of the main mass, max(z + R); channel, the deposit's height at
  the back wall, as the channel experiments measured it: the highest top z + R of the main mass's
  grains whose back edge x - R lies within one mean diameter of the back wall
  (:data:`BACK_WALL_BAND`; 0 when none does). The highest point anywhere stays in `h_top`.
- Normalised by the column's initial extent from its axis or back wall, r0 (cylinder radius) or L0
  (channel box length): h_inf / r0 and (r_inf - r0) / r0, against a = h0 / r0. The variables keep
  the names h_inf_over_r0 and runout_over_r0 in both geometries, so a study reads either; their
  long names and the `geometry` attribute say which length divides them.

:func:`analyse_trajectory` measures a whole trajectory (as :func:`colsim.io.trajectory.trajectory_dataset`
lays it out) into the analysis Dataset that `colsim analyse` writes.

The edge of a deposit is a sparse layer of grains on the floor, a few hundredths of a diameter
apart, so r_inf depends on the contact tolerance. Two checks come with it: r_inf at looser
tolerances, and :func:`mass_front`, the radius that holds a given share of the mass (no contacts).
"""
from __future__ import annotations

import json

from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..engine.contacts import touching_pairs
from ..engine.state import LEVER_OF_OLDER_FILES, ParticleState
from ..io.netcdf import at_rest_flag, at_rest_variable, run_coordinates
from ..io.state_file import state_from_dataset
from ..solvers import defaults
from .pour_geometry import geometry_of
from .settings import AnalysisSettings

DEFAULT_CONTACT_TOLERANCE = AnalysisSettings.contact_tolerance  # fraction of the smallest diameter
#: the front followed frame by frame: the radius holding this share of the mass (:func:`mass_front`),
#: stored in the analysis as FRONT_MASS_VARIABLE over time
FRONT_MASS_SHARE = 0.95
FRONT_MASS_VARIABLE = "mass_front_95_over_r0"
BACK_WALL_BAND = 1.0
"""A channel's h_inf: the highest grain top among grains whose back edge is within this many mean
diameters of the back wall."""


def column_length(attrs) -> float:
    """The column's initial extent that normalises its deposit (length): r0 of a cylinder, the box
    length `channel_length` (L0) of a channel; ValueError naming the attribute where it is missing
    or not a positive finite number."""
    name = "channel_length" if geometry_of(attrs) == "channel" else "r0"
    try:
        value = float(attrs[name])
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"a {geometry_of(attrs)} file needs attribute {name}, a positive length") from None
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"attribute {name} is {value:g}, not a positive finite length")
    return value


def distance(position: np.ndarray, geometry: str = "cylinder") -> np.ndarray:
    """(n,) distance (length) of each centre from the column's origin: from the axis,
    sqrt(x^2 + y^2), in a cylinder; from the back wall, x, in a channel."""
    if geometry == "channel":
        return position[:, 0].copy()
    return np.hypot(position[:, 0], position[:, 1])


def reach(state: ParticleState, geometry: str = "cylinder") -> np.ndarray:
    """(n,) distance (length) of each grain's far edge from the column's origin: distance + R."""
    return distance(state.position, geometry) + state.radius


@dataclass
class Deposit:
    """Final height and run-out (length) and the main mass (boolean mask (n,)); h_top, the highest
    point of the main mass, is h_inf in a cylinder (a channel's h_inf is its height at the back wall)."""

    main_mass: np.ndarray
    h_inf: float
    r_inf: float
    h_top: float = np.nan


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


def measure_deposit(state: ParticleState, tolerance: float | None = None, geometry: str = "cylinder") -> Deposit:
    """h_inf and r_inf of `state` as defined in the module docstring."""
    tolerance = contact_tolerance(state) if tolerance is None else tolerance
    mass = main_mass(state, tolerance)
    top = state.position[mass, 2] + state.radius[mass]
    edge = reach(state, geometry)[mass]
    if geometry == "channel":
        return Deposit(mass, height_at_back_wall(state, mass), float(edge.max()), float(top.max()))
    return Deposit(mass, float(top.max()), float(edge.max()), float(top.max()))


def height_at_back_wall(state: ParticleState, mask: np.ndarray) -> float:
    """A channel deposit's height (length) at its back wall x = 0: the highest top z + R of the
    selected grains whose back edge x - R is within BACK_WALL_BAND mean diameters of the wall; 0
    where none is."""
    band = BACK_WALL_BAND * 2.0 * float(state.radius.mean())
    near = mask & (state.position[:, 0] - state.radius <= band)
    if not near.any():
        return 0.0
    return float((state.position[near, 2] + state.radius[near]).max())


def mass_front(state: ParticleState, share: float, geometry: str = "cylinder") -> float:
    """Distance (length) from the axis (cylinder) or the back wall (channel), the reach of
    :func:`reach`, within which `share` (0-1) of the mass lies."""
    if not 0.0 < share <= 1.0:
        raise ValueError(f"mass share must be in (0, 1], got {share}")
    edge = reach(state, geometry)
    order = np.argsort(edge)
    cumulative = np.cumsum(state.mass[order]) / state.mass.sum()
    return float(edge[order][np.searchsorted(cumulative, share - 1e-12)])


MAX_PROFILE_BINS = 100_000   # a deposit profile's bins: a million diameters of run-out would need more


def deposit_profile(state: ParticleState, mask: np.ndarray, bin_width: float, r_max: float,
                    geometry: str = "cylinder"):
    """(bin centres, height): max z + R of the selected particles in bins of their centres' distance
    (:func:`distance`: radial in a cylinder, along the channel in a channel; NaN where empty)."""
    edges = np.arange(0.0, r_max + bin_width, bin_width)
    rho = distance(state.position[mask], geometry)
    top = state.position[mask, 2] + state.radius[mask]
    which = np.clip(np.digitize(rho, edges) - 1, 0, len(edges) - 2)
    height = np.full(len(edges) - 1, -np.inf)
    np.maximum.at(height, which, top)
    height[~np.isfinite(height)] = np.nan
    return 0.5 * (edges[1:] + edges[:-1]), height


def undisturbed_top_radius(initial: ParticleState, final: ParticleState, h0: float,
                           tolerance: float, geometry: str = "cylinder") -> float:
    """Extent (length) of the top that stayed in place, the 95th percentile of :func:`distance` over
    the grains of the top layer (initial z + R > h0 - d_max) that moved less than `tolerance`: the
    radius of the top disc of a cylinder, the length from the back wall of a channel's; 0 when none did."""
    top_layer = initial.position[:, 2] + initial.radius > h0 - 2.0 * initial.radius.max()
    moved = np.linalg.norm(final.position - initial.position, axis=1)
    still = top_layer & (moved < tolerance)
    if not still.any():
        return 0.0
    return float(np.percentile(distance(initial.position[still], geometry), 95))


def solver_step_counts(backends) -> tuple[float, float]:
    """(steps solved by APGD, steps Clarabel solved after APGD reached its cap) from each step's
    back-end (step_solver_backend); APGD's count includes the steps it solved in float64 after float32
    storage reached the cap. NaN for both where no back-end is recorded."""
    if len(backends) == 0:
        return np.nan, np.nan
    names = [str(name) for name in backends]
    return (float(names.count("apgd") + names.count(defaults.FLOAT64_FALLBACK)),
            float(names.count("clarabel-fallback")))


def _scalar(value, units: str, long_name: str):
    return (), value, {"units": units, "long_name": long_name}


LONG_NAMES = {
    "cylinder": {
        "h_inf": "final height of the main mass",
        "r_inf": "run-out radius of the main mass",
        "h_inf_over_r0": "final height over initial radius",
        "runout_over_r0": "run-out (r_inf - r0) over initial radius",
        "undisturbed_top_radius": "radius of the top disc that did not move, over r0",
        "front_position": "edge of the main mass: (its run-out radius - r0) over r0",
        FRONT_MASS_VARIABLE: f"front: (radius holding {FRONT_MASS_SHARE:.0%} of the mass - r0) over r0",
        "runout_over_r0_by_tolerance": "run-out (r_inf - r0) over r0 at each contact tolerance",
        "mass_front_over_r0": "(radius holding a share of the mass - r0) over r0",
        "radial_bin": "distance from the axis",
    },
    "channel": {
        "h_inf": "final height of the main mass at the back wall",
        "r_inf": "run-out of the main mass from the back wall",
        "h_inf_over_r0": "final height at the back wall over the box length L0",
        "runout_over_r0": "run-out (L_inf - L0) over the box length L0",
        "undisturbed_top_radius": "length of the top that did not move, from the back wall, over L0",
        "front_position": "edge of the main mass: (its run-out - L0) over L0",
        FRONT_MASS_VARIABLE: f"front: (distance holding {FRONT_MASS_SHARE:.0%} of the mass - L0) over L0",
        "runout_over_r0_by_tolerance": "run-out (L_inf - L0) over L0 at each contact tolerance",
        "mass_front_over_r0": "(distance from the back wall holding a share of the mass - L0) over L0",
        "radial_bin": "distance from the back wall along the channel",
    },
}
"""Each geometry's long names of the analysis variables whose meaning follows the geometry."""


def analyse_trajectory(trajectory, settings: AnalysisSettings, attrs: dict) -> xr.Dataset:
    """The analysis Dataset of a trajectory Dataset: deposit scalars, the run-out at every check
    tolerance and mass share, the deposit profile over `radial_bin`, histories over `time` and the
    kinetic energy over `step`, the run's at_rest flag; `attrs` plus the run's (aspect_ratio, mu_r,
    mu, r0, h0, duration, n_steps, and a channel's length, width and wall friction) and its
    geometry as global attributes. Lengths are normalised by :func:`column_length` (r0 or L0)."""
    geometry = geometry_of(trajectory.attrs)
    names = LONG_NAMES[geometry]
    r0, h0 = column_length(trajectory.attrs), float(trajectory.attrs["h0"])
    initial, final = state_from_dataset(trajectory, 0), state_from_dataset(trajectory, -1)
    tolerance = contact_tolerance(final, settings.contact_tolerance)
    history, mass_fronts = [], []
    for k in range(trajectory.sizes["time"]):   # each frame: the main mass's edge, the mass-share front
        state = state_from_dataset(trajectory, k)
        history.append(measure_deposit(state, tolerance, geometry))
        mass_fronts.append(mass_front(state, FRONT_MASS_SHARE, geometry))
    deposit = history[-1]
    fractions = sorted(set(settings.check_tolerances) | {settings.contact_tolerance})
    checks = [measure_deposit(final, contact_tolerance(final, f), geometry) for f in fractions]
    shares = sorted(set(settings.mass_shares))
    bin_width = settings.bin_width or 2.0 * float(final.radius.max())
    bins = (deposit.r_inf + bin_width) / bin_width
    if bins > MAX_PROFILE_BINS:
        raise ValueError(f"--bin-width {bin_width:g} cuts the deposit (radius {deposit.r_inf:g}) into {bins:.3g} "
                         f"bins, more than {MAX_PROFILE_BINS:,}: take a width of a diameter or so")
    centres, height = deposit_profile(final, deposit.main_mass, bin_width, deposit.r_inf + bin_width, geometry)
    energy = trajectory["step_kinetic_energy"].values + trajectory["step_rotational_energy"].values
    top_radius = undisturbed_top_radius(initial, final, h0, 2.0 * float(final.radius.min()) * 0.1, geometry)
    backends = trajectory["step_solver_backend"].values if "step_solver_backend" in trajectory else []
    apgd_steps, fallback_steps = solver_step_counts(backends)
    data = {
        "h_inf": _scalar(deposit.h_inf, "length", names["h_inf"]),
        "r_inf": _scalar(deposit.r_inf, "length", names["r_inf"]),
        "h_inf_over_r0": _scalar(deposit.h_inf / r0, "1", names["h_inf_over_r0"]),
        "runout_over_r0": _scalar((deposit.r_inf - r0) / r0, "1", names["runout_over_r0"]),
        "n_particles": _scalar(final.n, "1", "number of particles"),
        "n_main_mass": _scalar(int(deposit.main_mass.sum()), "1", "number of particles in the main mass"),
        "solid_fraction": _scalar(float(trajectory.attrs["column_solid_fraction"]), "1",
                                  "solid fraction of the column before release"),
        "final_to_peak_kinetic_energy": _scalar(float(energy[-1] / max(energy.max(), 1e-300)), "1",
                                                "kinetic energy at the end over its peak"),
        "wall_time": _scalar(float(trajectory.attrs["wall_time"]), "s", "wall time of the collapse"),
        "apgd_steps": _scalar(apgd_steps, "1", "steps solved by APGD"),
        "fallback_steps": _scalar(fallback_steps, "1",
                                  "steps solved by Clarabel after APGD reached its iteration cap"),
        "cone_programs_per_step": _scalar(
            float(trajectory["step_friction_iterations"].mean()) if "step_friction_iterations" in trajectory
            else np.nan, "1", "cone programs solved per step (1: associated law; more: Coulomb's fixed point)"),
        "undisturbed_top_radius": _scalar(top_radius / r0, "1", names["undisturbed_top_radius"]),
        "deposit_height": ("radial_bin", height, {"units": "length", "long_name": "deposit height (main mass)"}),
        "front_position": ("time", (np.array([d.r_inf for d in history]) - r0) / r0,
                           {"units": "1", "long_name": names["front_position"]}),
        FRONT_MASS_VARIABLE: ("time", (np.array(mass_fronts) - r0) / r0,
                              {"units": "1", "long_name": names[FRONT_MASS_VARIABLE]}),
        "height_history": ("time", np.array([d.h_inf for d in history]),
                           {"units": "length", "long_name": "height of the main mass"}),
        "runout_over_r0_by_tolerance": ("contact_tolerance", [(d.r_inf - r0) / r0 for d in checks],
                                        {"units": "1", "long_name": names["runout_over_r0_by_tolerance"]}),
        "mass_front_over_r0": ("mass_share", [(mass_front(final, share, geometry) - r0) / r0 for share in shares],
                               {"units": "1", "long_name": names["mass_front_over_r0"]}),
        "mean_diameter": _scalar(2.0 * float(final.radius.mean()), "length", "mean particle diameter"),
        "kinetic_energy": ("step", energy, {"units": "mass length^2/time^2", "long_name": "kinetic energy"}),
        "at_rest": at_rest_variable((), at_rest_flag(trajectory)),
    }
    if geometry == "channel":
        data["h_top"] = _scalar(deposit.h_top, "length", "highest point of the main mass")
    coords = {"radial_bin": ("radial_bin", centres, {"units": "length", "long_name": names["radial_bin"]}),
              "time": ("time", trajectory["time"].values, dict(trajectory["time"].attrs)),
              "scaled_time": ("time", trajectory["scaled_time"].values,
                              {"units": "1", "long_name": "time over sqrt(h0/g)"}),
              "step": trajectory["step"],
              "contact_tolerance": ("contact_tolerance", fractions,
                                    {"units": "1", "long_name": "contact tolerance over the smallest diameter"}),
              "mass_share": ("mass_share", shares, {"units": "1", "long_name": "share of the mass"}),
              **run_coordinates(trajectory.attrs)}
    return xr.Dataset(data, coords=coords, attrs={**attrs, **_run_attributes(trajectory)})


CHANNEL_ATTRIBUTES = ("channel_length", "channel_width", "wall_mu")
"""A channel trajectory's attributes that its analysis carries on (lengths, and a friction coefficient)."""


def _run_attributes(trajectory) -> dict:
    """The trajectory's run description that an analysis carries on."""
    geometry = geometry_of(trajectory.attrs)
    carried = ("aspect_ratio", "mu_r", "mu", "r0", "h0", "duration")
    if geometry == "channel":   # a channel's r0 (if its file has one) is not its column's length
        carried = tuple(key for key in carried if key != "r0" or key in trajectory.attrs) + CHANNEL_ATTRIBUTES
    missing = [key for key in carried if key not in trajectory.attrs]
    if geometry == "channel" and missing:
        raise ValueError(f"a channel file needs attribute {missing[0]}")
    attrs = {key: float(trajectory.attrs[key]) for key in carried}
    attrs["geometry"] = geometry
    attrs["n_steps"] = int(trajectory.attrs["n_steps"])
    attrs["friction_law"] = str(trajectory.attrs.get("friction_law", "associated"))
    # a trajectory written before the option existed was computed with R_eff
    attrs["rolling_lever"] = str(trajectory.attrs.get("rolling_lever", LEVER_OF_OLDER_FILES))
    if "step_solver_backend" in trajectory:   # how many steps each back-end solved
        names, counts = np.unique(trajectory["step_solver_backend"].values.astype(str), return_counts=True)
        attrs["solver_backends"] = json.dumps({str(n): int(c) for n, c in zip(names, counts)})
    return attrs
