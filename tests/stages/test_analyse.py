"""The analysis stage (colsim.stages.analyse): final height, run-out by connected cluster, solid fraction."""
from __future__ import annotations

import numpy as np
import pytest

from colsim.engine.state import ParticleState
from colsim.stages import analyse as analysis


def _chain_state():
    """A column of three touching spheres, a chain of two more reaching out, and a lost grain."""
    r = 0.2
    pos = [[0, 0, r], [0, 0, 3 * r], [0, 0, 5 * r],       # main stack
           [2 * r, 0, r], [4 * r, 0, r],                   # chain along the floor
           [3.0, 0, r]]                                    # detached, far away
    return ParticleState.at_rest(np.array(pos, float), np.full(6, r))


def test_runout_counts_a_chain_but_not_a_detached_grain():
    state = _chain_state()
    deposit = analysis.measure_deposit(state, tolerance=1e-6)
    assert deposit.main_mass.tolist() == [True] * 5 + [False]
    assert deposit.r_inf == pytest.approx(4 * 0.2 + 0.2, abs=1e-12)   # outer edge of the chain
    assert deposit.h_inf == pytest.approx(6 * 0.2, abs=1e-12)         # top of the stack


def test_looser_tolerance_and_mass_front_reach_the_detached_grain():
    state = _chain_state()
    tight = analysis.measure_deposit(state, tolerance=1e-6)
    loose = analysis.measure_deposit(state, tolerance=1.8 + 1e-9)   # bridges the 3.0 - 0.8 - 0.4 gap
    assert loose.main_mass.all() and loose.r_inf == pytest.approx(3.2) and tight.r_inf == pytest.approx(1.0)
    # equal masses at reaches 0.2 (x3), 0.6, 1.0, 3.2: half the mass within 0.2, 5/6 within 1.0
    assert analysis.mass_front(state, 0.5) == pytest.approx(0.2)
    assert analysis.mass_front(state, 5 / 6) == pytest.approx(1.0)
    assert analysis.mass_front(state, 1.0) == pytest.approx(3.2)
    with pytest.raises(ValueError, match="mass share"):
        analysis.mass_front(state, 1.5)


def test_floor_contacts_do_not_link_grains():
    r = 0.2
    state = ParticleState.at_rest(np.array([[0, 0, r], [0.5, 0, r], [0.5, 0, 3 * r]]), np.full(3, r))
    deposit = analysis.measure_deposit(state, tolerance=1e-6)
    # grains 0 and 1 both touch the floor but not each other: main mass = the stack {1, 2}
    assert deposit.main_mass.tolist() == [False, True, True]


def test_steps_are_counted_by_the_back_end_that_solved_them():
    """apgd_steps counts a step APGD solved in float64 after float32 storage reached its cap (it is
    APGD's); fallback_steps counts Clarabel's after APGD's cap; a file without back-ends gives NaN."""
    backends = np.array(["apgd", "apgd-float64-fallback", "clarabel", "clarabel-fallback", "apgd"])
    assert analysis.solver_step_counts(backends) == (3.0, 1.0)
    assert all(np.isnan(analysis.solver_step_counts([])))
