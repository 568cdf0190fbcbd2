"""Stages 1 and 2: fill the cylinder by free fall (pack), then cut the column at h0 = a r0 (trim).

Filling follows the paper: spheres with diameters uniform in [d_min, d_max] are created at random
non-overlapping places uniformly across the cylinder, above what is already there, and fall under
gravity with mu = mu_r = 0 until they are at rest. (`mu` sets a sliding friction while filling,
between the spheres and with the floor, for a looser packing than the paper's.) Places come from a jittered cubic lattice of
spacing 1.04 d_max: each sphere moves at random inside its own lattice cell, so no two overlap.
One cloud holds enough spheres for the whole height (:data:`CLOUD_SOLID_FRACTION`); should the
packing settle short of it, clouds are added until it is taller than the requested height.

In layers (`layer_height`, off by default): each cloud adds about that much settled packing and falls a few
diameters, not the column's height; before it falls, the spheres at rest more than `freeze_depth`
below the surface are fixed and leave the cone program, so a step costs what the top of the
packing costs, not the whole column (docs/validation/packing-layers.md measures both ways).

"At rest" means 95 % of the particles have a translational kinetic energy below `rest_energy` times
m g d (1e-3 by default: a speed below 0.045 sqrt(g d)) and 99 % carry a contact force; see
:func:`is_at_rest`. Velocities are then set to zero.
"""
from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..engine.contacts import fixed_pairs
from ..engine.records import Carry
from ..engine.solver_contract import SolverError
from ..engine.solver_contract import Solver
from ..engine.state import ContactLaw, FixedSpheres, ParticleState, StepSettings, Walls, fixed_code
from ..engine.stepper import run
from ..engine.warm_start import WarmStart
from ..io.checkpoint import load_packing_checkpoint, save_packing_checkpoint, sittings_commits
from .settings import POUR_STEP_RANGE, PackSettings
from .pour_geometry import CLOUD_SOLID_FRACTION, cloud_spheres, expected_spheres, mean_sphere_volume  # noqa: F401
from .stopwatch import Stopwatch

log = logging.getLogger(__name__)

LATTICE_FACTOR = 1.04


@dataclass
class PackingResult:
    """The settled packing and what it took. solid_fraction: of the column up to `height`.
    contact_forces: the last step's contact forces (to warm-start what comes next). clouds: how
    many clouds were poured; most_fixed: the most spheres fixed at once while filling.
    wall_time, cpu_time: seconds over all sittings (CPU: all threads; NaN when a sitting's is unknown).
    diagnostics: the StepDiagnostics of every step taken, over all sittings (from the resumed step on for a
    checkpoint written before packings kept them). commits: the git commits of the code of every sitting."""

    state: ParticleState
    height: float
    solid_fraction: float
    steps: int
    wall_time: float
    contact_forces: WarmStart
    clouds: int = 1
    most_fixed: int = 0
    cpu_time: float = float("nan")
    diagnostics: list = field(default_factory=list)
    commits: tuple = ()


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
    starting positions of the pack stage, and through :func:`starting_cloud` of the tests and the
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


def starting_cloud(n: int, r0: float, seed: int | np.random.Generator = 0, z_bottom: float = 0.0,
                   diameter_range=(0.25, 0.5), density: float = 1.0) -> ParticleState:
    """Exactly n spheres at rest, none overlapping, inside radius r0 above z_bottom: the first n of
    :func:`lattice_cloud` (its lowest layers; the top layer is filled from its first cells).

    seed: a seed or a numpy Generator. For the same generator this is the pack stage's own first cloud
    (pack uses every sphere of :func:`lattice_cloud`; this keeps the first n). The tests' pile and
    the benchmarks' packings start here."""
    position, radius = lattice_cloud(r0, n, z_bottom, diameter_range, np.random.default_rng(seed))
    return ParticleState.at_rest(position[:n], radius[:n], density)


def column_height(state: ParticleState) -> float:
    """Height (length) of a settled packing: the 95th percentile of z + R (robust to a loose top grain)."""
    return float(np.percentile(state.position[:, 2] + state.radius, 95)) if state.n else 0.0


def solid_fraction(state: ParticleState, r0: float, height: float) -> float:
    """Volume fraction of spheres (clipped to z in [0, height]) in the cylinder of radius r0."""
    z, r = state.position[:, 2], state.radius
    lo = np.clip(0.0 - z, -r, r)
    hi = np.clip(height - z, -r, r)
    def volume_below(h):
        """Volume of a sphere of radius r below height h relative to its centre, less half a sphere."""
        return np.pi * (r**2 * h - h**3 / 3.0)

    return float(np.sum(volume_below(hi) - volume_below(lo)) / (np.pi * r0**2 * height))


