"""A first-order back-end: accelerated projected gradient (APGD) on the contact forces.

It solves the force form of the step's cone program (:mod:`colsim.engine.program`),

    minimise   1/2 lam' W lam + c' lam      subject to lam_k in K_k,
    K_k = {(p, q, r): ||q|| <= mu_k p, ||r|| <= mu_r,k p},

the same convex program as Clarabel (same cones, same associated law), by Nesterov's accelerated
projected gradient with adaptive (gradient) restart and backtracking on the step length, as in
Chrono's APGD (Mazhar et al. 2015). W is never formed: the gradient is

    W lam + c = B u(lam) + g e_n,   u(lam) = Mbar^-1 (fbar + B' lam),

i.e. each contact's gap at the end of the step, so one iteration costs one product with B' and one
with B (work linear in the number of contacts) plus the exact Euclidean projection onto K_k
(:func:`colsim.engine.cones.project_point`). The compiled kernel fuses them and applies B and B' from the
contacts' frames and radii (12 numbers a contact) instead of the matrix (42 non-zeros a contact),
which costs less an iteration (docs/performance.md).

Preconditioning: each contact's normal, sliding and rolling rows are scaled separately, lam = S z
with S = diag(s_n, s_t, s_t, s_r, s_r) per contact and s = diag(W)^-1/2 (averaged over the two rows
of a pair). The scaled cone is again a coupled cone with mu' = mu s_n/s_t, mu_r' = mu_r s_n/s_r
(mu_s and mu_r_s in the code), so the projection stays exact.

Stopping (checked every `check_every` iterations, at the current iterate lam, in one compiled
sweep): the relative primal infeasibility and complementarity of
:func:`colsim.engine.cones.relative_residuals` must both fall below `tolerance`; dual feasibility
(lam_k in K_k) is exact by construction (the iterate is a projection). Their length L is the
step's root-mean-square free flight, or `length_floor` mean diameters where that is larger: at rest
the free flight is g dt^2 (4e-4 d at r0 = 2 and dt/sqrt(h0/g) = 0.004), and without a floor the
tolerance 1e-5 asks each contact's gap to 4e-9 d, which took most of a resting step's iterations
(at step 900 of an r0 = 2, a = 5 collapse: 1,280 iterations, 310 with the floor 0.1). The
primal residual, a maximum over the contacts, also counts as met once the largest violation is at
most `overlap_tolerance` mean diameters: with the floor, it is what holds most steps after
complementarity has converged (`auto` uses 1e-4 d; 4.3x fewer iterations at r0 = 4).
Not reaching it within `max_iter` iterations raises :class:`SolverError`.

Warm start: the solver accepts forces (m, 5) aligned with the program's contacts (zeros for new
contacts). :class:`colsim.engine.warm_start.WarmStart` carries a step's forces by contact pair, in the
global frame, and re-expresses them in the next step's contact frames.
"""
from __future__ import annotations

import logging
import time

import numpy as np

from . import defaults
from ..engine.apgd_iteration import ApgdIteration
from ..engine.backend import Backend, CpuBackend
from ..engine.cones import force_floor, length_scale, mean_diameter
from ..engine.program import ConeProgram
from ..engine.solver_contract import ConeSolution, Solver, SolverError, at_step

log = logging.getLogger(__name__)



