"""Time stepping: detect, assemble, solve, update (x += dx, v = dx/dt, w = dth/dt), check.

An overlap present at the start of a step is removed at a bounded speed, not within the step
(:func:`colsim.engine.contacts.recovery_relaxation`, :func:`colsim.engine.state.recovery_speed`), so
a smaller step does not turn the same overlap into a larger velocity.

Potential contacts come from the free-flight prediction u = v dt + g dt^2 of every particle
(:func:`colsim.engine.contacts.detect`): a pair is listed when its relative segment comes within a margin
(default 5 % of the smallest diameter, plus half the pair's relative displacement, for the velocity
changes of the step). After the step the largest overlap is measured. A step whose overlap exceeds
the tolerance is redone: missed pairs are added, linearised about their end-of-attempt normal, the
margin grows (2x by default) and cylinder gaps are tightened by the overlap the attempt made; a
solver that takes a warm start starts the redo from the attempt's forces (the missed pairs at
zero), not from the previous step's: a pour's impact steps are redone about once each, so this makes
its steps cheaper (docs/performance.md). A step that
still overlaps after `max_redo` redos fails with an :class:`OverlapError` naming the step.
The next step starts from the margin that caught a missed contact (at most 4x the base), halved
after each clean step (:func:`next_margin`): the fast phase of a tall column's collapse redoes fewer
steps (docs/performance.md).

The overlap check measures the pairs of the next step's first detection, made at the attempt's end
(:class:`Upcoming`): its swept pairs hold every pair that overlaps there, so the check needs no
search of its own, and :func:`run` hands that detection to the next step (one neighbour search a
step instead of two; the same contacts, overlaps and steps). On the GPU that detection measures
the pairs' largest overlap itself, so the host measures them only when it exceeds the tolerance.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from . import contacts as contact_detection
from . import friction
from .backend import HOST, Backend
from .records import Carry, StepDiagnostics
from .solver_contract import ConeSolution, Solver
from .state import ParticleState, StepSettings, recovery_speed
from .warm_start import WarmStart

log = logging.getLogger(__name__)


class OverlapError(RuntimeError):
    """A step left two bodies overlapping by more than the tolerance: a contact was missed."""


@dataclass
class Upcoming:
    """The first detection of the step after this one, made by this step's overlap check: the state
    and the margin (length) it was made for, its contacts, and the state's predicted motion (n, 3)."""

    state: ParticleState
    margin: float
    contacts: contact_detection.Contacts
    predicted: np.ndarray


@dataclass
class StepResult:
    """The new state, the contacts with their forces (m, 5), the step's diagnostics, the next step's
    first detection (:class:`Upcoming`) and, from :func:`run`, what the next step starts from."""

    state: ParticleState
    contacts: contact_detection.Contacts
    solution: ConeSolution
    diagnostics: StepDiagnostics
    upcoming: Upcoming | None = None
    carry: Carry | None = None


def base_margin(state: ParticleState, settings: StepSettings) -> float:
    """The detection margin (length) of a step with no history: detection_margin_fraction times the
    smallest diameter."""
    return settings.detection_margin_fraction * 2.0 * float(np.min(state.radius, initial=0.5))


CARRIED_MARGIN_LIMIT = 4.0  # the margin carried to the next step is at most this times the base


def next_margin(diagnostics: StepDiagnostics, base: float) -> float:
    """The margin to start the next step with (length): the margin of a step that missed a contact
    (a particle pair or the floor) is kept, up to 4x `base`; any other step's is halved, never below
    `base`. Motions that made one step miss a contact usually last several steps; starting from the
    margin that worked saves redoing each of them. (A redo for the cylinder's curvature alone is
    not a reason.) The limit matters while pouring: there every step misses some collision, and a
    margin carried without one grew to 14 candidate contacts per sphere."""
    return _next_margin(diagnostics.missed_contacts, diagnostics.detection_margin, base)


def _next_margin(missed: int, margin: float, base: float) -> float:
    """:func:`next_margin` of a step that missed `missed` contacts with margin `margin`."""
    if missed:
        return min(margin, CARRIED_MARGIN_LIMIT * base)
    return max(base, 0.5 * margin)


def _first_detection(backend: Backend, state: ParticleState, settings: StepSettings, predicted, margin: float,
                     most_recovered: float, kept: float) -> contact_detection.Contacts:
    """The contacts of a step's first attempt (no cylinder margin, no given normals)."""
    return backend.detect(state, settings.walls, settings.law, predicted, margin, settings.detection_slack,
                          np.zeros(state.n), None, most_recovered, kept)


