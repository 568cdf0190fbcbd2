"""colsim.study.size_limit on synthetic data whose limit is known."""
import numpy as np
import pytest

from colsim.study.size_limit import choose_fit, fit_limit, size_limit

D = 0.375                            # mean diameter of the study's spheres (0.25-0.5)
R0 = np.array([2.0, 3.0, 4.0, 5.0, 6.0])


def synthetic(x_inf, k, p, noise, seeds=3, seed=1):
    """{r0: seed values} of x_inf + k (d/r0)^p plus Gaussian noise of standard deviation `noise`."""
    rng = np.random.default_rng(seed)
    return {r0: x_inf + k * (D / r0) ** p + noise * rng.standard_normal(seeds) for r0 in R0}


def flat(runs):
    x = np.concatenate([np.full(len(v), D / r0) for r0, v in runs.items()])
    return x, np.concatenate(list(runs.values()))


def test_exact_data_give_the_limit_to_rounding():
    """Noise-free data: the p = 1 fit returns x_inf and k to 1e-12 (linear least squares is exact);
    with p = 2 the fitted exponent returns them to the bounded search's tolerance."""
    fit = fit_limit(*flat(synthetic(3.2, -4.0, 1.0, 0.0, seeds=1)), p=1.0)
    assert fit.x_inf == pytest.approx(3.2, abs=1e-12) and fit.k == pytest.approx(-4.0, abs=1e-11)
    free = fit_limit(*flat(synthetic(3.2, -4.0, 2.0, 0.0, seeds=1)), p=None)
    assert free.p == pytest.approx(2.0, abs=1e-4) and free.x_inf == pytest.approx(3.2, abs=1e-5)


def test_the_criterion_keeps_p_1_unless_the_data_ask_for_another():
    """p = 1 data with noise: the fixed exponent is kept; clean p = 2.5 data: the free one is chosen."""
    assert not choose_fit(*flat(synthetic(1.0, 2.0, 1.0, 0.01))).p_fitted
    chosen = choose_fit(*flat(synthetic(1.0, 2.0, 2.5, 1e-4)))
    assert chosen.p_fitted and chosen.p == pytest.approx(2.5, abs=0.05)


def test_the_bootstrap_interval_holds_the_true_limit_at_its_rate():
    """Over 40 synthetic studies (3 seeds, noise 0.03 on values near 1.5) the 90 % interval holds the
    true limit in 30 or more (binomial: P(fewer than 30 of 40 | 0.9) = 0.15 %), and ten times less
    noise at least halves the interval (not tenfold: which model the criterion picks varies between
    replicates, and the free exponent extrapolates more widely)."""
    hits, widths = 0, []
    for seed in range(40):
        limit = size_limit(synthetic(1.5, -2.0, 1.0, 0.03, seed=seed), D, replicates=300, level=0.9, seed=seed)
        hits += limit.low <= 1.5 <= limit.high
        widths.append(limit.high - limit.low)
    assert hits >= 30, hits
    quiet = size_limit(synthetic(1.5, -2.0, 1.0, 0.003, seed=0), D, replicates=300, level=0.9)
    assert quiet.high - quiet.low < np.median(widths) / 2


def test_the_band_and_the_p_1_interval_come_from_the_same_replicates():
    """The band at d/r0 = 0 is the interval of X_inf (percentiles of the same numbers, to rounding);
    with three sizes p is never fitted, so the interval at p = 1 is the interval; with five sizes
    and p = 2.5 data the free p is chosen in most replicates, and the p = 1 interval (a straight
    line through a curve) misses the true limit while the chosen one holds it."""
    three = size_limit({r0: v for r0, v in synthetic(1.5, -2.0, 1.0, 0.03).items() if r0 <= 4}, D, replicates=300)
    assert three.free_share == 0.0
    assert (three.linear_low, three.linear_high) == (three.low, three.high)
    low, high = three.band(np.array([0.0, 0.1, 0.2]))
    assert low[0] == pytest.approx(three.low, abs=1e-12) and high[0] == pytest.approx(three.high, abs=1e-12)
    assert np.all(low <= high) and three.replicate_fits.shape == (300, 3)
    curved = size_limit(synthetic(1.0, 2.0, 2.5, 1e-4), D, replicates=300)
    assert curved.free_share > 0.5
    assert curved.low <= 1.0 <= curved.high
    assert not curved.linear_low <= 1.0 <= curved.linear_high


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="at least 2 column sizes"):
        fit_limit([0.1, 0.1], [1.0, 1.1])
    with pytest.raises(ValueError, match="at least 4 column sizes"):
        fit_limit([0.1, 0.2, 0.3], [1.0, 1.1, 1.2], p=None)
    with pytest.raises(ValueError, match="finite"):
        fit_limit([0.1, 0.2], [1.0, np.nan])
