"""colsim.study.channel: the fitted exponents of a channel study beside the channel laws', and the
run-outs' convergence in the box length. Runs made from exact power laws give their exponents to
rounding (1e-9: a least-squares fit of exact logarithms), and spreads are ratios of given numbers."""
import numpy as np
import pytest
import xarray as xr

from colsim.study import channel

DIMS = ("aspect_ratio", "mu_r", "seed")


def _summary(ratios, runout, height, mu_rs=(0.12, 0.15), seeds=(1, 2)):
    """A summary whose runs are runout(a, mu_r) and height(a, mu_r) at every seed."""
    grid = lambda f: np.array([[[f(a, m)] * len(seeds) for m in mu_rs] for a in ratios], dtype=float)
    return xr.Dataset({"runout_over_r0": (DIMS, grid(runout)), "h_inf_over_r0": (DIMS, grid(height))},
                      coords={"aspect_ratio": list(ratios), "mu_r": list(mu_rs), "seed": list(seeds)})


def test_exponents_of_exact_power_laws_over_each_regime():
    """Run-outs 2 a^0.65 above a = 2.8 (and 1.2 a below, left out of the fit), heights a^0.5 above
    1.15: the fitted exponents are 0.65 and 0.5, over 3 and 4 aspect ratios."""
    ratios = (0.5, 1.0, 2.0, 3.0, 4.0, 5.0)
    summary = _summary(ratios, lambda a, m: 1.2 * a if a < 2.8 else 2.0 * a ** 0.65,
                       lambda a, m: a if a < 1.15 else a ** 0.5)
    runout, used = channel.fitted_exponent(summary, "runout_over_r0", 0.12)
    assert runout == pytest.approx(0.65, abs=1e-9) and used == 3
    height, used = channel.fitted_exponent(summary, "h_inf_over_r0", 0.15)
    assert height == pytest.approx(0.5, abs=1e-9) and used == 4
    text = channel.exponents_markdown(summary)
    assert "| 0.12 | 0.65 (3) | 0.65 +- 0.05 | 0.9 +- 0.1 | 0.67 | 0.50 (4) | 0.5 | 0.4 |" in text


def test_an_exponent_needs_two_aspect_ratios_with_runs():
    summary = _summary((1.0, 3.0), lambda a, m: a, lambda a, m: a)
    value, used = channel.fitted_exponent(summary, "runout_over_r0", 0.12)
    assert np.isnan(value) and used == 1
    assert "| - (1) |" in channel.exponents_markdown(summary)


def test_a_column_that_stood_has_no_run_out_exponent():
    """Run-outs under one mean diameter (0.375 over L0 = 6: 0.0625) at a = 4 and 5 are left out of the
    fit: the column stood. With a = 3's alone, fewer than two a remain; the heights still fit."""
    ratios = (3.0, 4.0, 5.0)
    summary = _summary(ratios, lambda a, m: 0.5 if a == 3.0 else 0.06, lambda a, m: a ** 0.5)
    summary["mean_diameter"] = xr.full_like(summary.runout_over_r0, 0.375)
    summary.attrs["channel_length"] = 6.0
    value, used = channel.fitted_exponent(summary, "runout_over_r0", 0.12)
    assert np.isnan(value) and used == 1
    height, used = channel.fitted_exponent(summary, "h_inf_over_r0", 0.12)
    assert height == pytest.approx(0.5, abs=1e-9) and used == 3
    summary["runout_over_r0"] = summary.runout_over_r0 * 0 + 0.07     # a grain's length or more: kept
    assert channel.fitted_exponent(summary, "runout_over_r0", 0.12)[1] == 3


def test_length_convergence_is_the_spread_between_the_two_largest_lengths():
    """Run-outs 2.0, 2.2, 2.25 and 2.28 at L0 = 3, 4.5, 6, 8 (a = 1); 3.0, 3.3, 3.5, 3.9 (a = 3): the
    spreads are 0.03/2.28 and 0.4/3.9; the first is within 2 %, the second not."""
    values = {3.0: (2.0, 3.0), 4.5: (2.2, 3.3), 6.0: (2.25, 3.5), 8.0: (2.28, 3.9)}
    summaries = {length: _summary((1.0, 3.0), lambda a, m, v=v: v[0] if a == 1.0 else v[1], lambda a, m: a)
                 for length, v in values.items()}
    convergence = channel.length_convergence(summaries)
    assert convergence.channel_length.values.tolist() == [3.0, 4.5, 6.0, 8.0]
    spread = convergence.relative_spread.sel(mu_r=0.12)
    assert float(spread.sel(aspect_ratio=1.0)) == pytest.approx(0.03 / 2.28, rel=1e-12)
    assert float(spread.sel(aspect_ratio=3.0)) == pytest.approx(0.4 / 3.9, rel=1e-12)
    text = channel.length_convergence_markdown(convergence)
    assert "| 0.12 | 1 | 2.000 | 2.200 | 2.250 | 2.280 | 1.3 % | converged |" in text
    assert "| 0.12 | 3 | 3.000 | 3.300 | 3.500 | 3.900 | 10.3 % | above 2 % |" in text


def test_a_column_that_stood_has_no_spread_in_length():
    """At a = 1 the mean run-out at L0 = 6 is 0.05, under one mean diameter (0.375 / 6 = 0.0625): the
    column stood there, the table says so and gives no spread; a = 3 (2.0 and 2.02) has its 1 %."""
    def at(length, short):
        summary = _summary((1.0, 3.0), lambda a, m: short if a == 1.0 else 2.0 + length / 300, lambda a, m: a)
        summary["mean_diameter"] = xr.full_like(summary.runout_over_r0, 0.375)
        summary.attrs["channel_length"] = length
        return summary

    convergence = channel.length_convergence({3.0: at(3.0, 0.3), 6.0: at(6.0, 0.05)})
    assert convergence.stood.sel(mu_r=0.12).values.tolist() == [[0, 0], [1, 0]]
    assert np.isnan(float(convergence.relative_spread.sel(mu_r=0.12, aspect_ratio=1.0)))
    assert float(convergence.relative_spread.sel(mu_r=0.12, aspect_ratio=3.0)) == pytest.approx(0.01 / 2.02, rel=1e-12)
    text = channel.length_convergence_markdown(convergence)
    assert "| 0.12 | 1 | 0.300 | stood | - | - |" in text


def test_length_convergence_refuses_one_length_or_other_sweeps():
    one = _summary((1.0,), lambda a, m: a, lambda a, m: a)
    with pytest.raises(ValueError, match="two box lengths"):
        channel.length_convergence({3.0: one})
    with pytest.raises(ValueError, match="other aspect_ratio values"):
        channel.length_convergence({3.0: one, 6.0: _summary((2.0,), lambda a, m: a, lambda a, m: a)})
