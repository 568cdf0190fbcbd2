"""colsim.study.seed_design against the least-squares algebra it rests on."""
import numpy as np
import pytest

from colsim.study.seed_design import best_seeds, limit_variance

D = 0.375
RADII = [2.0, 3.0, 4.0]


def test_two_sizes_one_seed_each_give_the_line_through_two_points():
    """X_inf = (x2 X1 - x1 X2)/(x2 - x1) for one run at each of two sizes x = d/r0: its variance is
    sigma^2 (x1^2 + x2^2)/(x2 - x1)^2 (to rounding)."""
    x1, x2 = D / 2, D / 4
    expected = 0.03**2 * (x1**2 + x2**2) / (x2 - x1) ** 2
    assert limit_variance([2.0, 4.0], [1, 1], [0.03, 0.03], D) == pytest.approx(expected, rel=1e-12)


def test_variance_falls_as_one_over_the_seeds_and_grows_with_a_sizes_spread():
    """Doubling every size's seeds halves the variance; more spread at one size raises it."""
    three = limit_variance(RADII, [3, 3, 3], [0.03] * 3, D)
    assert limit_variance(RADII, [6, 6, 6], [0.03] * 3, D) == pytest.approx(three / 2, rel=1e-12)
    assert limit_variance(RADII, [3, 3, 3], [0.06, 0.03, 0.03], D) > three


def test_cheap_small_columns_get_the_most_seeds():
    """With the calibration's costs a seed (r0 = 2, 3, 4: 151, 955 and 3,426 s of CPU with its pour
    shared by three mu_r; docs/validation/calibration.md) the best design puts the most seeds at
    r0 = 2 whether the spread is the same at every size or falls as 1/r0; with equal costs and
    spreads, scaling every n leaves Var x cost unchanged, so the ties include the uniform designs."""
    cost = [151.0, 955.0, 3426.0]
    for spread in ([0.03] * 3, [0.03 * 2 / r for r in RADII]):
        (_, best), *_ = best_seeds(RADII, cost, spread, D)
        assert best == (5, 2, 2)
    scored = dict((n, v) for v, n in best_seeds(RADII, [1.0] * 3, [0.03] * 3, D))
    assert scored[(2, 2, 2)] == pytest.approx(scored[(4, 4, 4)], rel=1e-12)


def test_bad_designs_are_refused():
    with pytest.raises(ValueError, match="two radii"):
        limit_variance([2.0], [3], [0.03], D)
    with pytest.raises(ValueError, match="at least one seed"):
        limit_variance(RADII, [3, 0, 3], [0.03] * 3, D)