def is_at_rest(result, gravity: float, rest_energy: float, rest_fraction: float = 0.95) -> bool:
    """Is the packing after this step (a StepResult) settled?

    Two conditions: at least `rest_fraction` of the particles have a translational kinetic energy
    below rest_energy m g d, and at least 99 % carry a contact force (so a cloud still at rest in
    the air is not taken as settled). A fraction rather than all particles, and translation only:
    with mu = mu_r = 0 a grain can slide along the floor or orbit along the frictionless cylinder
    forever (a true steady state of the filling), and nothing stops a grain spinning in place.
    """
    state = result.state
    slow = _slow(state, gravity, rest_energy)
    loaded = result.solution.forces[:, 0] > 0
    supported = np.zeros(state.n, dtype=bool)
    supported[result.contacts.i[loaded]] = True
    supported[result.contacts.j[loaded & (result.contacts.j >= 0)]] = True
    return slow.mean() >= rest_fraction and supported.mean() >= 0.99




#: A layer has landed (the next cloud may come) at the rest criterion with this many times
#: rest_energy: speeds 10x those of rest. Only the last cloud must come to rest.
LANDED_ENERGY_FACTOR = 100.0
#: a packing logs its progress every 50 steps, and at least this often (seconds): the steps of a big
#: pour's impact take 5-15 s each, and 50 of them left the log silent for over ten minutes
LOG_INTERVAL_S = 60.0


def pack_from(settings: PackSettings, rng: np.random.Generator, solver: Solver,
              checkpoint: str | Path | None = None, progress=None) -> PackingResult:
    """:func:`pack` with the pour's settings (`colsim pack`'s)."""
    return pack(settings.r0, settings.height, rng, solver, (settings.diameter_min, settings.diameter_max),
                settings.density, settings.gravity, settings.dt, settings.rest_energy, settings.max_steps,
                progress=progress, mu=settings.mu, max_spheres=settings.max_spheres,
                layer_height=settings.layer_height, freeze_depth=settings.freeze_depth, checkpoint=checkpoint,
                checkpoint_every=settings.checkpoint_every)


