"""The step's back-end: where its work runs, chosen once.

A time step (:mod:`colsim.engine.stepper`) predicts each particle's free flight, detects the
potential contacts, assembles the cone program, matches the last step's forces to the new contacts,
has a solver solve the program, moves the particles, and checks the overlaps. A :class:`Backend`
does each of these but the solve, and makes APGD's iteration for the solver
(:mod:`colsim.solvers.apgd`). The stage builds one from its `device` setting
(:func:`colsim.engine.backends.make_backend`) and hands it to the stepper and the solver; no function
below asks where it runs.

:class:`CpuBackend` runs everything on the host (numba's threads). The CUDA back-end
(:class:`colsim.engine.cuda_backend.CudaBackend`) is its subclass: it keeps the particles, the
contacts, the program and the warm start on one GPU between steps, and overrides only what runs
there. This module imports none of it.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Protocol

import numpy as np

from . import contacts as contact_detection
from .apgd_iteration import ApgdIteration, cpu_iteration
from .program import ConeProgram, assemble
from .state import ContactLaw, ParticleState, StepSettings, Walls
from .warm_start import WarmStart


class Backend(Protocol):
    """What the stepper and APGD ask of a back-end (see the module docstring)."""

    #: 'cpu' or 'cuda': recorded with a run, never branched on
    name: str
    #: the name of APGD's kernels, recorded in the solver's settings
    apgd_kernel: str
    #: how APGD's iteration may store its arrays (colsim.solvers.defaults.GPU_STORAGES), the first the default
    storages: tuple[str, ...]

    def predicted(self, state: ParticleState, settings: StepSettings):
        """(n, 3) the free-flight displacement v dt + g dt^2 of each particle over one step (length)."""

    def detect(self, state: ParticleState, walls: Walls, law: ContactLaw, predicted, margin: float, slack: float = 0.5,
               cylinder_margin=0.0, renormal=None, most_recovered: float = np.inf,
               kept: float = 0.0) -> contact_detection.Contacts:
        """The potential contacts (:func:`colsim.engine.contacts.detect`, its arguments)."""

    def assemble(self, state: ParticleState, found: contact_detection.Contacts, dt: float, gravity) -> ConeProgram:
        """The step's cone program (:func:`colsim.engine.program.assemble`)."""

    def carried(self, found: contact_detection.Contacts, forces) -> WarmStart:
        """A step's forces (m, 5) by contact pair, for the next step (:meth:`WarmStart.from_step`):
        where the solver left them (:meth:`colsim.engine.solver_contract.ConeSolution.resident_forces`)."""

    def matched(self, warm_start: WarmStart, found: contact_detection.Contacts):
        """(m, 5) the warm start's forces in `found`'s frames (:meth:`WarmStart.match`)."""

    def advance(self, state: ParticleState, u, dt: float) -> ParticleState:
        """The state after a step of dt with increments u (6n,) (:func:`advance`), where the solver left
        them (:meth:`colsim.engine.solver_contract.ConeSolution.resident_increments`)."""

    def overlaps(self, state: ParticleState, walls: Walls, tolerance: float,
                 detected: contact_detection.Contacts | None = None) -> contact_detection.Overlaps:
        """Every overlap of `state` (:func:`colsim.engine.contacts.overlaps`)."""

    def apgd_iteration(self, program: ConeProgram, warm_start, precondition: bool, lip_decay: float,
                       storage: str) -> ApgdIteration:
        """APGD's iteration state for `program` from `warm_start` (:mod:`colsim.engine.apgd_iteration`)."""


def predicted_displacement(state: ParticleState, settings: StepSettings) -> np.ndarray:
    """(n, 3) the free-flight displacement v dt + g dt^2 of each particle over one step (length)."""
    return state.velocity * settings.dt + np.asarray(settings.gravity) * settings.dt**2


def advance(state: ParticleState, u: np.ndarray, dt: float) -> ParticleState:
    """The state after a step of dt (time) with increments u = [dx; dth] (6n,): x + dx, v = dx / dt,
    w = dth / dt."""
    n = state.n
    dx = u[:3 * n].reshape(n, 3)
    dth = u[3 * n:].reshape(n, 3)
    return replace(state, position=state.position + dx, velocity=dx / dt,
                   angular_velocity=dth / dt, time=state.time + dt)


class CpuBackend:
    """Every part of the step on the host: a k-d tree's detection, numba's compiled kernels on its
    threads (:mod:`colsim.engine.threads`)."""

    name = "cpu"
    apgd_kernel = "numba"
    storages = ("float64",)

    def predicted(self, state, settings):
        return predicted_displacement(state, settings)

    def detect(self, state, walls, law, predicted, margin, slack=0.5, cylinder_margin=0.0, renormal=None,
               most_recovered=np.inf, kept=0.0):
        return contact_detection.detect(state, walls, law, predicted, margin, slack, cylinder_margin, renormal,
                                        most_recovered, kept)

    def assemble(self, state, found, dt, gravity):
        return assemble(state, found, dt, gravity)

    def carried(self, found, forces):
        return WarmStart.from_step(found, forces)

    def matched(self, warm_start, found):
        return warm_start.match(found)

    def advance(self, state, u, dt):
        return advance(state, u, dt)

    def overlaps(self, state, walls, tolerance, detected=None):
        return contact_detection.overlaps(state, walls, tolerance, detected)

    def apgd_iteration(self, program, warm_start, precondition, lip_decay, storage):
        return cpu_iteration(program, warm_start, precondition, lip_decay)


#: the back-end of a stage or step that names none: the host's
HOST = CpuBackend()
