"""The convergence study's tables and figure, from synthetic analyses with known numbers."""
import numpy as np
import pytest
import xarray as xr

from colsim.study.convergence import converged_steps, fit_converged_steps, time_step_means, convergence_markdown, runs_table


def analysis(a=2.0, r0=2.0, seed=1, steps=100, duration=4.0, h=1.0, runout=1.5, mean_d=0.4):
    """An analysis Dataset as `colsim analyse` writes it (the variables the table reads).
    Its height and front grow linearly to their final values over the run (frames every 0.5)."""
    t = np.arange(0.0, duration + 1e-9, 0.5)
    ramp = t / duration
    scalar = lambda value, units="1": ((), value, {"units": units, "long_name": "x"})  # noqa: E731
    return xr.Dataset(
        {"h_inf_over_r0": scalar(h), "runout_over_r0": scalar(runout),
         "final_to_peak_kinetic_energy": scalar(1e-3), "n_particles": scalar(900), "wall_time": scalar(10.0, "s"),
         "mean_diameter": scalar(mean_d, "length"),
         "height_history": ("time", (a + (h - a) * ramp) * r0, {"units": "length"}),
         "front_position": ("time", runout * ramp, {"units": "1"}),
         "scaled_time": ("time", t, {"units": "1"})},
        attrs={"r0": r0, "aspect_ratio": a, "mu_r": 0.12, "seed": seed, "n_steps": steps, "duration": duration})


def test_table_has_one_row_per_run_with_its_coordinates():
    groups = {"time_step": [analysis(steps=100), analysis(steps=200)],
              "end_time": [analysis(steps=200, duration=8.0)],
              "column_size": [analysis(r0=2.0), analysis(r0=3.0)],
              "seeds": [analysis(seed=s) for s in (1, 2, 3)]}
    table = runs_table(groups, default_end=4.0)
    assert table.sizes["run"] == 8
    assert list(table.study.values[:3]) == ["time_step", "time_step", "end_time"]
    np.testing.assert_allclose(table.scaled_dt.values[:2], [0.04, 0.02])
    np.testing.assert_allclose(table.r0_over_mean_diameter.values[3:5], [5.0, 7.5])
    # the run to t = 8 is measured again at t = 4, half-way along its ramps
    end = table.isel(run=2)
    assert float(end.runout_over_r0_at_default_end) == pytest.approx(0.75)
    assert float(end.h_inf_over_r0_at_default_end) == pytest.approx(1.5)
    assert table.scaled_dt.attrs["long_name"] == "time step over sqrt(h0/g)"
    assert table.h_inf_over_r0.attrs["units"] == "1"
    assert table.attrs["default_end_time"] == 4.0


def test_markdown_gives_the_relative_change_per_refinement():
    groups = {"time_step": [analysis(steps=100, h=1.0, runout=2.0), analysis(steps=200, h=1.1, runout=2.0),
                            analysis(steps=400, h=1.1, runout=1.9)],
              "seeds": [analysis(seed=s, h=h) for s, h in ((1, 0.9), (2, 1.0), (3, 1.1))]}
    text = convergence_markdown(runs_table(groups, 4.0))
    assert "| 2 | 2 | 200 | 0.02 | 1 | 1.100 | 0.000 | 10.0 % | +0.0 % | 2.000 | 0.000 | 0.0 % | +5.3 % |" in text
    assert "| 2 | 2 | 400 | 0.01 | 1 | 1.100 | 0.000 | 0.0 % | +0.0 % | 1.900 | 0.000 | 5.0 % | +0.0 % |" in text
    assert "a = 2, r0 = 2: converged at 400 steps" in text   # 200 is 5.3 % off in run-out
    assert "| 2 | 3 | 1.000 | 0.100 | 10.0 % |" in text   # sample std of 0.9, 1.0, 1.1


def test_time_step_runs_are_averaged_over_seeds_and_the_converged_step_is_named():
    """Three seeds per level: means, sample sd, and the fewest steps within 3 % of the finest (or a
    third of its seed sd): 500 here, where h is 2 % off and the run-out 1 %."""
    levels = {250: (1.00, 2.0), 500: (1.06, 2.18), 1000: (1.08, 2.2)}
    groups = {"time_step": [analysis(steps=n, seed=seed, h=h + 0.01 * (seed - 2), runout=r)
                            for n, (h, r) in levels.items() for seed in (1, 2, 3)]}
    table = runs_table(groups, 4.0)
    means = time_step_means(table.where(table.study == "time_step", drop=True))
    assert [row["steps"] for row in means] == [250, 500, 1000]
    assert means[0]["seeds"] == 3 and means[0]["h"] == pytest.approx(1.0) and means[0]["h_sd"] == pytest.approx(0.01)
    rows = [dict(row) for row in means]
    assert converged_steps(rows) == 500
    assert converged_steps(rows[:1]) is None
    # the fit through all three levels: h = 1.11 (1 - 6.1 dt), run-out 2.29 (1 - 7.6 dt): within 3 % of
    # X0 only below dt = 0.0039, finer than any level
    assert fit_converged_steps(rows) is None
    slow = [dict(row, h=1.0 + 0.1 * row["dt"], runout=2.0) for row in rows]   # c = 0.1: converged everywhere
    assert fit_converged_steps(slow) == 250
    text = convergence_markdown(table)
    assert "| 2 | 2 | 500 | 0.008 | 3 | 1.060 | 0.010 |" in text
    assert "a = 2, r0 = 2: converged at 500 steps" in text