class ApgdSolver(Solver):
    """Accelerated projected gradient on the contact forces (see the module docstring).

    tolerance: on the relative primal infeasibility and complementarity (dimensionless).
    max_iter: iterations before :class:`SolverError`. check_every: iterations between residual
    checks. precondition: scale each contact's normal, sliding and rolling rows separately.
    backend: where the iterations run (:class:`colsim.engine.backend.Backend`, the stage's; default
    the host's): it makes the iteration state (:meth:`~colsim.engine.backend.Backend.apgd_iteration`),
    and its `apgd_kernel` names the kernels in the solver's settings.
    length_floor: the residuals' length is at least this many mean diameters (module docstring;
    0: the step's free flight alone).
    overlap_tolerance: the primal residual also counts as met once the largest cone violation of
    the end-of-step gaps (a contact's overlap, for a sticking one) is at most this many mean
    diameters (0: the relative tolerance alone). Complementarity keeps `tolerance` either way.
    lipschitz_decay: the Lipschitz estimate L shrinks by this factor after every iteration and
    doubles when the descent test fails (as in Chrono's APGD): longer steps where W is flatter
    (docs/solvers.md, "The Lipschitz estimate's decay").
    storage: how the iteration stores its arrays (one of the back-end's `storages`):
    'float64', or on a GPU 'float32' (:data:`colsim.engine.cuda_apgd.NARROW_GEOMETRY`: fewer bytes an
    iteration, the stopping test and the step's forces still in float64); a float32 solve that reaches
    the cap is made again in float64 before the solver gives up.
    """

    name = "apgd"
    uses_warm_start = True

    def __init__(self, tolerance: float = defaults.APGD_TOLERANCE, max_iter: int = defaults.APGD_MAX_ITER, check_every: int = 10,
                 precondition: bool = True, backend: Backend | None = None,
                 lipschitz_decay: float = defaults.APGD_LIPSCHITZ_DECAY,
                 length_floor: float = 0.0, overlap_tolerance: float = 0.0, storage: str = defaults.DEFAULT_GPU_STORAGE,
                 verbose: bool = False):
        if not tolerance > 0:
            raise ValueError(f"APGD tolerance must be positive, got {tolerance}")
        if max_iter < 1 or check_every < 1:
            raise ValueError("max_iter and check_every must be >= 1")
        self.backend = CpuBackend() if backend is None else backend
        if storage not in defaults.GPU_STORAGES:
            raise ValueError(f"APGD's storage must be one of {', '.join(defaults.GPU_STORAGES)}, got {storage!r}")
        if storage not in self.backend.storages:
            raise ValueError(f"APGD's {storage} storage is the GPU's (device cuda); the {self.backend.name} "
                             f"stores {', '.join(self.backend.storages)}")
        self.storage = storage
        self.tolerance = float(tolerance)
        self.max_iter = int(max_iter)
        self.check_every = int(check_every)
        self.precondition = precondition
        if not 0 < lipschitz_decay <= 1:
            raise ValueError(f"lipschitz_decay must be in (0, 1], got {lipschitz_decay}")
        self.kernel = self.backend.apgd_kernel   # recorded in the settings (describe)
        self.lipschitz_decay = float(lipschitz_decay)
        if not length_floor >= 0:
            raise ValueError(f"length_floor must be >= 0 mean diameters, got {length_floor}")
        self.length_floor = float(length_floor)
        if not overlap_tolerance >= 0:
            raise ValueError(f"overlap_tolerance must be >= 0 mean diameters, got {overlap_tolerance}")
        self.overlap_tolerance = float(overlap_tolerance)
        self.verbose = verbose

    def describe(self) -> dict:
        """The settings; the overlap tolerance only when it is on and the storage only when it is not
        float64, so that runs made before they existed (and the packings, which do not use the first)
        compare equal to those made after."""
        settings = super().describe()
        if not self.overlap_tolerance:
            del settings["overlap_tolerance"]
        if self.storage == defaults.DEFAULT_GPU_STORAGE:   # likewise the storage, where it is the default
            del settings["storage"]
        return settings

    # -- the iteration ---------------------------------------------------------------------
    def prepare(self, program: ConeProgram, warm_start: np.ndarray | None = None,
                storage: str | None = None) -> ApgdIteration:
        """The scaled problem of `program` (m > 0 contacts) and its first iterate, ready to iterate,
        made by the back-end (storage: default the solver's)."""
        return self.backend.apgd_iteration(program, warm_start, self.precondition, self.lipschitz_decay,
                                           storage or self.storage)

    def stopping_scales(self, program: ConeProgram) -> tuple[float, float, float]:
        """The stopping rule's scales for `program`: the residuals' length L (the free flight or
        `length_floor` mean diameters d, whichever is larger), the force floor F0 (from the free
        flight alone) and the primal tolerance (relative to L: `tolerance`, or the overlap
        tolerance's `overlap_tolerance` d / L where that is larger)."""
        diameter = mean_diameter(program)
        free_flight = length_scale(program, diameter)
        scale = max(free_flight, self.length_floor * diameter)
        return (scale, force_floor(program, free_flight),
                max(self.tolerance, self.overlap_tolerance * diameter / scale))

    def solve(self, program: ConeProgram, warm_start: np.ndarray | None = None,
              step: int | None = None, max_iter: int | None = None) -> ConeSolution:
        """Solve `program` from `warm_start` ((m, 5) forces or None); max_iter: this call's cap
        (default: the solver's). Under float32 storage a solve that reaches the cap is made again from
        the same start in float64 (its info's `storage` says which solved, and its `backend` is
        defaults.FLOAT64_FALLBACK, which a collapse records as the step's `step_solver_backend`)."""
        if program.m == 0:
            return self.no_contacts(program)
        try:
            return self._solve(program, warm_start, step, max_iter, self.storage)
        except SolverError as error:
            if self.storage == defaults.DEFAULT_GPU_STORAGE:
                raise
            log.info("%s with %s storage; solving this step again with %s", error, self.storage,
                     defaults.DEFAULT_GPU_STORAGE)
            solution = self._solve(program, warm_start, step, max_iter, defaults.DEFAULT_GPU_STORAGE)
            solution.backend = defaults.FLOAT64_FALLBACK
            return solution

    def _solve(self, program: ConeProgram, warm_start, step, max_iter, storage: str) -> ConeSolution:
        """:meth:`solve` with the GPU's `storage`."""
        start = time.perf_counter()
        m = program.m
        max_iter = self.max_iter if max_iter is None else int(max_iter)
        run = self.prepare(program, warm_start, storage)
        started = "warm" if run.is_warm() else "cold"
        scale, floor, primal_tolerance = self.stopping_scales(program)
        setup_time = time.perf_counter() - start

        res = {"primal": np.inf, "dual": 0.0, "complementarity": np.inf}
        k = 0
        converged = False
        while k < max_iter:
            n = min(self.check_every, max_iter - k)
            res = run.iterate_and_check(n, program, scale, floor)
            k += n
            if self.verbose:
                log.info("apgd %d: primal %.2e compl %.2e L %.3g", k, res["primal"],
                         res["complementarity"], run.lip)
            if res["primal"] <= primal_tolerance and res["complementarity"] <= self.tolerance:
                converged = True
                break
        solve_time = time.perf_counter() - start - setup_time
        info = dict(res, start=started, backtracks=run.backtracks, restarts=run.restarts,
                    lipschitz=run.lip, length_scale=scale, kernel=self.kernel)
        if len(self.backend.storages) > 1:   # a back-end with a choice records the one made
            info["storage"] = storage
        if not converged:
            raise SolverError(
                f"APGD did not converge{at_step(step)} within {max_iter} iterations "
                f"(relative primal infeasibility {res['primal']:.2e}, complementarity "
                f"{res['complementarity']:.2e}, tolerance {self.tolerance:.1e}, {m} contacts)",
                status="MaxIterations", step=step, residuals=res)
        return run.solution(program, k, setup_time, solve_time, info)
