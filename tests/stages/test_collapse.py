"""The collapse stage (colsim.stages.collapse): warm start from the packing, checkpoints, rest."""
from __future__ import annotations

import numpy as np
import pytest

from colsim import io
from colsim.io.checkpoint import CheckpointError
from colsim.solvers import AutoSolver, ClarabelSolver
from colsim.stages.collapse import CollapseSettings, collapse
from colsim.stages.trim import trim

from helpers import PACKING_R0 as R0

CLARABEL = ClarabelSolver()


def test_the_packing_forces_reach_the_first_collapse_step(packing, tmp_path):
    """Pack -> file -> trim -> file -> collapse: the column's contact forces before release are
    the packing's (they carry its weight), and the first step of an `auto` collapse at a small step
    starts from them with APGD (no cold first step)."""
    forces = packing.contact_forces
    weight = float(np.sum(packing.state.mass)) * 9.81
    on_floor = forces.family == 1
    # n points from the sphere to the floor; 1 %: the last step still decelerates a few grains
    assert forces.force[on_floor, 2].sum() == pytest.approx(-weight, rel=1e-2)
    path = tmp_path / "packing.nc"
    io.write_state(path, packing.state, io.global_attributes(io.STATE_KIND, "test", {}),
                   io.contact_force_variables(forces))
    state, dataset = io.read_state(path)
    stored = io.contact_forces_of(dataset)
    np.testing.assert_array_equal(stored.j, forces.j)
    np.testing.assert_array_equal(stored.force, forces.force)
    h0 = 1.0 * R0
    kept = state.position[:, 2] + state.radius <= h0
    column = trim(state, h0)
    settings = CollapseSettings(mu_r=0.12, n_steps=1000, checkpoint_every=10**6)
    auto = AutoSolver(scaled_time_step=settings.duration / settings.n_steps)
    run = collapse(column, h0, settings, auto, warm_start=stored.subset(kept), stop_after=3)
    assert [d.solver_backend for d in run.diagnostics] == ["apgd"] * 3
    cold = collapse(column, h0, settings, auto, stop_after=1)     # a column without its forces
    assert cold.diagnostics[0].solver_backend == "apgd"


@pytest.mark.slow
def test_zero_rolling_resistance_spreads_further_and_lower(packing):
    """The paper: spheres without rolling resistance end nearly flat (Eq. 5 vs Eq. 6).

    Measured over all grains, not the main mass: with mu_r = 0 spheres keep rolling on the floor
    and break into clusters (the main mass can be a small fragment), which is the point.
    """
    h0 = 2.0 * R0
    column = trim(packing.state, h0)
    top, spread = {}, {}
    for mu_r in (0.0, 0.12):
        final = collapse(column, h0, CollapseSettings(mu_r=mu_r, n_steps=100), CLARABEL).frames[-1][1]
        top[mu_r] = np.percentile(final.position[:, 2] + final.radius, 99)
        spread[mu_r] = np.mean(np.hypot(final.position[:, 0], final.position[:, 1]) + final.radius)
    # Margins of half and one largest grain diameter (0.5), the resolution of both measures;
    # measured with seed [7, 0]: tops 0.75 vs 1.18, mean radial reach 3.30 vs 2.40.
    assert top[0.0] < top[0.12] - 0.25
    assert spread[0.0] > spread[0.12] + 0.5


def test_collapse_resumes_from_checkpoint_to_the_same_result(packing, tmp_path):
    h0 = 1.0 * R0
    column = trim(packing.state, h0)
    settings = CollapseSettings(n_steps=12, frame_every=4, checkpoint_every=5)
    whole = collapse(column, h0, settings, CLARABEL)
    checkpoint = tmp_path / "run.checkpoint"
    first = collapse(column, h0, settings, CLARABEL, checkpoint=checkpoint, stop_after=7)   # "killed" at step 7
    assert len(first.diagnostics) == 7 and checkpoint.exists()
    # run again with another checkpoint interval and end (issue 45.4: neither changes a step)
    again = CollapseSettings(n_steps=12, frame_every=4, checkpoint_every=3, max_duration=None)
    resumed = collapse(column, h0, again, CLARABEL, checkpoint=checkpoint)
    assert resumed.resumed_from == 5                       # the last checkpoint before the kill
    assert [k for k, _ in resumed.frames] == [k for k, _ in whole.frames]
    np.testing.assert_allclose(resumed.frames[-1][1].position, whole.frames[-1][1].position, rtol=0, atol=1e-12)
    # a checkpoint of other settings is refused (issue 45.2), neither resumed nor replaced
    with pytest.raises(CheckpointError, match="another run"):
        collapse(column, h0, CollapseSettings(n_steps=12, mu_r=0.0, checkpoint_every=5), CLARABEL,
                 checkpoint=checkpoint)


