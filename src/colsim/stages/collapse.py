"""Stage 3: remove the cylinder and let the column collapse (SPEC section 3).

A channel's column (a :class:`colsim.stages.pour_geometry.Channel`) collapses along +x when its gate
is removed: the back wall and the sidewalls stay, with the settings' wall_mu (or mu) and mu_r.

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
from ..engine.backend import HOST, Backend
from ..engine.solver_contract import Solver
from ..engine.state import ParticleState
from ..engine.stepper import run
from ..engine.warm_start import WarmStart
from ..io.checkpoint import load_checkpoint, save_checkpoint, segment_commits
from .analyse import measure_deposit
from .pour_geometry import Channel
from .settings import CollapseSettings, SMALLEST_SCALED_STEP  # noqa: F401 (the stage's settings, here too)
from .stopwatch import Stopwatch

log = logging.getLogger(__name__)



@dataclass
class CollapseRun:
    """frames: list of (step, ParticleState); diagnostics: list of StepDiagnostics (one per step);
    at_rest: whether the deposit was found at rest (None: not checked, no max_duration);
    wall_time, cpu_time: seconds over all segments (CPU: all threads; NaN when a segment's is unknown);
    commits: the git commits of the code of every segment, the first first."""

    initial: ParticleState
    frames: list
    diagnostics: list
    wall_time: float
    resumed_from: int = 0
    at_rest: bool | None = None
    cpu_time: float = float("nan")
    commits: tuple = ()


#: settings that change when a run stops or checkpoints, never a step: a checkpoint resumes across them
NOT_IN_FINGERPRINT = ("checkpoint_every", "max_duration")


def deposit_at_rest(times, heights, fronts, window: float, tolerance: float) -> bool:
    """True when the history (frame times, h_inf, r_inf; lengths in any one unit) covers `window`
    back from its last frame and neither quantity moved more than `tolerance` within it (only the
    frames :func:`in_rest_window` are read)."""
    times, heights, fronts = (np.asarray(v, dtype=float) for v in (times, heights, fronts))
    if not covers_rest_window(times, window):
        return False
    recent = in_rest_window(times, window)
    return bool(np.ptp(heights[recent]) < tolerance and np.ptp(fronts[recent]) < tolerance)


def covers_rest_window(times, window: float) -> bool:
    """Whether frames at `times` reach `window` back from the last one."""
    return len(times) > 0 and times[-1] - times[0] >= window * (1 - 1e-9)


def in_rest_window(times, window: float) -> np.ndarray:
    """(frames,) bool: the frames within `window` back from the last one (times in the window's unit)."""
    times = np.asarray(times, dtype=float)
    return times >= times[-1] - window * (1 + 1e-9)


class DepositHistory:
    """h_inf and r_inf of a run's frames, measured when the rest test reads them and kept: only the
    frames inside the rest window once the kinetic energy is low, not every frame (the measure finds
    the contact graph's main mass, whose cost grows with the spheres: over every frame of a large
    collapse it would add up)."""

    def __init__(self, geometry: str = "cylinder"):
        self._measured: dict[int, tuple[float, float]] = {}
        self._geometry = geometry   # r_inf from the axis (cylinder) or the back wall (channel)

    def at_rest(self, frames, time_scale: float, window: float, tolerance: float) -> bool:
        """:func:`deposit_at_rest` of `frames` ([(step, state)]; times over `time_scale`)."""
        times = np.array([state.time for _, state in frames]) / time_scale
        if not covers_rest_window(times, window):   # nothing to measure yet
            return False
        heights, fronts = np.full(len(frames), np.nan), np.full(len(frames), np.nan)
        for n in np.flatnonzero(in_rest_window(times, window)):
            heights[n], fronts[n] = self._deposit(*frames[n])
        return deposit_at_rest(times, heights, fronts, window, tolerance)

    def _deposit(self, step: int, state: ParticleState) -> tuple[float, float]:
        if step not in self._measured:
            deposit = measure_deposit(state, geometry=self._geometry)
            self._measured[step] = deposit.h_inf, deposit.r_inf
        return self._measured[step]


def _fingerprint(column: ParticleState, settings: CollapseSettings, h0: float, solver: Solver,
                 warm_start: WarmStart | None, channel: Channel | None = None) -> str:
    digest = hashlib.sha256()
    arrays = [column.position, column.velocity, column.angular_velocity, column.radius]
    if warm_start is not None:
        arrays += [warm_start.i, warm_start.j, warm_start.family, warm_start.force, warm_start.rolling]
    for array in arrays:
        digest.update(np.ascontiguousarray(array).tobytes())
    described = {k: v for k, v in asdict(settings).items()
                 if k not in NOT_IN_FINGERPRINT and not (k == "wall_mu" and v is None)}
    if channel is not None:   # a cylinder's checkpoints keep their fingerprint
        described["channel"] = asdict(channel)
    digest.update(json.dumps([described, h0, solver.describe()], sort_keys=True, default=str).encode())
    return digest.hexdigest()


def collapse(column: ParticleState, h0: float, settings: CollapseSettings, solver: Solver,
             warm_start: WarmStart | None = None, checkpoint: str | Path | None = None, progress=None,
             stop_after: int | None = None, backend: Backend = HOST,
             channel: Channel | None = None) -> CollapseRun:
    """Release `column` (height h0) and integrate it with `solver`; see the module docstring.

    channel: the column's channel (its gate removed at release), or None for a cylinder's column.
    warm_start: the column's contact forces before release (from its packing), for the first step.
    progress: optional callable(diagnostics) after each step.
    stop_after: stop (as if killed) after this many steps in this call, for tests of resuming.
    backend: where the steps run (:mod:`colsim.engine.backend`; the solver's must be the same).
    """
    if channel is None and settings.wall_mu is not None:
        raise ValueError("wall_mu is the friction of a channel's walls; this column is a cylinder's, whose walls "
                         "are gone at release (leave wall_mu out)")
    step_settings = settings.step_settings(h0, channel)
    fingerprint = _fingerprint(column, settings, h0, solver, warm_start, channel)
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
    history = DepositHistory("cylinder" if channel is None else "channel")
    at_rest = None
    last = settings.max_steps
    for result in run(state, step_settings, last - resumed_from, solver, resumed_from, carry, backend):
        k, state = result.diagnostics.step, result.state
        diagnostics.append(result.diagnostics)
        is_frame = k % settings.frame_every == 0 or k in (settings.n_steps, last)
        if is_frame:
            frames.append((k, state.copy()))
        if progress is not None:
            progress(result.diagnostics)
        if rest_check and is_frame:
            at_rest = k >= settings.n_steps and _at_rest(history, frames, time_scale, diagnostics, column, settings)
            if at_rest:
                break
        if checkpoint is not None and k < last and clock.checkpoint_due(k % settings.checkpoint_every == 0):
            save_checkpoint(checkpoint, fingerprint, state, frames, diagnostics, result.carry,
                            clock.wall(), clock.cpu(), earlier)
        if stop_after is not None and k - resumed_from >= stop_after:
            break
    return CollapseRun(column, frames, diagnostics, clock.wall(), resumed_from, at_rest, clock.cpu(),
                       tuple(segment_commits(earlier)))


def _at_rest(history: DepositHistory, frames, time_scale, diagnostics, column, settings) -> bool:
    """The module docstring's rest test: the energy first (no deposit measured while it is high)."""
    energy = np.array([d.kinetic_energy + d.rotational_energy for d in diagnostics])
    if energy[-1] > settings.rest_energy * energy.max():
        return False
    return history.at_rest(frames, time_scale, settings.rest_window,
                           settings.rest_tolerance * 2.0 * float(column.radius.mean()))