def test_column_size_is_tabled_per_aspect_ratio_at_both_end_times():
    groups = {"column_size": [analysis(a=0.5, r0=r0, seed=seed, duration=8.0, steps=200, runout=r, h=0.5)
                              for r0, seed, r in ((3.0, 1, 0.5), (2.0, 1, 0.4), (3.0, 2, 0.7))]
              + [analysis(a=2.0, r0=2.0, runout=1.5)]}
    text = convergence_markdown(runs_table(groups, 4.0))
    assert "run-out at t/sqrt(h0/g) = 4 |" in text
    # sorted by r0 within a = 0.5, two seeds averaged at r0 = 3; the run-out at t = 4 is half-way
    assert "| 0.5 | 2 | 5.0 | 1 | 900 | 8 | 0.500 |  | 0.400 | 0.000 |  | 0.200 |" in text
    assert "| 0.5 | 3 | 7.5 | 2 | 900 | 8 | 0.500 | 0.0 % | 0.600 | 0.200 | 50.0 % | 0.300 |" in text
    assert "| 2 | 2 | 5.0 | 1 | 900 | 4 | 1.000 |  | 1.500 | 0.000 |  | 1.500 |" in text


def test_unknown_sub_study_and_empty_input_are_errors():
    with pytest.raises(ValueError, match="unknown convergence sub-studies"):
        runs_table({"timestep": [analysis()]}, 4.0)
    with pytest.raises(ValueError, match="no analyses"):
        runs_table({}, 4.0)


def test_convergence_figure_is_written(tmp_path):
    from colsim.study.figures import convergence_figure

    groups = {"time_step": [analysis(steps=n) for n in (100, 200)], "end_time": [analysis(duration=8.0)],
              "column_size": [analysis(a=0.5, r0=r0, seed=seed, duration=8.0) for r0 in (2.0, 3.0) for seed in (1, 2)],
              "seeds": [analysis(seed=s) for s in (1, 2)]}
    path = convergence_figure(runs_table(groups, 4.0), tmp_path / "convergence.png")
    assert path.stat().st_size > 10000


def test_column_size_limits_recover_a_known_limit_against_the_laws(tmp_path):
    """Runs made on X = X_inf + k d/r0 exactly (r0 = 2, 3, 4, three seeds, d = 0.375, a = 2 and 5)
    give X_inf to 1e-9 (a least-squares fit of noise-free data) inside its interval and band (whose
    width is the size law's exponent's alone: the seeds agree), and no fitted p (three sizes); the
    r0 within 5 % solves |k| (d/r0) = 0.05 X_inf, the largest r0's mean is off by k (d/4) / X_inf; the laws are those of colsim.study.experimental_laws at each a
    (no Lajeunesse height above a = 0.74); the table and the figure are written."""
    from colsim.study.convergence import column_size_limit_markdown, column_size_limits
    from colsim.study.experimental_laws import lube_height, lube_runout
    from colsim.study.figures import column_size_limit_figure

    d, truth = 0.375, {"h": (0.9, -1.2), "runout": (3.5, -4.0)}
    runs = [analysis(a=a, r0=r0, seed=seed, mean_d=d, h=truth["h"][0] + truth["h"][1] * d / r0,
                     runout=truth["runout"][0] + truth["runout"][1] * d / r0)
            for a in (2.0, 5.0) for r0 in (2.0, 3.0, 4.0) for seed in (1, 2, 3)]
    limits = column_size_limits(runs_table({"column_size": runs}, 4.0), replicates=200)
    for a in (2.0, 5.0):
        h = limits.sel(aspect_ratio=a, measure="h_inf_over_r0")
        r = limits.sel(aspect_ratio=a, measure="runout_over_r0")
        assert float(h.limit) == pytest.approx(0.9, abs=1e-9)
        assert float(r.limit) == pytest.approx(3.5, abs=1e-9)
        assert float(r.limit_low) < 3.5 < float(r.limit_high) and np.isnan(float(r.fitted_exponent))
        line = 3.5 - 4.0 * limits.d_over_r0.values
        assert np.all(r.band_low.values <= line + 1e-9) and np.all(line - 1e-9 <= r.band_high.values)
        assert float(r.r0_for_5_percent) == pytest.approx(4.0 * d / (0.05 * 3.5))
        # X(4) / X_inf - 1, to pytest's default 1e-6 relative (the fit of exact data is good to 1e-9)
        assert float(r.largest_r0_off) == pytest.approx(-4.0 * d / 4.0 / 3.5)
        assert float(h.lube) == pytest.approx(float(lube_height(a)))
        assert float(r.lube) == pytest.approx(float(lube_runout(a)))
        assert np.isnan(float(h.lajeunesse))
    text = column_size_limit_markdown(limits)
    five = limits.sel(aspect_ratio=5.0, measure="runout_over_r0")
    assert (f"| 5 | runout_over_r0 | 3 | 4 | 3.500 [{float(five.limit_low):.3f}, {float(five.limit_high):.3f}] | - | "
            "3.578 | -2 % |") in text
    assert "| -10.7 % | 8.6 | 21 |" in text
    assert column_size_limit_figure(runs_table({"column_size": runs}, 4.0), limits, tmp_path / "f.png").stat().st_size > 0
    one_size = runs_table({"column_size": [analysis(r0=2.0, seed=s) for s in (1, 2)]}, 4.0)
    assert column_size_limits(one_size) is None
