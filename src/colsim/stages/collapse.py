"""Stage 3: remove the cylinder and let the column collapse (SPEC section 3).

The column of height h0 is released at t = 0 with sliding coefficient mu and rolling coefficient
mu_r, and integrated to t / sqrt(h0/g) = duration in n_steps equal steps (the paper: 4 and 100).
The friction law is the paper's associated one unless friction_law = 'coulomb' (:mod:`colsim.engine.friction`).
With max_duration set, it goes on at the same dt until the deposit is at rest or t / sqrt(h0/g)
reaches max_duration, whichever comes first. At rest: the final height and run-out (measured as in
:mod:`colsim.stages.analyse`) moved less than rest_tolerance mean diameters over the last rest_window,
and the kinetic energy (translational and rotational) is below rest_energy times its peak. The
energy test is needed: grains at the edge join the main mass in jumps, a time unit or more apart.
Frames (state every `frame_every` steps, and the first and last) and per-step diagnostics are kept.
A checkpoint is written every `checkpoint_every` steps (atomically), and after 10 minutes of wall
time without one (:data:`colsim.stages.stopwatch.CHECKPOINT_INTERVAL_S`); a run started again with
the same inputs resumes from it and ends with the same result as an uninterrupted run.
"""
from __future__ import annotations

import hashlib
import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..engine.records import Carry
from ..engine.solver_contract import Solver
from ..engine.state import ContactLaw, FrictionLaw, ParticleState, StepSettings, Walls
from ..engine.stepper import run
from ..engine.warm_start import WarmStart
from ..io.checkpoint import load_checkpoint, save_checkpoint, sittings_commits
from .analyse import measure_deposit
from .collapse_defaults import (CHECKPOINT_EVERY, DURATION, FRAME_EVERY, REST_ENERGY, REST_TOLERANCE,
                                REST_WINDOW, STEPS)
from .stopwatch import Stopwatch

log = logging.getLogger(__name__)