def pack(r0: float, height: float, rng: np.random.Generator, solver: Solver, diameter_range=(0.25, 0.5),
         density: float = PackSettings.density, gravity: float = PackSettings.gravity, dt: float = PackSettings.dt,
         rest_energy: float = PackSettings.rest_energy, max_steps: int = PackSettings.max_steps, progress=None,
         mu: float = PackSettings.mu, max_spheres: int | None = PackSettings.max_spheres,
         layer_height: float | None = PackSettings.layer_height, freeze_depth: float = PackSettings.freeze_depth,
         checkpoint: str | Path | None = None, checkpoint_every: int = PackSettings.checkpoint_every) -> PackingResult:
    """Fill a cylinder of radius r0 until the settled packing is taller than `height` (length),
    solving each step with `solver`. mu: sliding friction between the spheres and with the floor
    while filling (the paper's 0; the cylinder stays frictionless, rolling is free).
    max_spheres: ValueError before anything is allocated when the packing would hold more
    (:func:`expected_spheres`; None: no bound).

    layer_height: each cloud adds about this settled thickness (length; None: one cloud for the
    whole height). Before a cloud falls, the spheres more than freeze_depth (length) below the
    settled surface that are at rest become fixed (:class:`colsim.engine.state.FixedSpheres`): they leave
    the program, and the cloud and the top of the packing settle on them. A cloud is followed by
    the next once it has landed (:data:`LANDED_ENERGY_FACTOR`); the last one and the spheres not
    fixed step until :func:`is_at_rest` (the fixed ones were at rest when fixed). The forces
    handed on are the last step's, and between fixed spheres those of when they last moved.

    checkpoint: a file written every `checkpoint_every` steps and after
    :data:`~colsim.stages.stopwatch.CHECKPOINT_INTERVAL_S` of wall time without one (atomically);
    a packing started again with the same inputs, settings and generator state resumes from it and
    ends with the same packing as one never stopped. None: no checkpoint."""
    d_min, d_max = diameter_range
    if not 0 < d_min <= d_max:
        raise ValueError(f"diameter range must satisfy 0 < min <= max, got {diameter_range}")
    if r0 < d_max:
        raise ValueError(f"cylinder radius r0 = {r0} is smaller than the largest particle (diameter {d_max})")
    if height <= 0:
        raise ValueError(f"packing height must be positive, got {height}")
    scaled = dt * np.sqrt(gravity / d_min)
    if not POUR_STEP_RANGE[0] <= scaled <= POUR_STEP_RANGE[1]:
        raise ValueError(f"the pour's step dt = {dt:g} is {scaled:.3g} times sqrt(d_min/g), the time to fall about a"
                         f" diameter; it must lie within {POUR_STEP_RANGE[0]:g}-{POUR_STEP_RANGE[1]:g} (gravity {gravity:g})")
    if layer_height is not None and not layer_height > 0:
        raise ValueError(f"layer height must be positive (or None: one cloud), got {layer_height}")
    if not freeze_depth >= 0:
        raise ValueError(f"freeze depth must be >= 0, got {freeze_depth}")
    settings = StepSettings(dt=dt, gravity=(0.0, 0.0, -gravity), walls=Walls(cylinder_radius=r0),
                            law=ContactLaw.uniform(mu, 0.0))
    expected = expected_spheres(r0, height, diameter_range)
    if max_spheres is not None and expected > max_spheres:
        raise ValueError(f"the packing of r0 = {r0:g} to height {height:g} would hold about {expected:,.0f} "
                         f"spheres (diameters {d_min:g}-{d_max:g}), above the bound of {max_spheres:,} "
                         "(raise it with --max-spheres, or pack.max_spheres in a study)")
    fingerprint = _fingerprint(rng, solver, r0=r0, height=height, diameter_range=diameter_range,
                               density=density, gravity=gravity, dt=dt, rest_energy=rest_energy,
                               mu=mu, layer_height=layer_height, freeze_depth=freeze_depth)
    saved = load_packing_checkpoint(checkpoint, fingerprint)
    state = ParticleState.at_rest(np.zeros((0, 3)), np.zeros(0), density)
    fixed = np.zeros(0, dtype=bool)
    clock, steps, warm = Stopwatch(), 0, None
    clouds, most_fixed = 0, 0
    history = []   # each step's StepDiagnostics
    earlier = []   # the commits of the earlier sittings
    if saved:
        loop = saved["loop"]
        state, warm, fixed = saved["state"], saved["warm"], loop["fixed"].astype(bool)
        steps, clouds, most_fixed = int(loop["steps"]), int(loop["clouds"]), int(loop["most_fixed"])
        rng.bit_generator.state = json.loads(str(loop["rng"]))
        clock = Stopwatch(saved["elapsed"], saved["cpu"])
        history, earlier = saved["diagnostics"], saved["commits"]
        log.info("resuming the packing from its checkpoint at step %d (cloud %d, %d spheres)", steps, clouds, state.n)
    while saved or column_height(state) < height:
        if saved:   # the cloud the checkpoint was written in
            last, energy = bool(loop["last"]), float(loop["energy"])
            resume = {"supports": loop["supports"].astype(np.int64), "margin": saved["margin"]}
            saved = None
        else:
            last, energy, resume = None, None, None
        if resume is None:
            surface = column_height(state)
            missing = height + 2 * d_max - surface
            last = layer_height is None or missing <= layer_height + 2 * d_max
            thickness = missing if last else layer_height
            n_new = int(np.ceil(cloud_spheres(r0, thickness, diameter_range)))
            z_bottom = float(np.max(state.position[:, 2] + state.radius, initial=0.0))
            if layer_height is not None:
                fixed |= _buried_at_rest(state, surface - freeze_depth, gravity, rest_energy)
            position, radius = lattice_cloud(r0, n_new, z_bottom, diameter_range, rng)
            state = _add(state, position, radius)
            fixed = np.concatenate([fixed, np.zeros(len(radius), dtype=bool)])
            clouds, most_fixed = clouds + 1, max(most_fixed, int(np.count_nonzero(fixed)))
            log.info("pouring %d spheres (%d in all, %d fixed) from z = %.2f", len(radius), state.n,
                     np.count_nonzero(fixed), z_bottom)
            energy = rest_energy if last else LANDED_ENERGY_FACTOR * rest_energy
        save = None
        if checkpoint is not None:
            def save(placed, forces, margin, steps_done, supports, fixed=fixed, last=last, energy=energy):
                loop = {"fixed": fixed, "steps": steps_done, "clouds": clouds, "most_fixed": most_fixed,
                        "rng": json.dumps(rng.bit_generator.state), "last": last, "energy": energy,
                        "supports": supports}
                save_packing_checkpoint(checkpoint, fingerprint, placed, forces, margin, loop,
                                        clock.wall(), clock.cpu(), history, earlier)
        try:
            state, warm, steps = _settle(state, fixed, settings, solver, warm, steps, max_steps, energy, progress,
                                         resume, save, checkpoint_every, clock, history)
        except SolverError as error:
            if not fixed.any():
                raise
            # a moving sphere caged by fixed ones that overlap it from opposite sides has no
            # feasible step: this cloud settles again with nothing fixed
            log.warning("%s; settling this cloud again with nothing fixed", error)
            fixed[:] = False
            state, warm, steps = _settle(state, fixed, settings, solver, warm, error.step or steps,
                                         max_steps, energy, progress, None, save, checkpoint_every, clock, history)
    state.velocity[:] = 0.0
    state.angular_velocity[:] = 0.0
    state.time = 0.0
    return PackingResult(state, column_height(state), solid_fraction(state, r0, height),
                         steps, clock.wall(), warm, clouds, most_fixed, clock.cpu(), history,
                         tuple(sittings_commits(earlier)))