def test_rest_criterion_needs_the_whole_window_steady():
    from colsim.stages.collapse import deposit_at_rest

    t = np.arange(0.0, 3.01, 0.2)
    steady = np.r_[np.linspace(1.0, 2.0, 6), np.full(10, 2.0)]      # moving until t = 1, then still
    assert deposit_at_rest(t, np.ones_like(t), steady, window=1.0, tolerance=0.01)
    assert not deposit_at_rest(t[:8], np.ones(8), steady[:8], window=1.0, tolerance=0.01)  # t <= 1.4
    assert not deposit_at_rest(t[:3], np.ones(3), np.ones(3), window=1.0, tolerance=0.01)  # too short
    assert not deposit_at_rest(t, steady, np.ones_like(t), window=3.0, tolerance=0.01)      # height moved


def test_collapse_runs_on_to_rest_and_stops_there(packing):
    """An a = 0.5 column (79 spheres) run on past its nominal end t/sqrt(h0/g) = 2: it ends where the
    deposit is at rest, well before 12 (measured: at rest at t = 7.5, step 75 of 120 at most, kinetic
    energy 0.5 % of its peak), and follows the fixed-length run exactly up to its end."""
    h0 = 0.5 * R0
    column = trim(packing.state, h0)
    fixed = CollapseSettings(n_steps=20, duration=2.0, frame_every=5)
    settings = CollapseSettings(n_steps=20, duration=2.0, frame_every=5, max_duration=12.0,
                                rest_window=1.0, rest_tolerance=0.1)
    run = collapse(column, h0, settings, CLARABEL)
    assert run.at_rest
    assert settings.n_steps <= len(run.diagnostics) < settings.max_steps
    assert run.frames[-1][0] == len(run.diagnostics)
    energy = np.array([d.kinetic_energy + d.rotational_energy for d in run.diagnostics])
    assert energy[-1] <= settings.rest_energy * energy.max()
    short = collapse(column, h0, fixed, CLARABEL)              # the same steps up to the nominal end
    assert run.frames[len(short.frames) - 1][0] == short.frames[-1][0]
    np.testing.assert_allclose(run.frames[len(short.frames) - 1][1].position, short.frames[-1][1].position,
                               rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="max_duration"):
        CollapseSettings(duration=4.0, max_duration=2.0)




def test_the_rest_test_measures_only_the_frames_it_reads(packing, monkeypatch):
    """The rest test measures a frame's deposit only once the energy is low and the frame lies in
    the rest window, each frame once (DepositHistory), and comes to the same verdict at every frame
    as the test on every frame measured (deposit_at_rest): the run stops at the same step."""
    from colsim.stages import collapse as stage

    h0 = 0.5 * R0
    column = trim(packing.state, h0)
    settings = CollapseSettings(n_steps=20, duration=2.0, frame_every=5, max_duration=12.0,
                                rest_window=1.0, rest_tolerance=0.1)
    measured = []
    measure = stage.measure_deposit
    monkeypatch.setattr(stage, "measure_deposit", lambda state, **how: measured.append(state.time) or measure(state, **how))
    run = collapse(column, h0, settings, CLARABEL)
    assert run.at_rest and len(measured) == len(set(measured)) < len(run.frames)
    time_scale = np.sqrt(h0 / settings.gravity)
    times = np.array([state.time for _, state in run.frames]) / time_scale
    deposits = [measure(state) for _, state in run.frames]
    energy = np.array([d.kinetic_energy + d.rotational_energy for d in run.diagnostics])
    tolerance = settings.rest_tolerance * 2.0 * float(column.radius.mean())

    def at_rest(n):   # the rest test at the n-th frame, every frame's deposit measured
        k = run.frames[n - 1][0]
        return (k >= settings.n_steps and energy[k - 1] <= settings.rest_energy * energy[:k].max()
                and stage.deposit_at_rest(times[:n], [d.h_inf for d in deposits[:n]],
                                          [d.r_inf for d in deposits[:n]], settings.rest_window, tolerance))
    verdicts = [at_rest(n) for n in range(1, len(run.frames) + 1)]
    assert verdicts[-1] and not any(verdicts[:-1])