@dataclass
class CollapseSettings:
    """The collapse's physics and numerics. Times are dimensionless (t / sqrt(h0/g))."""

    mu: float = 0.577
    mu_r: float = 0.12
    floor_mu: float | None = None       # None: same as mu
    floor_mu_r: float | None = None     # None: same as mu_r
    duration: float = DURATION
    n_steps: int = STEPS
    frame_every: int = FRAME_EVERY
    gravity: float = 9.81
    checkpoint_every: int = CHECKPOINT_EVERY
    max_duration: float | None = None   # None: stop at `duration` (the paper)
    rest_window: float = REST_WINDOW     # t / sqrt(h0/g)
    rest_tolerance: float = REST_TOLERANCE   # mean diameters
    rest_energy: float = REST_ENERGY     # of the peak kinetic energy
    friction_law: str = "associated"     # or "coulomb" (colsim.engine.friction)
    friction_tolerance: float = FrictionLaw().tolerance     # coulomb's fixed point, mean diameters
    rolling_lever: str = "paper"         # or "effective" (R_eff; colsim.engine.state.rolling_lever)

    def __post_init__(self):
        for name in ("mu", "mu_r"):
            if getattr(self, name) < 0:
                raise ValueError(f"friction coefficient {name} must be >= 0, got {getattr(self, name)}")
        if self.duration <= 0 or self.n_steps < 1 or self.frame_every < 1:
            raise ValueError(f"need duration > 0, n_steps >= 1, frame_every >= 1; got "
                             f"{self.duration}, {self.n_steps}, {self.frame_every}")
        if self.duration / self.n_steps < SMALLEST_SCALED_STEP:
            raise ValueError(f"the step dt/sqrt(h0/g) = {self.duration / self.n_steps:.3g} (duration {self.duration:g}"
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

    def friction(self) -> FrictionLaw:
        return FrictionLaw(self.friction_law, self.friction_tolerance)

    def law(self) -> ContactLaw:
        floor_mu = self.mu if self.floor_mu is None else self.floor_mu
        floor_mu_r = self.mu_r if self.floor_mu_r is None else self.floor_mu_r
        return ContactLaw(mu=(self.mu, floor_mu, 0.0), mu_r=(self.mu_r, floor_mu_r, 0.0),
                          rolling_lever=self.rolling_lever)

    def time_step(self, h0: float) -> float:
        return self.duration / self.n_steps * np.sqrt(h0 / self.gravity)

    def step_settings(self, h0: float) -> StepSettings:
        """The engine's settings for one step of the collapse of a column of height h0: the
        floor and no cylinder, gravity, the contact and friction laws, dt from `time_step`."""
        return StepSettings(dt=self.time_step(h0), gravity=(0.0, 0.0, -self.gravity),
                            walls=Walls(floor=True, cylinder_radius=None), law=self.law(),
                            friction=self.friction())

    def scaled_time(self, steps: int) -> float:
        """t / sqrt(h0/g) after `steps` steps."""
        return steps * self.duration / self.n_steps

    @property
    def max_steps(self) -> int:
        """Steps to max_duration (n_steps without one)."""
        if self.max_duration is None:
            return self.n_steps
        return int(round(self.n_steps * self.max_duration / self.duration))


@dataclass
class CollapseRun:
    """frames: list of (step, ParticleState); diagnostics: list of StepDiagnostics (one per step);
    at_rest: whether the deposit was found at rest (None: not checked, no max_duration);
    wall_time, cpu_time: seconds over all sittings (CPU: all threads; NaN when a sitting's is unknown);
    commits: the git commits of the code of every sitting, the first first."""

    initial: ParticleState
    frames: list
    diagnostics: list
    wall_time: float
    resumed_from: int = 0
    at_rest: bool | None = None
    cpu_time: float = float("nan")
    commits: tuple = ()


#: the smallest step dt/sqrt(h0/g) a collapse takes: 4e-5 of the default step, far below any use;
#: at 1e-300 the step's masses over dt^2 overflow
SMALLEST_SCALED_STEP = 1e-9

#: settings that change when a run stops or checkpoints, never a step: a checkpoint resumes across them
NOT_IN_FINGERPRINT = ("checkpoint_every", "max_duration")


def deposit_at_rest(times, heights, fronts, window: float, tolerance: float) -> bool:
    """True when the history (frame times, h_inf, r_inf; lengths in any one unit) covers `window`
    back from its last frame and neither quantity moved more than `tolerance` within it."""
    times, heights, fronts = (np.asarray(v, dtype=float) for v in (times, heights, fronts))
    if len(times) == 0 or times[-1] - times[0] < window * (1 - 1e-9):
        return False
    recent = times >= times[-1] - window * (1 + 1e-9)
    return bool(np.ptp(heights[recent]) < tolerance and np.ptp(fronts[recent]) < tolerance)


def _deposit(state: ParticleState, time_scale: float) -> tuple[float, float, float]:
    """(t / sqrt(h0/g), h_inf, r_inf) of a frame."""
    deposit = measure_deposit(state)
    return state.time / time_scale, deposit.h_inf, deposit.r_inf


def _fingerprint(column: ParticleState, settings: CollapseSettings, h0: float, solver: Solver,
                 warm_start: WarmStart | None) -> str:
    digest = hashlib.sha256()
    arrays = [column.position, column.velocity, column.angular_velocity, column.radius]
    if warm_start is not None:
        arrays += [warm_start.i, warm_start.j, warm_start.family, warm_start.force, warm_start.rolling]
    for array in arrays:
        digest.update(np.ascontiguousarray(array).tobytes())
    described = {k: v for k, v in asdict(settings).items() if k not in NOT_IN_FINGERPRINT}
    digest.update(json.dumps([described, h0, solver.describe()], sort_keys=True, default=str).encode())
    return digest.hexdigest()


def collapse(column: ParticleState, h0: float, settings: CollapseSettings, solver: Solver,
             warm_start: WarmStart | None = None, checkpoint: str | Path | None = None, progress=None,
             stop_after: int | None = None) -> CollapseRun:
    """Release `column` (height h0) and integrate it with `solver`; see the module docstring.

    warm_start: the column's contact forces before release (from its packing), for the first step.
    progress: optional callable(diagnostics) after each step.
    stop_after: stop (as if killed) after this many steps in this call, for tests of resuming.
    """
    step_settings = settings.step_settings(h0)
    fingerprint = _fingerprint(column, settings, h0, solver, warm_start)
    saved = load_checkpoint(checkpoint, fingerprint)
    if saved:
        state, frames, diagnostics, carry = (saved[k] for k in ("state", "frames", "diagnostics", "carry"))
        clock, earlier = Stopwatch(saved["elapsed"], saved["cpu"]), saved["commits"]
        log.info("resuming from the checkpoint at step %d", len(diagnostics))
    else:
        state, frames, diagnostics, clock, earlier = column.copy(), [(0, column.copy())], [], Stopwatch(), []
        carry = Carry(warm_start if solver.uses_warm_start else None)
    resumed_from = len(diagnostics)
    rest_check = settings.max_duration is not None
    time_scale = np.sqrt(h0 / settings.gravity)
    history = [_deposit(s, time_scale) for _, s in frames] if rest_check else []
    at_rest = None
    last = settings.max_steps
    for result in run(state, step_settings, last - resumed_from, solver, resumed_from, carry):
        k, state = result.diagnostics.step, result.state
        diagnostics.append(result.diagnostics)
        is_frame = k % settings.frame_every == 0 or k in (settings.n_steps, last)
        if is_frame:
            frames.append((k, state.copy()))
        if progress is not None:
            progress(result.diagnostics)
        if rest_check and is_frame:
            history.append(_deposit(state, time_scale))
            at_rest = k >= settings.n_steps and _at_rest(history, diagnostics, column, settings)
            if at_rest:
                break
        if checkpoint is not None and k < last and clock.checkpoint_due(k % settings.checkpoint_every == 0):
            save_checkpoint(checkpoint, fingerprint, state, frames, diagnostics, result.carry,
                            clock.wall(), clock.cpu(), earlier)
        if stop_after is not None and k - resumed_from >= stop_after:
            break
    return CollapseRun(column, frames, diagnostics, clock.wall(), resumed_from, at_rest, clock.cpu(),
                       tuple(sittings_commits(earlier)))


def _at_rest(history, diagnostics, column, settings) -> bool:
    energy = np.array([d.kinetic_energy + d.rotational_energy for d in diagnostics])
    if energy[-1] > settings.rest_energy * energy.max():
        return False
    times, heights, fronts = np.array(history).T
    return deposit_at_rest(times, heights, fronts, settings.rest_window,
                           settings.rest_tolerance * 2.0 * float(column.radius.mean()))