def _fingerprint(rng: np.random.Generator, solver: Solver, **settings) -> str:
    """What a packing checkpoint must match: the generator's state at the start, the solver and
    every setting of :func:`pack` that changes a step (not max_steps nor checkpoint_every: a pour
    stopped at max_steps resumes when given more)."""
    described = [rng.bit_generator.state, solver.describe(), settings]
    return hashlib.sha256(json.dumps(described, sort_keys=True, default=str).encode()).hexdigest()


def _buried_at_rest(state: ParticleState, depth_z: float, gravity: float, rest_energy: float) -> np.ndarray:
    """(n,) bool: spheres whose top is below depth_z (length) and whose kinetic energy of
    translation is below rest_energy m g d."""
    return _slow(state, gravity, rest_energy) & (state.position[:, 2] + state.radius < depth_z)


def _slow(state: ParticleState, gravity: float, rest_energy: float) -> np.ndarray:
    """(n,) bool: translational kinetic energy below rest_energy m g d (d the sphere's diameter)."""
    speed2 = np.einsum("ij,ij->i", state.velocity, state.velocity)
    return 0.5 * speed2 / (gravity * 2.0 * state.radius) < rest_energy


def _settle(state: ParticleState, fixed: np.ndarray, settings: StepSettings, solver: Solver,
            warm: WarmStart | None, steps: int, max_steps: int, rest_energy: float, progress,
            resume: dict | None = None, save=None, save_every: int = PackSettings.checkpoint_every,
            clock: Stopwatch | None = None, history: list | None = None):
    """Step the spheres not `fixed` ((n,) bool) on the fixed ones until :func:`is_at_rest` with
    rest_energy. warm: forces by pair in the numbering of `state` (None: cold). Returns the new
    state, the forces by pair (numbering of `state`: the last step's, and those of pairs of fixed
    spheres from when they last moved) and the step count.

    resume: {supports, margin} of a cloud resumed from a checkpoint (the fixed spheres it settles
    on, and the detection margin its next step starts from); save: optional callable(state, warm,
    margin, steps, supports), called every `save_every` steps with the whole packing, and when
    :data:`~colsim.stages.stopwatch.CHECKPOINT_INTERVAL_S` of `clock`'s wall time passed since the last;
    history: a list to which each step's StepDiagnostics is appended."""
    clock = clock or Stopwatch()
    moving = np.flatnonzero(~fixed)
    if resume is None:
        below = state.position[moving, 2] - state.radius[moving]
        near = fixed & (state.position[:, 2] + state.radius > float(below.min()) - 2.0 * state.radius.max())
        supports, margin = np.flatnonzero(near), None
    else:
        supports, margin = resume["supports"], resume["margin"]
    walls = replace(settings.walls, fixed=FixedSpheres(state.position[supports], state.radius[supports]))
    local = replace(settings, walls=walls)
    carry = Carry(None if warm is None else _renumber(warm, moving, supports, state.n), margin)
    sub = state.subset(moving)
    gravity = -settings.gravity[2]
    logged = time.perf_counter()
    for result in run(sub, local, max_steps - steps, solver, first_step=steps, carry=carry):
        sub, steps = result.state, steps + 1
        if history is not None:
            history.append(result.diagnostics)
        if progress is not None:
            progress(result.diagnostics, sub)
        if steps % 50 == 0 or time.perf_counter() - logged >= LOG_INTERVAL_S:
            logged = time.perf_counter()
            d = result.diagnostics
            log.info("pack step %d: %d moving, %d contacts, kinetic energy %.3g, %.2f s solve",
                     steps, sub.n, d.n_contacts, d.kinetic_energy + d.rotational_energy, d.solve_time)
        if is_at_rest(result, gravity, rest_energy):
            break
        if save is not None and clock.checkpoint_due(steps % save_every == 0):
            forces = _number_back(WarmStart.from_step(result.contacts, result.solution.forces), moving, supports)
            save(_place(state, moving, sub), _merge(_between_fixed(warm, fixed), forces),
                 result.carry.margin, steps, supports)
    else:
        raise RuntimeError(f"packing not at rest after {max_steps} steps (raise max_steps or dt)")
    _check_clear_of_fixed(sub, state.subset(fixed), settings.overlap_tolerance)
    state = _place(state, moving, sub)
    forces = _number_back(WarmStart.from_step(result.contacts, result.solution.forces), moving, supports)
    return state, _merge(_between_fixed(warm, fixed), forces), steps


