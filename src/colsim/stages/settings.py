"""Every setting of every stage, declared once: its default, unit and help live here and nowhere else.

One dataclass per stage (:class:`PackSettings`, :class:`TrimSettings`, :class:`CollapseSettings`,
:class:`AnalysisSettings`) and one for the cone-program back-end that the pour and the collapse share
(:class:`SolverSettings`). Each field is made by :func:`setting`, whose metadata say how it is
written on the command line and in a settings file (`name`: `--steps`, ``steps:``), what values it
takes (`kind`) and what it means (`unit`, `help`). The CLI's flags are generated from these
(:mod:`colsim.cli.flags`), a settings file (the workflow's settings.yaml) is read into them, and a
test checks the config schema's and config.yaml's defaults against them.

Light on purpose: the CLI builds its parser from this module before it loads the engine.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, fields

import numpy as np

from ..engine.state import FRICTION_LAWS, ROLLING_LEVERS, ContactLaw, FrictionLaw, StepSettings, Walls, channel_planes
from ..solvers import defaults
from .pour_geometry import GEOMETRIES, LATTICE_FACTOR, Channel

#: the kinds of value a setting takes (colsim.cli.flags parses each)
KINDS = ("positive", "non_negative", "integer", "positive_int", "choice")

LENGTH = "length"   # the particles' length unit (the paper: diameters 0.25-0.5)
#: where APGD's iterations may run
DEVICES = ("cpu", "cuda", "auto")


def setting(default, help: str, *, unit: str = "1", kind: str = "positive", name: str | None = None,
            choices: tuple | None = None, optional: bool = False, many: bool = False, flag: bool = True,
            recorded_when_set: bool = False):
    """A settings dataclass field: `default` (None with `optional`: a value meaning 'not set'),
    `help` (one phrase, the CLI's help), `unit` (UDUNITS; '1': dimensionless), `kind` (KINDS),
    `name` (on the command line and in settings files; the field's own name if None), `choices`
    (kind 'choice'), `many` (a list of values), `flag` (False: not a CLI flag; the stage sets it),
    `recorded_when_set` (a file and a key hold it only at a value other than its default: a setting
    added later, whose default keeps the files and keys made before it, :func:`by_name`)."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind!r} of a setting (one of {', '.join(KINDS)})")
    metadata = {"help": help, "unit": unit, "kind": kind, "name": name, "choices": choices,
                "optional": optional, "many": many, "flag": flag, "recorded_when_set": recorded_when_set}
    return field(default=tuple(default) if many else default, metadata=metadata)


def settings_key(settings) -> str:
    """Ten hex digits of the SHA-256 of `settings` (a packing's, a run's or the analyses' settings, as
    their settings file holds them) as canonical JSON: the key that names their folder. The workflow
    names folders by it and a stage given the key (--settings-key) checks its settings file by it."""
    text = json.dumps(settings, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:10]


def external_name(item) -> str:
    """A field's name on the command line (dashes for underscores) and in settings files."""
    return item.metadata.get("name") or item.name


def declared(cls) -> list:
    """The fields of a settings dataclass that a user sets (flag or settings file)."""
    return [item for item in fields(cls) if item.metadata.get("flag", True)]


def by_name(settings) -> dict:
    """{external name: value} of the declared fields of a settings object (lists for tuples): what a
    file records of the settings it was made with (a `recorded_when_set` field only when not at its
    default: :func:`unrecorded`)."""
    return {external_name(item): (list(value) if isinstance(value := getattr(settings, item.name), tuple)
                                  else value)
            for item in declared(type(settings)) if not unrecorded(item, getattr(settings, item.name))}


def unrecorded(item, value) -> bool:
    """Whether a field at `value` stays out of files and keys: a `recorded_when_set` field at its
    default (the cylinder's geometry, a channel's settings left unset)."""
    return bool(item.metadata.get("recorded_when_set")) and value == item.default


@dataclass(frozen=True)
class SolverSettings:
    """The cone-program back-end of a pour or a collapse (docs/solvers.md)."""

    solver: str = setting(defaults.DEFAULT_SOLVER, "cone-program back-end (auto: APGD for every step, warm or "
                          f"cold, up to dt/sqrt(h0/g) = {defaults.AUTO_APGD_BELOW:g}, Clarabel above and where "
                          "APGD reaches its cap; docs/solvers.md)", kind="choice", choices=defaults.SOLVERS)
    solver_tolerance: float | None = setting(None, "solver tolerance (none: the back-end's own; for auto, "
                                             "APGD's)", optional=True)
    solver_length_floor: float | None = setting(
        None, "APGD's stopping rule: measure its residuals against the step's free flight or this many mean "
        f"diameters, whichever is larger (none: under auto {defaults.AUTO_APGD_LENGTH_FLOOR:g}, apgd 0)",
        kind="non_negative", optional=True)
    solver_overlap_tolerance: float | None = setting(
        None, "APGD's stopping rule: a step's contacts count as feasible once no end-of-step gap violates "
        "its cone by more than this many mean diameters (none: a collapse under auto "
        f"{defaults.AUTO_APGD_OVERLAP_TOLERANCE:g}, otherwise 0: the relative tolerance alone)",
        kind="non_negative", optional=True)
    threads: int = setting(1, "threads of APGD's loops over contacts and bodies (results differ between "
                           "counts by rounding only, far below the tolerance)", kind="positive_int")
    device: str = setting("cpu", "where APGD's iterations, the swept pairs, the warm start's matching and the "
                          "overlap check run: cpu (numba's threads), cuda (one GPU, numba.cuda; the rest of a "
                          "step stays on the CPU for now) or auto (cuda for "
                          f"{defaults.GPU_FROM_SPHERES:,} spheres or more where a GPU is visible, else cpu); "
                          "results differ between devices by rounding only", kind="choice", choices=DEVICES)
    gpu_storage: str = setting(defaults.DEFAULT_GPU_STORAGE, "how APGD's iteration stores its arrays on a GPU: "
                               "float64, or float32 (the iterate, T x, the wrenches and the contacts' frames; the "
                               "arithmetic, the stopping test and the step's forces stay float64; about a third fewer "
                               "bytes an iteration); the CPU stores float64 either way", kind="choice",
                               choices=defaults.GPU_STORAGES)


#: the pour's step over sqrt(d_min / g), the time to fall about a diameter, must lie in this range:
#: the default (dt 0.02, d_min 0.25, g 9.81) is 0.125; far above, spheres cross each other within a
#: step, far below, the pour takes millions of steps (gravity 1e-300 had the spheres fly off while a
#: study reported a deposit)
POUR_STEP_RANGE = (1e-4, 2.0)


@dataclass(frozen=True)
class PackSettings:
    """The pour: a cylinder of radius r0, or a channel's box of length channel_length and width
    channel_width behind its gate, filled by free fall (mu_r = 0) until the settled packing is taller
    than `height` (SPEC section 3)."""

    height: float | None = setting(None, "the settled packing must be taller than this; the tallest "
                                   "h0 = a r0 (a channel: a L0) needed (required)", unit=LENGTH, optional=True)
    r0: float = setting(3.0, "cylinder radius (the default study's)", unit=LENGTH)
    geometry: str = setting("cylinder", "what the pour fills: cylinder (radius r0) or channel (the box 0 < x < "
                            "channel_length, |y| < channel_width/2 of a channel along +x, behind a gate that the "
                            "collapse removes)", kind="choice", choices=GEOMETRIES, recorded_when_set=True)
    channel_length: float | None = setting(None, "a channel's box length L0 along its axis, r0's role: h0 = a L0 "
                                           "(geometry channel)", unit=LENGTH, optional=True, recorded_when_set=True)
    channel_width: float | None = setting(None, "a channel's width W between its sidewalls, at least 1.04 largest "
                                          "diameters (geometry channel)", unit=LENGTH, optional=True,
                                          recorded_when_set=True)
    seed: int = setting(0, "run seed", kind="integer")
    root_seed: int = setting(2024, "study seed (the default study's); the stream is numpy "
                             "default_rng([seed, root_seed])", kind="integer")
    diameter_min: float = setting(0.25, "smallest diameter", unit=LENGTH)
    diameter_max: float = setting(0.5, "largest diameter", unit=LENGTH)
    density: float = setting(1.0, "particle density", unit="mass/length^3")
    gravity: float = setting(9.81, "gravity", unit="length/time^2")
    dt: float = setting(0.02, "time step of the filling", unit="time")
    rest_energy: float = setting(1e-3, "at rest when 95 % of the particles have kinetic energy below this "
                                 "times m g d and 99 % carry a contact force")
    max_steps: int = setting(5000, "give up after this many steps", kind="positive_int")
    #: 3x the r0 = 8, a = 5 column's 160,000 spheres, about 4 GB of packing; r0 = 20 would pour 2.4
    #: million and run out of memory on a 24 GB machine
    max_spheres: int = setting(500_000, "refuse, before any work, a packing expected to hold more spheres "
                               "than this (about 4 GB at the default)", kind="positive_int")
    mu: float = setting(0.0, "sliding friction between spheres and with the floor while filling; the "
                        "paper's is 0, a small value gives a looser packing", kind="non_negative")
    #: one cloud by default: the layers' deposits at a = 5 are not yet the pour's
    #: (docs/validation/packing-layers.md)
    layer_height: float | None = setting(None, "fill in clouds that each add about this settled thickness "
                                         "(docs/validation/packing-layers.md measures 2.5); none: one cloud "
                                         "for the whole height", unit=LENGTH, optional=True)
    freeze_depth: float = setting(3.5, "while filling in layers, spheres at rest more than this below the "
                                  "settled surface are fixed and leave the program", unit=LENGTH,
                                  kind="non_negative")
    #: a killed job loses at most this many steps of work, or 10 minutes of it
    #: (stopwatch.CHECKPOINT_INTERVAL_S), whichever is less
    checkpoint_every: int = setting(25, "checkpoint every k steps", kind="positive_int")

    def __post_init__(self):
        if self.height is None:
            raise ValueError("a packing needs its height (--height, or height: in the settings file)")
        if self.diameter_min > self.diameter_max:
            raise ValueError(f"diameter_min {self.diameter_min} exceeds diameter_max {self.diameter_max}")
        check_geometry(self.geometry, self.channel_length, self.channel_width, self.diameter_max)

    @property
    def footprint(self):
        """What the pour fills, seen from above: the cylinder's radius r0, or the channel's :class:`Channel`."""
        return self.r0 if self.geometry == "cylinder" else Channel(self.channel_length, self.channel_width)

    @property
    def length_scale(self) -> float:
        """r0, or a channel's L0: h0 = a times it (length)."""
        return self.r0 if self.geometry == "cylinder" else self.channel_length


def check_geometry(geometry: str, length, width, diameter_max: float) -> None:
    """ValueError (one line) naming the first channel setting that `geometry` cannot take: a channel
    needs a length L0 > 0, and a length and a width that hold the pour's lattice cell (LATTICE_FACTOR
    times the largest diameter: a little more than one diameter); a cylinder takes neither."""
    if geometry not in GEOMETRIES:
        raise ValueError(f"geometry must be one of {', '.join(GEOMETRIES)}, got {geometry!r}")
    given = [name for name, value in (("channel_length", length), ("channel_width", width)) if value is not None]
    if geometry == "cylinder":
        if given:
            raise ValueError(f"{' and '.join(given)} set a channel, but geometry is cylinder (set geometry: "
                             "channel, or leave them out)")
        return
    if length is None or width is None:
        raise ValueError("geometry channel needs channel_length (L0) and channel_width (W)")
    if not (length > 0 and np.isfinite(length)):
        raise ValueError(f"channel_length L0 must be positive, got {length}")
    cell = LATTICE_FACTOR * diameter_max   # the pour's lattice cell: the box must hold one
    for name, value in (("channel_width W", width), ("channel_length L0", length)):
        if not (value >= cell and np.isfinite(value)):
            raise ValueError(f"{name} = {value} is below {LATTICE_FACTOR:g} times the largest diameter "
                             f"{diameter_max}: the pour's lattice cell ({cell:g}) does not fit in the box")


@dataclass(frozen=True)
class TrimSettings:
    """The cut of a packing at h0 = a r0."""

    aspect_ratio: float | None = setting(None, "a = h0 / r0 (required)", optional=True)

    def __post_init__(self):
        if self.aspect_ratio is None:
            raise ValueError("a trim needs its aspect ratio (--aspect-ratio, or aspect_ratio: in the settings file)")


#: a channel's collapse keeps the overlaps of a step's start up to this fraction of the smallest
#: diameter, half the stepper's overlap tolerance (StepSettings.overlap_kept): between the sidewalls a
#: chain of grains from wall to wall may have no motion but dilating ones under the walls' friction,
#: and asking its overlap back left the first step of a slot 1.6 diameters wide with no solution
CHANNEL_OVERLAP_KEPT = 0.005
#: the smallest step dt/sqrt(h0/g) a collapse takes: 4e-5 of the default step, far below any use;
#: at 1e-300 the step's masses over dt^2 overflow
SMALLEST_SCALED_STEP = 1e-9


def scaled_step(duration, n_steps):
    """The collapse's step dt / sqrt(h0/g): its end time t / sqrt(h0/g) over its equal steps (numbers
    or arrays)."""
    return duration / n_steps


@dataclass
class CollapseSettings:
    """The collapse's physics and numerics (SPEC section 3). Times are dimensionless (t / sqrt(h0/g)).
    The defaults: dt/sqrt(h0/g) = 0.004, where the results stop depending on the step
    (docs/validation/time-step.md); the paper's is 100 steps."""

    mu: float = setting(0.577, "sliding friction coefficient", kind="non_negative")
    mu_r: float = setting(0.12, "rolling resistance coefficient (the default study sweeps 0, 0.06, 0.12 "
                          "and 0.2)", kind="non_negative")
    floor_mu: float | None = setting(None, "the floor's mu (none: the same as mu)", kind="non_negative",
                                     optional=True)
    floor_mu_r: float | None = setting(None, "the floor's mu_r (none: the same as mu_r)", kind="non_negative",
                                       optional=True)
    wall_mu: float | None = setting(None, "a channel's sidewalls' and back wall's sliding friction (glass is "
                                    "smoother than the floor; none: the same as mu); their rolling resistance is "
                                    "mu_r", kind="non_negative", optional=True, recorded_when_set=True)
    friction_law: str = setting("associated", "associated (the paper's: a sliding contact opens by mu |du_t| "
                                "a step) or coulomb (non-associated: it does not; a fixed point of cone "
                                "programs)", kind="choice", choices=FRICTION_LAWS)
    friction_tolerance: float = setting(FrictionLaw().tolerance, "coulomb: stop the fixed point when its gap "
                                        "correction changes by at most this many mean diameters, root mean "
                                        "square over the contacts")
    rolling_lever: str = setting("paper", "lever L of the rolling moment L r between two spheres: paper (its "
                                 "Eqs. 6 and 9: 2 R_i R_j/(R_i + R_j), each radius when equal) or effective "
                                 "(R_eff = R_i R_j/(R_i + R_j), the common DEM convention, half of it); R_i "
                                 "at the floor either way", kind="choice", choices=ROLLING_LEVERS)
    duration: float = setting(4.0, "end time t / sqrt(h0/g)")
    n_steps: int = setting(1000, "number of equal steps (the paper's is 100)", kind="positive_int",
                           name="steps")
    max_duration: float | None = setting(None, "go on past duration at the same dt until the deposit is at "
                                         "rest, up to this t / sqrt(h0/g) (none: stop at duration; the "
                                         "default study's runs go on to 12)", optional=True)
    rest_window: float = setting(1.0, "at rest: h_inf and r_inf steady over this t / sqrt(h0/g)")
    rest_tolerance: float = setting(0.1, "at rest: h_inf and r_inf moved less than this many mean diameters")
    rest_energy: float = setting(1e-2, "at rest: kinetic energy below this times its peak")
    frame_every: int = setting(25, "keep a frame every k steps", kind="positive_int")
    checkpoint_every: int = setting(100, "checkpoint every k steps (and after 10 minutes without one)",
                                    kind="positive_int")
    gravity: float = setting(9.81, "gravity (the column file's)", unit="length/time^2", flag=False)

    def __post_init__(self):
        for name in ("mu", "mu_r", "wall_mu"):
            if getattr(self, name) is not None and not getattr(self, name) >= 0:
                raise ValueError(f"friction coefficient {name} must be >= 0, got {getattr(self, name)}")
        if self.duration <= 0 or self.n_steps < 1 or self.frame_every < 1:
            raise ValueError(f"need duration > 0, n_steps >= 1, frame_every >= 1; got "
                             f"{self.duration}, {self.n_steps}, {self.frame_every}")
        if self.scaled_step < SMALLEST_SCALED_STEP:
            raise ValueError(f"the step dt/sqrt(h0/g) = {self.scaled_step:.3g} (duration {self.duration:g}"
                             f" over {self.n_steps} steps) is below {SMALLEST_SCALED_STEP:g}, where the step's"
                             " arithmetic loses its digits")
        if self.gravity <= 0:
            raise ValueError(f"gravity must be positive, got {self.gravity}")
        if self.max_duration is not None and self.max_duration < self.duration:
            raise ValueError(f"max_duration {self.max_duration} is below duration {self.duration}")
        self.friction()   # checks the law's name and tolerance
        self.law()        # checks the rolling lever
        if self.rest_window <= 0 or self.rest_tolerance <= 0 or self.rest_energy <= 0:
            raise ValueError(f"need rest_window, rest_tolerance and rest_energy > 0; got "
                             f"{self.rest_window}, {self.rest_tolerance}, {self.rest_energy}")

    @property
    def scaled_step(self) -> float:
        """The step dt / sqrt(h0/g)."""
        return scaled_step(self.duration, self.n_steps)

    def friction(self) -> FrictionLaw:
        return FrictionLaw(self.friction_law, self.friction_tolerance)

    def law(self, channel: bool = False) -> ContactLaw:
        """The contacts' coefficients: (particle, floor, wall). No wall is left after a cylinder's
        release; a channel's sidewalls and back wall take wall_mu (or mu) and mu_r."""
        floor_mu = self.mu if self.floor_mu is None else self.floor_mu
        floor_mu_r = self.mu_r if self.floor_mu_r is None else self.floor_mu_r
        wall_mu, wall_mu_r = (self.mu if self.wall_mu is None else self.wall_mu, self.mu_r) if channel else (0.0, 0.0)
        return ContactLaw(mu=(self.mu, floor_mu, wall_mu), mu_r=(self.mu_r, floor_mu_r, wall_mu_r),
                          rolling_lever=self.rolling_lever)

    def time_step(self, h0: float) -> float:
        return self.scaled_step * np.sqrt(h0 / self.gravity)

    def step_settings(self, h0: float, channel: Channel | None = None) -> StepSettings:
        """The engine's settings for one step of the collapse of a column of height h0: the
        floor and no cylinder (or a channel's back wall and sidewalls, its gate removed, and the
        overlaps it keeps: CHANNEL_OVERLAP_KEPT), gravity, the contact and friction laws, dt from
        `time_step`."""
        if channel is None:
            walls, kept = Walls(floor=True, cylinder_radius=None), 0.0
        else:
            walls = Walls(floor=True, planes=channel_planes(channel.length, channel.width, gate=False))
            kept = CHANNEL_OVERLAP_KEPT
        return StepSettings(dt=self.time_step(h0), gravity=(0.0, 0.0, -self.gravity), walls=walls,
                            law=self.law(channel is not None), friction=self.friction(), overlap_kept=kept)

    def scaled_time(self, steps: int) -> float:
        """t / sqrt(h0/g) after `steps` steps."""
        return steps * self.scaled_step

    @property
    def max_steps(self) -> int:
        """Steps to max_duration (n_steps without one)."""
        if self.max_duration is None:
            return self.n_steps
        return int(round(self.n_steps * self.max_duration / self.duration))


@dataclass(frozen=True)
class AnalysisSettings:
    """What `colsim analyse` measures: contact tolerances as fractions of the smallest diameter (the
    study's and the checks'), mass shares (0-1], radial bin of the profile (None: d_max)."""

    contact_tolerance: float = setting(0.01, "particles touch when their gap is at most this fraction of "
                                       "the smallest diameter", kind="non_negative")
    check_tolerances: tuple = setting((0.1, 0.5, 1.0), "also measure the run-out with these contact "
                                      "tolerances", kind="non_negative", many=True)
    mass_shares: tuple = setting((0.9, 0.95, 0.99), "also report the radius holding these shares of the "
                                 "mass", many=True)
    bin_width: float | None = setting(None, "radial bin of the deposit profile (none: the largest diameter)",
                                      unit=LENGTH, optional=True)


#: each stage's settings, by its subcommand
STAGES = {"pack": PackSettings, "trim": TrimSettings, "collapse": CollapseSettings, "analyse": AnalysisSettings}
#: the stages that solve cone programs (and so take SolverSettings too)
SOLVING_STAGES = ("pack", "collapse")
