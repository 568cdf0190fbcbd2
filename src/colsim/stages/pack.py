"""Stages 1 and 2: fill the cylinder by free fall (pack), then cut the column at h0 = a r0 (trim).

A channel (geometry channel) is filled the same way: its box 0 < x < L0, |y| < W/2, between the
back wall, the sidewalls and the gate (plane walls, :func:`colsim.engine.state.channel_planes`),
frictionless as the cylinder is; L0 plays r0's role.

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
from ..engine.backend import HOST, Backend
from ..engine.solver_contract import Solver, SolverError
from ..engine.state import ContactLaw, FixedSpheres, ParticleState, StepSettings, Walls, channel_planes
from ..engine.stepper import run
from ..engine.warm_start import WarmStart
from ..io.checkpoint import load_packing_checkpoint, save_packing_checkpoint, segment_commits
from .settings import POUR_STEP_RANGE, PackSettings
from .pour_geometry import Channel, cloud_spheres, column_height, expected_spheres, lattice_cloud, solid_fraction
from .stopwatch import Stopwatch

log = logging.getLogger(__name__)



@dataclass
class PackingResult:
    """The settled packing and what it took. solid_fraction: of the column up to `height`.
    contact_forces: the last step's contact forces (to warm-start what comes next). clouds: how
    many clouds were poured; most_fixed: the most spheres fixed at once while filling.
    wall_time, cpu_time: seconds over all segments (CPU: all threads; NaN when a segment's is unknown).
    diagnostics: the StepDiagnostics of every step taken, over all segments (from the resumed step on for a
    checkpoint written before packings kept them). commits: the git commits of the code of every segment."""

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


def starting_cloud(n: int, r0, seed: int | np.random.Generator = 0, z_bottom: float = 0.0,
                   diameter_range=(0.25, 0.5), density: float = 1.0) -> ParticleState:
    """Exactly n spheres at rest, none overlapping, inside radius r0 (or the box of the footprint r0,
    a :class:`colsim.stages.pour_geometry.Channel`) above z_bottom: the first n of
    :func:`lattice_cloud` (its lowest layers; the top layer is filled from its first cells).

    seed: a seed or a numpy Generator. For the same generator this is the pack stage's own first cloud
    (pack uses every sphere of :func:`lattice_cloud`; this keeps the first n). The tests' pile and
    the benchmarks' packings start here."""
    position, radius = lattice_cloud(r0, n, z_bottom, diameter_range, np.random.default_rng(seed))
    return ParticleState.at_rest(position[:n], radius[:n], density)


def is_at_rest(result, gravity: float, rest_energy: float, rest_fraction: float = 0.95) -> bool:
    """Is the packing after this step (a StepResult) settled?

    Two conditions: at least `rest_fraction` of the particles have a translational kinetic energy
    below rest_energy m g d, and at least 99 % carry a contact force (so a cloud still at rest in
    the air is not taken as settled). A fraction rather than all particles, and translation only:
    with mu = mu_r = 0 a grain can slide along the floor or orbit along the frictionless cylinder
    forever (a true steady state of the filling), and nothing stops a grain spinning in place.
    """
    state = result.state
    if _slow(state, gravity, rest_energy).mean() < rest_fraction:
        return False   # the contacts' bodies not read: on the GPU they stay there (DeviceContacts)
    loaded = result.solution.forces[:, 0] > 0
    supported = np.zeros(state.n, dtype=bool)
    supported[result.contacts.i[loaded]] = True
    supported[result.contacts.j[loaded & (result.contacts.j >= 0)]] = True
    return supported.mean() >= 0.99




#: A layer has landed (the next cloud may come) at the rest criterion with this many times
#: rest_energy: speeds 10x those of rest. Only the last cloud must come to rest.
LANDED_ENERGY_FACTOR = 100.0
#: a packing logs its progress every 50 steps, and at least this often (seconds): the steps of a big
#: pour's impact take seconds each, and 50 of them would leave the log silent for many minutes
LOG_INTERVAL_S = 60.0


def pack(settings: PackSettings, rng: np.random.Generator, solver: Solver,
         checkpoint: str | Path | None = None, progress=None, backend: Backend = HOST) -> PackingResult:
    """Fill a cylinder of radius settings.r0 (or a channel's box: settings.footprint) until the settled
    packing is taller than
    settings.height (length), solving each step with `solver`; `rng` places the spheres. A
    ValueError names a setting the pour cannot use, before anything is allocated (a packing
    expected to hold more than settings.max_spheres included: :func:`expected_spheres`).

    settings.mu: sliding friction between the spheres and with the floor while filling (the
    paper's 0; the cylinder stays frictionless, rolling is free). settings.layer_height: each cloud
    adds about this settled thickness (None: one cloud for the whole height). Before a cloud falls,
    the spheres more than settings.freeze_depth below the settled surface that are at rest become
    fixed (:class:`colsim.engine.state.FixedSpheres`): they leave the program, and the cloud and
    the top of the packing settle on them. A cloud is followed by the next once it has landed
    (:data:`LANDED_ENERGY_FACTOR`); the last one and the spheres not fixed step until
    :func:`is_at_rest` (the fixed ones were at rest when fixed). The forces handed on are the last
    step's, and between fixed spheres those of when they last moved.

    checkpoint: a file written every settings.checkpoint_every steps and after
    :data:`~colsim.stages.stopwatch.CHECKPOINT_INTERVAL_S` of wall time without one (atomically);
    a packing started again with the same settings and generator state resumes from it and ends
    with the same packing as one never stopped. None: no checkpoint. progress: optional
    callable(StepDiagnostics, moving spheres' ParticleState) after each step. backend: where the
    steps run (:mod:`colsim.engine.backend`; the solver's must be the same)."""
    _check(settings)
    fingerprint = _fingerprint(rng, solver, settings)
    saved = load_packing_checkpoint(checkpoint, fingerprint)
    pour = _Pour(settings, solver, progress, backend)
    state = ParticleState.at_rest(np.zeros((0, 3)), np.zeros(0), settings.density)
    fixed = np.zeros(0, dtype=bool)
    steps, warm, clouds, most_fixed = 0, None, 0, 0
    earlier = []   # the commits of the earlier segments
    if saved:
        loop = saved["loop"]
        state, warm, fixed = saved["state"], saved["warm"], loop["fixed"].astype(bool)
        steps, clouds, most_fixed = int(loop["steps"]), int(loop["clouds"]), int(loop["most_fixed"])
        rng.bit_generator.state = json.loads(str(loop["rng"]))
        pour.clock = Stopwatch(saved["elapsed"], saved["cpu"])
        pour.history, earlier = saved["diagnostics"], saved["commits"]
        log.info("resuming the packing from its checkpoint at step %d (cloud %d, %d spheres)", steps, clouds, state.n)
    while saved or column_height(state) < settings.height:
        if saved:   # the cloud the checkpoint was written in
            last, energy = bool(loop["last"]), float(loop["energy"])
            resume = {"supports": loop["supports"].astype(np.int64), "margin": saved["margin"]}
            saved = None
        else:
            state, fixed, last = _pour_cloud(state, fixed, settings, rng)
            clouds, most_fixed = clouds + 1, max(most_fixed, int(np.count_nonzero(fixed)))
            energy = settings.rest_energy * (1.0 if last else LANDED_ENERGY_FACTOR)
            resume = None
        save = None
        if checkpoint is not None:
            def save(placed, forces, margin, steps_done, supports, fixed=fixed, last=last, energy=energy):
                loop = {"fixed": fixed, "steps": steps_done, "clouds": clouds, "most_fixed": most_fixed,
                        "rng": json.dumps(rng.bit_generator.state), "last": last, "energy": energy,
                        "supports": supports}
                save_packing_checkpoint(checkpoint, fingerprint, placed, forces, margin, loop,
                                        pour.clock.wall(), pour.clock.cpu(), pour.history, earlier)
        try:
            state, warm, steps = pour.settle(state, fixed, warm, steps, energy, resume, save)
        except SolverError as error:
            if not fixed.any():
                raise
            # a moving sphere caged by fixed ones that overlap it from opposite sides has no
            # feasible step: this cloud settles again with nothing fixed
            log.warning("%s; settling this cloud again with nothing fixed", error)
            fixed[:] = False
            state, warm, steps = pour.settle(state, fixed, warm, error.step or steps, energy, None, save)
    # new arrays, not zeroed in place: a GPU's steps keep device copies of theirs (engine/cuda_state)
    state = replace(state, velocity=np.zeros_like(state.velocity), angular_velocity=np.zeros_like(state.velocity),
                    time=0.0)
    return PackingResult(state, column_height(state), solid_fraction(state, settings.footprint, settings.height),
                         steps, pour.clock.wall(), warm, clouds, most_fixed, pour.clock.cpu(), pour.history,
                         tuple(segment_commits(earlier)))


def check_pour_step(dt: float, gravity: float, d_min: float) -> None:
    """ValueError unless the pour's step dt lies within POUR_STEP_RANGE of sqrt(d_min/g), the time to
    fall about a diameter: a pour's own check, and that of a packing's or a column's gravity."""
    scaled = dt * np.sqrt(gravity / d_min)
    if not POUR_STEP_RANGE[0] <= scaled <= POUR_STEP_RANGE[1]:
        raise ValueError(f"the pour's step dt = {dt:g} is {scaled:.3g} times sqrt(d_min/g), the time to fall"
                         f" about a diameter; it must lie within {POUR_STEP_RANGE[0]:g}-{POUR_STEP_RANGE[1]:g}"
                         f" (gravity {gravity:g})")


def _check(settings: PackSettings) -> None:
    """ValueError naming the first setting a pour cannot use."""
    d_min, d_max, gravity = settings.diameter_min, settings.diameter_max, settings.gravity
    if not 0 < d_min <= d_max:
        raise ValueError(f"diameter range must satisfy 0 < min <= max, got {(d_min, d_max)}")
    if settings.geometry == "cylinder" and settings.r0 < d_max:
        raise ValueError(f"cylinder radius r0 = {settings.r0} is smaller than the largest particle (diameter {d_max})")
    if not settings.height > 0:
        raise ValueError(f"packing height must be positive, got {settings.height}")
    check_pour_step(settings.dt, gravity, d_min)
    if settings.layer_height is not None and not settings.layer_height > 0:
        raise ValueError(f"layer height must be positive (or None: one cloud), got {settings.layer_height}")
    if not settings.freeze_depth >= 0:
        raise ValueError(f"freeze depth must be >= 0, got {settings.freeze_depth}")
    expected = expected_spheres(settings.footprint, settings.height, (d_min, d_max))
    if settings.max_spheres is not None and expected > settings.max_spheres:
        size = (f"channel L0 = {settings.channel_length:g}, W = {settings.channel_width:g}"
                if settings.geometry == "channel" else f"r0 = {settings.r0:g}")
        raise ValueError(f"the packing of {size} to height {settings.height:g} would hold about "
                         f"{expected:,.0f} spheres (diameters {d_min:g}-{d_max:g}), above the bound of "
                         f"{settings.max_spheres:,} (raise it with --max-spheres, or pack.max_spheres in a study)")


def _fingerprint(rng: np.random.Generator, solver: Solver, settings: PackSettings) -> str:
    """What a packing checkpoint must match: the generator's state at the start, the solver and
    every setting of the pour that changes a step (not max_steps, max_spheres nor checkpoint_every:
    a pour stopped at max_steps resumes when given more; nor the seeds, which the generator holds)."""
    stepping = {"r0": settings.r0, "height": settings.height,
                "diameter_range": (settings.diameter_min, settings.diameter_max), "density": settings.density,
                "gravity": settings.gravity, "dt": settings.dt, "rest_energy": settings.rest_energy,
                "mu": settings.mu, "layer_height": settings.layer_height, "freeze_depth": settings.freeze_depth}
    if settings.geometry != "cylinder":   # a cylinder's checkpoints keep their fingerprint
        stepping |= {"geometry": settings.geometry, "channel": (settings.channel_length, settings.channel_width)}
    described = [rng.bit_generator.state, solver.describe(), stepping]
    return hashlib.sha256(json.dumps(described, sort_keys=True, default=str).encode()).hexdigest()


def _pour_cloud(state: ParticleState, fixed: np.ndarray, settings: PackSettings, rng: np.random.Generator):
    """The packing with the next cloud above it: (state, fixed (n,) bool, last), where `last` says
    whether this cloud fills the rest of the height. Pouring in layers, the spheres buried deeper
    than settings.freeze_depth and at rest become fixed first."""
    d_max = settings.diameter_max
    surface = column_height(state)
    missing = settings.height + 2 * d_max - surface
    last = settings.layer_height is None or missing <= settings.layer_height + 2 * d_max
    thickness = missing if last else settings.layer_height
    diameter_range = (settings.diameter_min, d_max)
    n_new = int(np.ceil(cloud_spheres(settings.footprint, thickness, diameter_range)))
    z_bottom = float(np.max(state.position[:, 2] + state.radius, initial=0.0))
    if settings.layer_height is not None:
        fixed = fixed | _buried_at_rest(state, surface - settings.freeze_depth, settings.gravity, settings.rest_energy)
    position, radius = lattice_cloud(settings.footprint, n_new, z_bottom, diameter_range, rng)
    state = _add(state, position, radius)
    fixed = np.concatenate([fixed, np.zeros(len(radius), dtype=bool)])
    log.info("pouring %d spheres (%d in all, %d fixed) from z = %.2f", len(radius), state.n,
             np.count_nonzero(fixed), z_bottom)
    return state, fixed, last


def _buried_at_rest(state: ParticleState, depth_z: float, gravity: float, rest_energy: float) -> np.ndarray:
    """(n,) bool: spheres whose top is below depth_z (length) and whose kinetic energy of
    translation is below rest_energy m g d."""
    return _slow(state, gravity, rest_energy) & (state.position[:, 2] + state.radius < depth_z)


def _slow(state: ParticleState, gravity: float, rest_energy: float) -> np.ndarray:
    """(n,) bool: translational kinetic energy below rest_energy m g d (d the sphere's diameter)."""
    speed2 = np.einsum("ij,ij->i", state.velocity, state.velocity)
    return 0.5 * speed2 / (gravity * 2.0 * state.radius) < rest_energy


class _Pour:
    """What the clouds of one packing share: its settings and step, the solver, the stopwatch over all
    segments, each step's StepDiagnostics (`history`) and the progress callback."""

    def __init__(self, settings: PackSettings, solver: Solver, progress=None, backend: Backend = HOST):
        self.settings, self.solver, self.progress, self.backend = settings, solver, progress, backend
        self.step = StepSettings(dt=settings.dt, gravity=(0.0, 0.0, -settings.gravity),
                                 walls=pour_walls(settings.footprint), law=ContactLaw.uniform(settings.mu, 0.0))
        self.clock, self.history = Stopwatch(), []

    def settle(self, state: ParticleState, fixed: np.ndarray, warm: WarmStart | None, steps: int,
               rest_energy: float, resume: dict | None = None, save=None):
        """Step the spheres not `fixed` ((n,) bool) on the fixed ones until :func:`is_at_rest` with
        rest_energy; `steps` were taken before. warm: forces by pair in the numbering of `state`
        (None: cold). Returns the new state, the forces by pair (numbering of `state`: the last
        step's, and those of pairs of fixed spheres from when they last moved) and the step count.

        resume: {supports, margin} of a cloud resumed from a checkpoint (the fixed spheres it settles
        on, and the detection margin its next step starts from); save: optional callable(state, warm,
        margin, steps, supports), called every settings.checkpoint_every steps with the whole packing,
        and when :data:`~colsim.stages.stopwatch.CHECKPOINT_INTERVAL_S` of wall time passed since the last."""
        moving = np.flatnonzero(~fixed)
        if resume is None:
            below = state.position[moving, 2] - state.radius[moving]
            near = fixed & (state.position[:, 2] + state.radius > float(below.min()) - 2.0 * state.radius.max())
            supports, margin = np.flatnonzero(near), None
        else:
            supports, margin = resume["supports"], resume["margin"]
        walls = replace(self.step.walls, fixed=FixedSpheres(state.position[supports], state.radius[supports]))
        carry = Carry(None if warm is None else warm.for_moving(moving, supports, state.n), margin)
        held = None if warm is None else warm.among(fixed)   # forces between fixed spheres, kept as they are
        max_steps = self.settings.max_steps
        sub, logged = state.subset(moving), time.perf_counter()
        for result in run(sub, replace(self.step, walls=walls), max_steps - steps, self.solver,
                          first_step=steps, carry=carry, backend=self.backend):
            sub, steps = result.state, steps + 1
            logged = self._record(result.diagnostics, sub, steps, logged)
            if is_at_rest(result, self.settings.gravity, rest_energy):
                break
            if save is not None and self.clock.checkpoint_due(steps % self.settings.checkpoint_every == 0):
                forces = WarmStart.from_step(result.contacts, result.solution.forces).in_whole(moving, supports)
                save(_place(state, moving, sub), _joined(held, forces), result.carry.margin, steps, supports)
        else:
            raise RuntimeError(f"packing not at rest after {max_steps} steps (raise max_steps or dt)")
        _check_clear_of_fixed(sub, state.subset(fixed), self.step.overlap_tolerance)
        forces = WarmStart.from_step(result.contacts, result.solution.forces).in_whole(moving, supports)
        return _place(state, moving, sub), _joined(held, forces), steps

    def _record(self, diagnostics, moving: ParticleState, steps: int, logged: float) -> float:
        """Keep a step's diagnostics, report them to the progress callback, and log them every 50
        steps or :data:`LOG_INTERVAL_S` after the last line. logged: the perf_counter time of the
        last line; returns that of the last line now."""
        self.history.append(diagnostics)
        if self.progress is not None:
            self.progress(diagnostics, moving)
        if steps % 50 and time.perf_counter() - logged < LOG_INTERVAL_S:
            return logged
        log.info("pack step %d: %d moving, %d contacts, kinetic energy %.3g, %.2f s solve", steps, moving.n,
                 diagnostics.n_contacts, diagnostics.kinetic_energy + diagnostics.rotational_energy,
                 diagnostics.solve_time)
        return time.perf_counter()


def pour_walls(footprint) -> Walls:
    """The walls a pour fills (besides the floor): the cylinder of radius `footprint`, or a
    :class:`Channel`'s back wall, sidewalls and gate."""
    if isinstance(footprint, Channel):
        return Walls(planes=channel_planes(footprint.length, footprint.width, gate=True))
    return Walls(cylinder_radius=footprint)


def _place(state: ParticleState, moving: np.ndarray, sub: ParticleState) -> ParticleState:
    """`state` with the particles `moving` (indices) replaced by those of `sub`, at sub's time."""
    out = state.copy()
    out.position[moving], out.velocity[moving] = sub.position, sub.velocity
    out.angular_velocity[moving] = sub.angular_velocity
    out.time = sub.time
    return out


def _joined(held: WarmStart | None, forces: WarmStart) -> WarmStart:
    """The forces held between fixed spheres (None: none) with a step's forces."""
    return forces if held is None else held.joined(forces)


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
