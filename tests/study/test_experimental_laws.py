"""The experimental laws of SPEC section 5: values on both sides of every breakpoint, shapes, range."""
import numpy as np
import pytest

from colsim.study import experimental_laws as laws


@pytest.mark.parametrize("law, a, expected", [
    (laws.lube_runout, 0.0, 0.0),
    (laws.lube_runout, 1.0, 1.24),
    (laws.lube_runout, 1.7 - 1e-12, 1.24 * 1.7),
    (laws.lube_runout, 1.7, 1.6 * np.sqrt(1.7)),
    (laws.lube_runout, 4.0, 3.2),
    (laws.lube_height, 0.5, 0.5),
    (laws.lube_height, 1.0 - 1e-12, 1.0),
    (laws.lube_height, 1.0, 0.88),
    (laws.lube_height, 9.0, 0.88 * 9.0 ** (1 / 6)),
    (laws.lajeunesse_runout, 0.5, 0.675),
    (laws.lajeunesse_runout, 0.74 - 1e-12, 1.35 * 0.74),
    (laws.lajeunesse_runout, 0.74, 2.0 * np.sqrt(0.74)),
    (laws.lajeunesse_runout, 4.0, 4.0),
    (laws.lajeunesse_height, 0.5, 0.5),
    (laws.lajeunesse_height, 0.74 - 1e-12, 0.74),
    (laws.lajeunesse_height, 0.74, 0.74 * 0.74),
    (laws.lajeunesse_height, 2.0, 1.48),
])
def test_values_at_and_around_breakpoints(law, a, expected):
    assert law(a) == pytest.approx(expected, rel=1e-9, abs=1e-9)
    assert isinstance(law(a), float)


@pytest.mark.parametrize("law", [laws.lube_runout, laws.lube_height, laws.lajeunesse_runout, laws.lajeunesse_height])
def test_vectorised_and_nan_outside_the_measured_range(law):
    a = np.array([[0.5, 1.0], [2.0, 5.0]])
    values = law(a)
    assert values.shape == a.shape
    np.testing.assert_allclose(values, [[law(0.5), law(1.0)], [law(2.0), law(5.0)]])
    assert np.isnan(law(-0.1)) and np.isnan(law(10.0)) and np.isnan(law(np.nan))
    assert np.all(np.isfinite(law(np.linspace(0, 9.99, 50))))


@pytest.mark.parametrize("law, brk", [(laws.lube_runout, 1.7), (laws.lube_height, 1.0),
                                       (laws.lajeunesse_runout, 0.74), (laws.lajeunesse_height, 0.74)])
def test_laws_increase_on_each_side_of_their_breakpoint(law, brk):
    for a in (np.linspace(0.01, brk - 1e-9, 200), np.linspace(brk, 9.99, 200)):
        assert np.all(np.diff(law(a)) > 0)


def test_laws_are_indexed_by_summary_variable():
    assert set(laws.LAWS) == {"runout_over_r0", "h_inf_over_r0"}
    assert laws.LAWS["h_inf_over_r0"]["Lube et al. (2004)"] is laws.lube_height