def _place(state: ParticleState, moving: np.ndarray, sub: ParticleState) -> ParticleState:
    """`state` with the particles `moving` (indices) replaced by those of `sub`, at sub's time."""
    out = state.copy()
    out.position[moving], out.velocity[moving] = sub.position, sub.velocity
    out.angular_velocity[moving] = sub.angular_velocity
    out.time = sub.time
    return out


def _renumber(warm: WarmStart, moving: np.ndarray, supports: np.ndarray, n: int) -> WarmStart:
    """The pairs of `warm` (numbered as the n particles) between a moving particle and a moving
    one, a wall or a support, numbered as the step numbers them: moving in order, supports as fixed
    spheres (j = -2 - k)."""
    as_moving = np.full(n, -1, dtype=np.int64)
    as_moving[moving] = np.arange(len(moving))
    as_support = np.full(n, -1, dtype=np.int64)
    as_support[supports] = np.arange(len(supports))
    i = as_moving[warm.i]
    other = np.maximum(warm.j, 0)
    j = np.where(warm.j < 0, warm.j,
                 np.where(as_moving[other] >= 0, as_moving[other], fixed_code(as_support[other])))
    keep = (i >= 0) & ((warm.j < 0) | (as_moving[other] >= 0) | (as_support[other] >= 0))
    return WarmStart(i[keep], j[keep], warm.family[keep], warm.force[keep], warm.rolling[keep])


def _number_back(forces: WarmStart, moving: np.ndarray, supports: np.ndarray) -> WarmStart:
    """The inverse of :func:`_renumber`: a step's forces in the numbering of the whole packing."""
    j = forces.j.copy()                       # walls keep -1
    particle, fixed = forces.j >= 0, forces.j <= -2
    j[particle] = moving[forces.j[particle]]
    j[fixed] = supports[-2 - forces.j[fixed]]
    return WarmStart(moving[forces.i], j, forces.family.copy(), forces.force.copy(), forces.rolling.copy())


def _between_fixed(warm: WarmStart | None, fixed: np.ndarray) -> WarmStart | None:
    """The pairs of `warm` whose bodies are all fixed (or walls): their forces from when they last moved."""
    if warm is None:
        return None
    keep = fixed[warm.i] & ((warm.j == -1) | fixed[np.maximum(warm.j, 0)])
    return WarmStart(warm.i[keep], warm.j[keep], warm.family[keep], warm.force[keep], warm.rolling[keep])


def _merge(old: WarmStart | None, new: WarmStart) -> WarmStart:
    """The pairs of two warm starts with no pair in both."""
    if old is None:
        return new
    return WarmStart(*(np.concatenate([getattr(old, name), getattr(new, name)])
                       for name in ("i", "j", "family", "force", "rolling")))


def _check_clear_of_fixed(moving: ParticleState, fixed: ParticleState, tolerance: float) -> None:
    """RuntimeError when a moving sphere overlaps a fixed one by more than `tolerance` of the
    smallest diameter: one that sank below the supports given to the program."""
    if fixed.n == 0 or moving.n == 0:
        return
    allowed = tolerance * 2.0 * float(min(moving.radius.min(), fixed.radius.min()))
    _, _, _, gap = fixed_pairs(moving, FixedSpheres(fixed.position, fixed.radius), np.zeros(moving.n))
    if gap.size and -gap.min() > allowed:
        raise RuntimeError(f"a settling sphere overlaps a fixed one by {-gap.min():.3g} (allowed {allowed:.3g}): "
                           "it sank below the supports; raise pack.freeze_depth")


def _add(state: ParticleState, position, radius) -> ParticleState:
    zeros = np.zeros_like(position)
    return ParticleState(
        np.vstack([state.position, position]), np.vstack([state.velocity, zeros]),
        np.vstack([state.angular_velocity, zeros]), np.concatenate([state.radius, radius]),
        state.density, state.time,
    )
