"""colsim.study.polygon: the rolling coefficient of a regular polygon (the paper's Eqs. 7-10)."""
from __future__ import annotations

import numpy as np
import pytest

from colsim.study.polygon import polygon_rolling_coefficient


def test_polygon_rolling_coefficient_matches_the_paper():
    assert polygon_rolling_coefficient(6) == pytest.approx(np.pi / 24, rel=1e-15)   # Eq. 10: 0.131
    assert round(polygon_rolling_coefficient(6), 3) == 0.131
    # more sides, rounder particle: mu_r falls like 1/N, both methods agree as N grows
    values = [polygon_rolling_coefficient(n) for n in (3, 4, 6, 12, 100)]
    assert all(a > b for a, b in zip(values, values[1:]))
    assert polygon_rolling_coefficient(1000, "exact") == pytest.approx(polygon_rolling_coefficient(1000), rel=1e-5)
    with pytest.raises(ValueError):
        polygon_rolling_coefficient(2)
