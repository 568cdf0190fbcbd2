"""Settled random packings for benchmarks, built by pouring with the engine and cached as .npz.

    from packings import settled_packing            # with benchmarks/ on sys.path
    state = settled_packing(1000)                   # ParticleState, about at rest on the floor z = 0

    python -m benchmarks packings 1000 4000         # build them (or show the cached ones)

How a packing is made (``build_packing``):

1. **Cloud**: the pack stage's own generator, :func:`colsim.stages.pack.starting_cloud` (the tests'
   pile starts there too): a cubic lattice of spacing 0.52 (1.04 d_max) inside a cylinder of radius
   r0 (about the z axis), the bottom layer at z = 0.26, radii uniform in [0.125, 0.25] (the paper's
   diameters 0.25-0.5), each sphere at a random place inside its own cell, so the cloud does not
   overlap. r0 is the smallest radius (in steps of 0.1) for which the lattice column is at most
   ``aspect`` (2.5) r0 tall, so the settled column (solid fraction about 0.58 against the lattice's
   0.22) stands about r0 high: wide and shallow columns settle in fewer steps than tall ones.
2. **Pour**: mu = mu_r = 0 with the cylinder, dt = 0.02, until the kinetic energy per particle is
   below ``pour_tolerance`` (1e-4) m g d (mean mass, mean diameter), or ``max_pour_steps``.
   Frictionless spheres keep rearranging for hundreds of steps at about 1e-4 m g d.
3. **Lock**: the same packing with the collapse's friction (mu = 0.577, mu_r = 0.12, cylinder still
   on) until the kinetic energy per particle is below ``lock_tolerance`` (1e-8) m g d, or
   ``max_lock_steps``. Friction freezes the frictionless structure in a few tens of steps without
   changing it measurably; the result is what the collapse starts from.

Large packings (``n_target > tile_above``, 2,000 by default) are not poured: on the shared 2-core
machine a frictionless 1,000-sphere pour took 10 minutes (331 + 11 steps, from the former cloud: a
lattice centred on the axis, jittered by 0.005) and 4,000 spheres did not
get past 50 steps in 3 minutes, so 4,000 would take about an hour and 16,000 many hours. They are
2 x 2 copies of a settled packing of n_target / 4 spheres (itself
poured or tiled), their axes at (+-s, +-s) with s = r0 + 0.005, r0 the half-width of the copy (its
cylinder's radius, or for a tiled copy 2 r0' + 0.01), so no two copies touch. The copies are
identical, which a one-step benchmark does not notice (the program has the same size and structure
as a poured one); at the seams the columns meet with a gap of >= 0.01 instead of interlocking.
Velocities are kept (about 0).

Cache: ``benchmarks/.cache/settled_v2_<n>_seed<seed>.npz`` (git-ignored) with position, velocity,
angular_velocity, radius, cylinder_radius, and the build's record (steps, final kinetic energy).
Delete a file to rebuild it. (``v2``: poured from the pack stage's cloud; the former
``settled_<n>_seed<seed>.npz`` came from the former cloud and are not read.)
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import record as run_record
from colsim.solvers import ClarabelSolver, Solver
from colsim.engine.state import ContactLaw, ParticleState, StepSettings, Walls
from colsim.engine.stepper import step
from colsim.stages.pack import starting_cloud
from colsim.stages.pour_geometry import LATTICE_FACTOR, lattice_layer

CACHE = run_record.cache_dir()
DIAMETER_RANGE = (0.25, 0.5)
SPACING = LATTICE_FACTOR * DIAMETER_RANGE[1]   # the pack stage's lattice: 0.52


def cylinder_radius_for(n_target: int, aspect: float = 2.5) -> float:
    """Smallest r0 (steps of 0.1) whose lattice column of n_target spheres is at most aspect r0 tall."""
    r0 = 1.0
    while True:
        per_layer = len(lattice_layer(r0, SPACING))
        if per_layer and math.ceil(n_target / per_layer) * SPACING <= aspect * r0:
            return round(r0, 1)
        r0 += 0.1


def energy_scale(state: ParticleState, gravity: float = 9.81) -> float:
    """m g d with the mean mass and mean diameter: the energy unit of the settling criteria."""
    return float(state.mass.mean() * gravity * 2.0 * state.radius.mean())


def build_packing(n: int, seed: int = 0, dt: float = 0.02, solver: Solver | None = None,
                  cylinder_radius: float | None = None, pour_tolerance: float = 1e-4,
                  lock_tolerance: float = 1e-8, max_pour_steps: int = 500, max_lock_steps: int = 100,
                  verbose: bool = True) -> tuple[ParticleState, dict]:
    """Pour and lock a packing of n spheres (module docstring); returns (state, record)."""
    solver = solver or ClarabelSolver()
    r0 = cylinder_radius or cylinder_radius_for(n)
    state = starting_cloud(n, r0, seed, diameter_range=DIAMETER_RANGE)
    scale = energy_scale(state)
    walls = Walls(floor=True, cylinder_radius=r0)
    phases = [
        ("pour", StepSettings(dt=dt, walls=walls, law=ContactLaw.uniform(0.0, 0.0)),
         pour_tolerance, max_pour_steps),
        ("lock", StepSettings(dt=dt, walls=walls, law=ContactLaw.uniform(0.577, 0.12)),
         lock_tolerance, max_lock_steps),
    ]
    # the cloud must fall before "at rest" means settled: at least the free-fall time of its top
    fall_steps = int(math.sqrt(2.0 * state.position[:, 2].max() / 9.81) / dt) + 10
    record = {"n": n, "seed": seed, "dt": dt, "cylinder_radius": r0}
    k, start = 0, time.perf_counter()
    for name, settings, tolerance, max_steps in phases:
        for phase_step in range(1, max_steps + 1):
            k += 1
            result = step(state, settings, solver, step_number=k)
            state, d = result.state, result.diagnostics
            energy = (d.kinetic_energy + d.rotational_energy) / n / scale
            if verbose and (k % 25 == 0 or energy < tolerance):
                print(f"  {name} step {k}: {d.n_contacts} contacts, kinetic energy {energy:.2e} m g d "
                      f"per particle, overlap {d.largest_overlap:.1e}, {time.perf_counter() - start:.0f} s",
                      file=sys.stderr, flush=True)
            if energy < tolerance and (name != "pour" or k >= fall_steps):
                break
        record[f"{name}_steps"] = phase_step
        record[f"{name}_energy"] = energy
    record["seconds"] = time.perf_counter() - start
    return replace(state, time=0.0), record


def tile(state: ParticleState, cylinder_radius: float) -> ParticleState:
    """2 x 2 copies of a packing within |x|, |y| <= r0 (length), at (+-s, +-s), s = r0 + 0.005."""
    s = cylinder_radius + 0.005
    shifts = np.array([[-s, -s, 0.0], [s, -s, 0.0], [-s, s, 0.0], [s, s, 0.0]])
    return ParticleState(
        position=np.concatenate([state.position + shift for shift in shifts]),
        velocity=np.tile(state.velocity, (4, 1)),
        angular_velocity=np.tile(state.angular_velocity, (4, 1)),
        radius=np.tile(state.radius, 4),
        density=state.density,
    )


def cache_path(n_target: int, seed: int = 0) -> Path:
    return CACHE / f"settled_v2_{n_target}_seed{seed}.npz"


def settled_packing(n_target: int, seed: int = 0, tile_above: int = 2000, verbose: bool = True,
                    **build_options) -> ParticleState:
    """A settled packing of n_target spheres (exactly n_target, or 4 * (n_target // 4) when tiled:
    4,000 is 2 x 2 poured 1,000s and 16,000 is 2 x 2 of those).

    Read from the cache when there; otherwise built (module docstring) and cached. build_options go
    to :func:`build_packing` and are not part of the cache key.
    """
    path = cache_path(n_target, seed)
    if path.exists():
        data = np.load(path)
        return ParticleState(data["position"], data["velocity"], data["angular_velocity"],
                             data["radius"])
    if n_target > tile_above:
        quarter = n_target // 4
        base = settled_packing(quarter, seed, tile_above, verbose, **build_options)
        r0 = float(np.load(cache_path(quarter, seed))["cylinder_radius"])
        state = tile(base, r0)
        record = {"n": state.n, "seed": seed, "tiled_from": quarter, "cylinder_radius": 2 * r0 + 0.01}
    else:
        if verbose:
            print(f"pouring {n_target} spheres (seed {seed}) for {path.name}", file=sys.stderr)
        state, record = build_packing(n_target, seed, verbose=verbose, **build_options)
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez(path, position=state.position, velocity=state.velocity,
             angular_velocity=state.angular_velocity, radius=state.radius,
             **{key: np.asarray(value) for key, value in record.items()})
    return state


def packing_record(n_target: int, seed: int = 0) -> dict:
    """The build record stored with a cached packing (cylinder_radius, steps, energies...)."""
    data = np.load(cache_path(n_target, seed))
    return {key: data[key].item() for key in data.files if data[key].ndim == 0}


def main(argv=None):
    import argparse

    parser = argparse.ArgumentParser(description="Build (or show) cached settled packings.")
    parser.add_argument("n", type=int, nargs="+", help="target sphere counts, e.g. 1000 4000")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    table = run_record.table(["target", "spheres", "cylinder radius", "pour steps", "lock steps", "build s",
                          "tiled from"])
    for n in args.n:
        packing = settled_packing(n, args.seed)
        built = packing_record(n, args.seed)
        cells = [built.get(key, "-") for key in ("cylinder_radius", "pour_steps", "lock_steps", "seconds",
                                                   "tiled_from")]
        table.row(n, packing.n, *(f"{c:.4g}" if isinstance(c, float) else c for c in cells),
                  data={"target": n, "spheres": packing.n, **built})


if __name__ == "__main__":
    run_record.run("packings", main)
