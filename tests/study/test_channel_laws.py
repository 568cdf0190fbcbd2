"""The channel (quasi-two-dimensional) laws of colsim.study.experimental_laws: each law's value at
its stated break points and where its coefficients give an exact number, the gap Lube et al. (2005)
leave between their regimes, NaN outside 0 <= a < 10 as the cylinder's laws, Balmforth &
Kerswell's exponents, and the fitted exponent a comparison uses. Values are closed-form numbers of
the coefficients, so they are compared to rounding (1e-12)."""
import numpy as np
import pytest

from colsim.study import experimental_laws as laws

EXACT = dict(rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("law, a, expected", [
    (laws.lube_2005_runout, 1.0, 1.2),
    (laws.lube_2005_runout, 1.8 - 1e-12, 1.2 * 1.8),
    (laws.lube_2005_runout, 2.8, 1.9 * 2.8 ** (2 / 3)),
    (laws.lube_2005_runout, 8.0, 1.9 * 4.0),              # 8^(2/3) = 4
    (laws.lube_2005_height, 1.0, 1.0),
    (laws.lube_2005_height, 1.15 - 1e-12, 1.15),
    (laws.lube_2005_height, 1.15, 1.15 ** 0.4),
    (laws.lube_2005_height, 2.0 ** 2.5, 2.0),              # (2^2.5)^0.4 = 2
    (laws.lajeunesse_2005_runout, 1.0, 1.8),
    (laws.lajeunesse_2005_runout, 3.0 - 1e-12, 5.4),
    (laws.lajeunesse_2005_runout, 3.0, 2.3 * 3.0 ** (2 / 3)),
    (laws.lajeunesse_2005_runout, 8.0, 9.2),
    (laws.lajeunesse_2005_height, 0.5, 0.5),
    (laws.lajeunesse_2005_height, 0.7, 0.7 ** (1 / 3)),
    (laws.lajeunesse_2005_height, 8.0, 2.0),
])
def test_values_at_break_points_and_from_the_coefficients(law, a, expected):
    assert law(a) == pytest.approx(expected, **EXACT)
    assert isinstance(law(a), float)


def test_lube_2005_gives_no_run_out_between_its_two_regimes():
    """The linear regime holds below a = 1.8 and the power law from 2.8: in between, no value."""
    assert np.isnan(laws.lube_2005_runout(np.array([1.8, 2.3, 2.8 - 1e-9]))).all()
    assert np.isfinite(laws.lube_2005_runout(np.array([1.8 - 1e-9, 2.8]))).all()


@pytest.mark.parametrize("law", [laws.lube_2005_runout, laws.lube_2005_height, laws.lajeunesse_2005_runout,
                                 laws.lajeunesse_2005_height])
def test_nan_outside_the_range_and_vectorised_as_the_cylinder_laws(law):
    assert np.isnan(law(-0.1)) and np.isnan(law(10.0)) and np.isnan(law(np.nan))
    a = np.array([[0.5, 1.0], [3.0, 5.0]])
    np.testing.assert_allclose(law(a), [[law(0.5), law(1.0)], [law(3.0), law(5.0)]])


def test_each_power_branch_has_its_stated_exponent():
    """The log-log slope of each law's upper branch is its exponent, exactly (two points suffice)."""
    a = np.array([4.0, 9.0])
    for law, exponent in ((laws.lube_2005_runout, 2 / 3), (laws.lajeunesse_2005_runout, 2 / 3),
                          (laws.lube_2005_height, 0.4), (laws.lajeunesse_2005_height, 1 / 3)):
        assert laws.power_law_exponent(a, law(a)) == pytest.approx(exponent, **EXACT)


def test_power_law_exponent_skips_what_it_cannot_fit():
    assert laws.power_law_exponent([1, 2, 4, np.nan], [3, 6, 12, 7]) == pytest.approx(1.0, **EXACT)
    assert np.isnan(laws.power_law_exponent([2, 2], [1, 3]))
    assert np.isnan(laws.power_law_exponent([1, 2], [0.0, -1.0]))


def test_balmforth_kerswell_exponents_as_their_abstract_states_them():
    """(l - L)/L ~ a^(0.9 +- 0.1) wide, a^(0.65 +- 0.05) narrow; H/h ~ a^0.6 wide, a^0.5 narrow, so
    h/L = (H/L)/(H/h) ~ a^(1 - 0.6) and a^(1 - 0.5)."""
    bk = laws.BALMFORTH_KERSWELL
    assert bk["wide"]["runout_over_r0"] == (0.9, 0.1) and bk["narrow"]["runout_over_r0"] == (0.65, 0.05)
    assert bk["wide"]["h_inf_over_r0"][0] == pytest.approx(1 - 0.6) and bk["narrow"]["h_inf_over_r0"][0] == 0.5


def test_laws_for_picks_the_geometry_and_refuses_another():
    assert laws.laws_for("cylinder") is laws.LAWS and laws.laws_for("channel") is laws.CHANNEL_LAWS
    assert set(laws.CHANNEL_LAWS) == set(laws.LAWS)
    with pytest.raises(ValueError, match="geometry 'sphere'"):
        laws.laws_for("sphere")


def test_final_values_drop_a_height_above_the_initial_one_in_a_channel():
    """Lajeunesse's 2005 height as printed, a^(1/3), is above a for 0.7 <= a < 1: no final value there."""
    at_0_8 = laws.final_values("h_inf_over_r0", 0.8, "channel")
    assert np.isnan(at_0_8["Lajeunesse et al. (2005)"]) and at_0_8["Lube et al. (2005)"] == pytest.approx(0.8)
    assert laws.final_values("h_inf_over_r0", 2.0, "channel")["Lajeunesse et al. (2005)"] == \
        pytest.approx(2 ** (1 / 3), **EXACT)
    assert laws.final_values("runout_over_r0", 2.0) == {"Lube et al. (2004)": laws.lube_runout(2.0),
                                                        "Lajeunesse et al. (2004)": laws.lajeunesse_runout(2.0)}