def step(state: ParticleState, settings: StepSettings, solver: Solver, step_number: int = 0,
         warm_start: WarmStart | None = None, margin: float | None = None,
         upcoming: Upcoming | None = None, backend: Backend = HOST) -> StepResult:
    """Advance `state` by one step of settings.dt; see the module docstring for the checks.

    warm_start: forces by contact pair, matched to each attempt's contacts (None: a cold start).
    margin: detection margin of the first attempt (length); None: :func:`base_margin`.
    upcoming: the last step's :attr:`StepResult.upcoming`, taken as the first attempt's contacts
    when it was made for this state and margin (None, or another's: detected here), and its
    predicted motion when made for this state.
    backend: where the step's parts run (the solver's own iterations are its own back-end's)."""
    smallest_diameter = 2.0 * float(np.min(state.radius, initial=0.5))
    mean_diameter = 2.0 * float(np.mean(state.radius)) if state.n else 1.0
    tolerance = settings.overlap_tolerance * smallest_diameter
    most_recovered = recovery_speed(settings, mean_diameter) * settings.dt
    kept = settings.overlap_kept * smallest_diameter
    base = base_margin(state, settings)
    margin = base if margin is None else margin
    started = time.perf_counter()
    ahead = upcoming if upcoming is not None and upcoming.state is state else None   # made for this state
    predicted = backend.predicted(state, settings) if ahead is None else ahead.predicted
    cylinder_margin = np.zeros(state.n)
    renormal, missed = None, 0
    start_from = warm_start
    for attempt in range(settings.max_redo + 1):
        t0 = time.perf_counter()
        if attempt == 0 and ahead is not None and ahead.margin == margin:
            found = ahead.contacts
        else:
            found = backend.detect(state, settings.walls, settings.law, predicted, margin,
                                   settings.detection_slack, cylinder_margin, renormal, most_recovered, kept)
        t1 = time.perf_counter()
        program = backend.assemble(state, found, settings.dt, settings.gravity)
        t2 = time.perf_counter()
        guess = None if start_from is None else backend.matched(start_from, found)
        t3 = time.perf_counter()
        solution = friction.solve_step(program, solver, settings.friction, mean_diameter, guess, step_number)
        new_state = backend.advance(state, solution.resident_increments(), settings.dt)
        t4 = time.perf_counter()
        following_margin = _next_margin(missed, margin, base)   # the next step's, if this attempt holds
        following_motion = backend.predicted(new_state, settings)
        following = Upcoming(new_state, following_margin, _first_detection(
            backend, new_state, settings, following_motion, following_margin, most_recovered, kept), following_motion)
        overlap = backend.overlaps(new_state, settings.walls, tolerance, detected=following.contacts)
        t5 = time.perf_counter()
        if overlap.largest <= tolerance:
            break
        log.debug("step %d: overlap %.3g exceeds %.3g (%d pairs); redoing",
                 step_number, overlap.largest, tolerance, len(overlap.pairs[0]))
        margin *= settings.margin_growth
        missed += (len(overlap.pairs[0]) + int(overlap.largest_floor > tolerance)
                   + int(overlap.largest_fixed > tolerance) + int(overlap.largest_plane > tolerance))
        cylinder_margin += 1.5 * overlap.cylinder
        renormal = _merge_pairs(renormal, overlap.pairs, state.n)
        if solver.uses_warm_start:   # the redo's contacts hold the attempt's, with the missed ones added
            start_from = backend.carried(found, solution.resident_forces())
    else:
        raise OverlapError(
            f"step {step_number}: largest overlap {overlap.largest:.3g} exceeds the tolerance "
            f"{tolerance:.3g} after {settings.max_redo} redos")
    trans, rot = new_state.kinetic_energy()
    diagnostics = StepDiagnostics(
        step=step_number, time=new_state.time, n_contacts=found.m,
        n_active=solution.active_contacts(), largest_overlap=overlap.largest,
        kinetic_energy=trans, rotational_energy=rot, solver_status=solution.status,
        solver_backend=solution.backend or solver.name, solver_iterations=solution.iterations,
        friction_iterations=solution.info.get("friction_iterations", 1),
        detection_time=t1 - t0, assembly_time=t2 - t1,
        setup_time=solution.setup_time, solve_time=solution.solve_time, redone=attempt,
        missed_contacts=missed,
        detection_margin=margin, wall_time=time.perf_counter() - started,
        matching_time=t3 - t2, check_time=t5 - t4,
    )
    return StepResult(new_state, found, solution, diagnostics, following)


def _merge_pairs(old, new, n):
    """Union of two (i, j, normal) pair sets; the newer normal wins for a pair in both."""
    if old is None:
        return new
    keys_new = new[0].astype(np.int64) * n + new[1]
    keep = ~np.isin(old[0].astype(np.int64) * n + old[1], keys_new)
    return tuple(np.concatenate([a[keep], b]) for a, b in zip(old, new))


def run(state: ParticleState, settings: StepSettings, n_steps: int, solver: Solver,
        first_step: int = 0, carry: Carry | None = None, backend: Backend = HOST) -> Iterator[StepResult]:
    """Yield the result of each of n_steps steps from `state` (step numbers from first_step + 1).

    carry: what the first step starts from (a resumed run's last :attr:`StepResult.carry`, or a
    warm start from an earlier stage); each result carries what the next step starts from.
    backend: where the steps' parts run (:func:`step`)."""
    carry = carry or Carry()
    base = base_margin(state, settings)
    upcoming = None
    for k in range(first_step + 1, first_step + n_steps + 1):
        result = step(state, settings, solver, k, carry.warm_start, carry.margin, upcoming, backend)
        upcoming = result.upcoming
        warm = backend.carried(result.contacts, result.solution.resident_forces()) if solver.uses_warm_start else None
        carry = result.carry = Carry(warm, next_margin(result.diagnostics, base))
        state = result.state
        yield result
