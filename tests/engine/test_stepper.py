"""The time step (colsim.engine.stepper): its two failure modes, a missed contact (redone, or OverlapError)
and a solver that does not converge (SolverError); the phases it times."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from colsim.engine.contacts import overlaps
from colsim.engine.state import ContactLaw, ParticleState, StepSettings, Walls
from colsim.engine.stepper import OverlapError, base_margin, next_margin, step
from colsim.solvers import ClarabelSolver, SolverError
from colsim.solvers.apgd import ApgdSolver


def _train(max_redo: int):
    """Sphere C (x = 0) flies at 2 along +x into A (resting, gap 0.001); B rests 0.01 beyond A.

    Gravity off, no walls, detection margin 1e-6 d and no slack: A-B is not predicted (neither
    moves in free flight), but C pushes A about 0.02 in the step, into B.
    """
    radius = np.full(3, 0.2)
    position = np.array([[0.0, 0, 0], [0.401, 0, 0], [0.811, 0, 0]])
    velocity = np.array([[2.0, 0, 0], [0, 0, 0], [0, 0, 0]])
    state = ParticleState(position, velocity, np.zeros((3, 3)), radius)
    settings = StepSettings(dt=0.02, gravity=(0.0, 0.0, 0.0), walls=Walls(floor=False),
                            law=ContactLaw.uniform(0.3, 0.0), detection_margin_fraction=1e-6,
                            detection_slack=0.0, max_redo=max_redo)
    return state, settings


def test_missed_contact_is_redone():
    """The first attempt overlaps A and B by ~0.009 (> tolerance 0.004); the step is redone with
    the missed pair and ends within the tolerance, conserving momentum (1e-9 relative: no external
    force; Clarabel's tolerance)."""
    state, settings = _train(max_redo=3)
    result = step(state, settings, ClarabelSolver(), step_number=5)
    tolerance = settings.overlap_tolerance * 0.4
    assert result.diagnostics.redone >= 1
    assert result.diagnostics.largest_overlap <= tolerance
    assert overlaps(result.state, settings.walls).largest <= tolerance
    assert result.contacts.m >= 2  # C-A and the added A-B
    momentum = (result.state.mass[:, None] * result.state.velocity).sum(axis=0)
    np.testing.assert_allclose(momentum, (state.mass[:, None] * state.velocity).sum(axis=0),
                               rtol=1e-9, atol=1e-9 * state.mass[0] * 2.0)
    assert result.state.velocity[2, 0] > 0.1  # B was pushed: the contact was really taken


class _RecordingApgd(ApgdSolver):
    """APGD that keeps each call's contacts' warm start ((m, 5) or None) and forces."""

    def __init__(self):
        super().__init__(tolerance=1e-8)
        self.calls = []

    def solve(self, program, warm_start=None, step=None, max_iter=None):
        solution = super().solve(program, warm_start=warm_start, step=step, max_iter=max_iter)
        self.calls.append((None if warm_start is None else np.array(warm_start), solution.forces.copy()))
        return solution


def test_redo_starts_from_the_attempt_it_redoes():
    """A redone step warm-starts from its first attempt's forces (the pairs it shares with it), not
    from the previous step's: the redo then only has to take up the missed pair. The first attempt
    here starts cold; the redo's start holds that attempt's C-A force (to rounding: the same
    frame) and zero for the added A-B pair, and the step still meets the overlap tolerance."""
    state, settings = _train(max_redo=3)
    solver = _RecordingApgd()
    result = step(state, settings, solver, step_number=5)
    assert result.diagnostics.redone >= 1
    assert len(solver.calls) == result.diagnostics.redone + 1
    first_start, first_forces = solver.calls[0]
    redo_start, _ = solver.calls[1]
    assert first_start is None
    assert first_forces[0, 0] > 0            # the attempt's C-A push, contact 0 in both attempts
    np.testing.assert_allclose(redo_start[0], first_forces[0], rtol=1e-12, atol=1e-15)
    assert np.all(redo_start[1:] == 0.0)     # A-B: new in the redo
    assert result.diagnostics.largest_overlap <= settings.overlap_tolerance * 0.4


def test_next_step_starts_from_the_margin_that_caught_the_missed_pair():
    """The redone step records the missed pair and its grown margin; the next step starts there,
    and each clean step after that halves it, down to the base margin (here 1e-6 d)."""
    state, settings = _train(max_redo=3)
    result = step(state, settings, ClarabelSolver(), step_number=5)
    base = base_margin(state, settings)
    d = result.diagnostics
    assert d.missed_contacts >= 1
    assert d.detection_margin == pytest.approx(base * settings.margin_growth ** d.redone)
    assert next_margin(d, base) == d.detection_margin
    clean = replace(d, redone=0, missed_contacts=0)
    assert next_margin(clean, base) == pytest.approx(0.5 * d.detection_margin)
    assert next_margin(replace(clean, detection_margin=base), base) == base


def test_missed_contact_without_redo_raises():
    """With no redo allowed the overlapping step is an OverlapError naming the step, not a result."""
    state, settings = _train(max_redo=0)
    with pytest.raises(OverlapError, match="step 5"):
        step(state, settings, ClarabelSolver(), step_number=5)


def test_unconverged_solver_raises_with_step_and_status():
    """Clarabel stopped after one iteration: SolverError names the step (17) and the status."""
    state = ParticleState.at_rest([[0.0, 0.0, 0.2]], [0.2])
    settings = StepSettings(dt=0.02, law=ContactLaw.uniform(0.5, 0.1))
    with pytest.raises(SolverError) as caught:
        step(state, settings, ClarabelSolver(max_iter=1), step_number=17)
    error = caught.value
    assert error.step == 17
    assert error.status == "MaxIterations"
    assert "step 17" in str(error) and "MaxIterations" in str(error)


def test_a_step_times_its_phases_within_its_wall_time():
    """Each timed phase of the accepted attempt (detection, assembly, matching, set-up, solve, the
    overlap check) is a time, and together they fit in the step's wall time, which also holds the
    redone attempt: perf_counter's clock, monotonic, so exact."""
    state, settings = _train(max_redo=3)
    solver = _RecordingApgd()
    d = step(state, settings, solver, step_number=5).diagnostics
    phases = [d.detection_time, d.assembly_time, d.matching_time, d.setup_time, d.solve_time, d.check_time]
    assert d.redone >= 1 and all(t >= 0.0 for t in phases)
    assert d.check_time > 0.0 and sum(phases) <= d.wall_time


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_a_redo_on_the_gpu_takes_the_cpu_s_step():
    """The train's step on the GPU (APGD's kernels; the detection, and the redo's given pair joined to
    it, on the device: numba's simulator here) is the CPU's: the same redos, the same contacts in the
    same order, and the same end state. Both run APGD's arithmetic on the same programs, so they
    stop at the same iteration; the positions agree to 1e-12 of the step's largest displacement, the
    rounding of a GPU's fused multiply-adds over some hundreds of iterations."""
    pytest.importorskip("colsim.engine.cuda_contacts", reason="numba.cuda is not importable")
    from colsim.engine.backends import make_backend
    from colsim.engine.cuda_contacts import DeviceContacts

    state, settings = _train(max_redo=3)
    cuda = make_backend("cuda")
    gpu = step(state, settings, ApgdSolver(tolerance=1e-8, backend=cuda), step_number=5, backend=cuda)
    cpu = step(state, settings, ApgdSolver(tolerance=1e-8), step_number=5)
    assert gpu.diagnostics.redone == cpu.diagnostics.redone >= 1
    assert gpu.diagnostics.solver_iterations == cpu.diagnostics.solver_iterations
    assert isinstance(gpu.contacts, DeviceContacts) and gpu.contacts.pair_count == 2
    for name in ("i", "j", "family", "lever", "keys"):
        np.testing.assert_array_equal(getattr(gpu.contacts, name), getattr(cpu.contacts, name))
    moved = np.abs(cpu.state.position - state.position).max()
    np.testing.assert_allclose(gpu.state.position, cpu.state.position, rtol=0, atol=1e-12 * moved)
