"""The analysis of a channel's deposit (colsim.stages.analyse with geometry "channel"): the run-out
along +x from the back wall by the connected cluster, the height at the back wall, fronts and
profiles along the channel, and a cylinder file without the attribute analysed as before.

Every deposit here is built by hand from spheres of radius R = 0.25, at positions that are exact
binary fractions, so the lengths measured are sums of exact numbers: they are compared to 1e-12,
rounding's room, not a method's error."""
from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from colsim.engine.state import ParticleState
from colsim.stages import analyse as analysis
from colsim.stages.settings import AnalysisSettings

R = 0.25
D = 2 * R
EXACT = 1e-12


def _line_along_x(y: float = 0.0):
    """A stack of three spheres against the back wall (centres at x = R), a line of touching spheres
    along x on the floor out to x = 9R, and a detached grain beyond it (its back edge 0.5 R past the
    line's front: a gap far above the contact tolerance)."""
    pos = [[R, y, R], [R, y, 3 * R], [R, y, 5 * R]]                  # the stack at the back wall
    pos += [[(2 * k + 1) * R, y, R] for k in range(1, 5)]            # x = 3R, 5R, 7R, 9R on the floor
    pos += [[11.5 * R, y, R]]                                        # detached, gap 0.5 R
    return ParticleState.at_rest(np.array(pos, float), np.full(len(pos), R))


def test_runout_is_the_front_of_the_connected_line_and_not_the_detached_grain():
    deposit = analysis.measure_deposit(_line_along_x(), tolerance=1e-6, geometry="channel")
    assert deposit.main_mass.tolist() == [True] * 7 + [False]
    assert deposit.r_inf == pytest.approx(10 * R, abs=EXACT)        # front of the sphere at x = 9R
    loose = analysis.measure_deposit(_line_along_x(), tolerance=0.5 * R + 1e-9, geometry="channel")
    assert loose.main_mass.all() and loose.r_inf == pytest.approx(12.5 * R, abs=EXACT)


def test_runout_is_measured_along_the_channel_not_from_an_axis():
    """Off the channel's centre line (y = 0.3) the cylinder's radial reach would grow with y; the
    channel's reach is x + R whatever y is."""
    state = _line_along_x(y=0.3)
    channel = analysis.measure_deposit(state, tolerance=1e-6, geometry="channel")
    cylinder = analysis.measure_deposit(state, tolerance=1e-6)
    assert channel.r_inf == pytest.approx(10 * R, abs=EXACT)
    assert cylinder.r_inf == pytest.approx(np.hypot(9 * R, 0.3) + R, abs=EXACT)


def test_height_at_the_back_wall_is_the_top_of_the_grains_next_to_it():
    """The main mass: a stack of three at the back wall (top 6R), a floor line, and a stack of five
    further out (top 10R). The height at the wall is 6R; the highest point, h_top, is 10R. A grain
    above the stack's top but not touching it (gap 0.125R) is not in the main mass: it does not
    raise the height at the wall."""
    pos = [[R, 0, R], [R, 0, 3 * R], [R, 0, 5 * R]]
    pos += [[(2 * k + 1) * R, 0, R] for k in range(1, 6)]            # floor line to x = 11R
    pos += [[11 * R, 0, (2 * k + 1) * R] for k in range(1, 5)]       # stack of five at x = 11R
    pos += [[R, 0, 7.125 * R]]                                         # loose grain above the wall stack
    state = ParticleState.at_rest(np.array(pos, float), np.full(len(pos), R))
    deposit = analysis.measure_deposit(state, tolerance=1e-6, geometry="channel")
    assert not deposit.main_mass[-1] and deposit.main_mass[:-1].all()
    assert deposit.h_inf == pytest.approx(6 * R, abs=EXACT)
    assert deposit.h_top == pytest.approx(10 * R, abs=EXACT)
    assert analysis.measure_deposit(state, tolerance=1e-6).h_inf == pytest.approx(10 * R, abs=EXACT)


def test_the_back_wall_band_is_one_mean_diameter_from_the_wall():
    """Two towers joined on the floor: one with its back edge exactly one mean diameter from the wall
    (x - R = D: inside the band), one 1e-9 beyond it (outside). All grains have the same radius, so the mean diameter is D."""
    tower = lambda x, n: [[x, 0, (2 * k + 1) * R] for k in range(n)]
    inside = ParticleState.at_rest(np.array(tower(R + D, 3) + [[R + 2 * D, 0, R]], float),
                                   np.full(4, R))
    assert analysis.height_at_back_wall(inside, np.ones(4, bool)) == pytest.approx(6 * R, abs=EXACT)
    outside = ParticleState.at_rest(np.array(tower(R + D + 1e-9, 3), float), np.full(3, R))
    assert analysis.height_at_back_wall(outside, np.ones(3, bool)) == 0.0


def test_mass_front_and_profile_follow_the_channel_axis():
    state = _line_along_x(y=0.3)
    # equal masses at reaches 2R (x3), 4R, 6R, 8R, 10R, 12.5R: half of the 8 grains within 4R
    assert analysis.mass_front(state, 0.5, "channel") == pytest.approx(4 * R, abs=EXACT)
    assert analysis.mass_front(state, 1.0, "channel") == pytest.approx(12.5 * R, abs=EXACT)
    mass = np.array([True] * 7 + [False])
    centres, height = analysis.deposit_profile(state, mass, D, 10 * R + D, "channel")
    # bins of width 2R from x = 0: the stack's centres (x = R) in the first, one floor grain per bin after
    np.testing.assert_allclose(centres[:5], [R, 3 * R, 5 * R, 7 * R, 9 * R], atol=EXACT)
    np.testing.assert_allclose(height[:5], [6 * R, 2 * R, 2 * R, 2 * R, 2 * R], atol=EXACT)
    assert np.isnan(height[5:]).all()


def _trajectory(state: ParticleState, attrs: dict) -> xr.Dataset:
    """A trajectory of two identical frames of `state` (a deposit at rest), laid out as
    colsim.io.trajectory.trajectory_dataset lays one out, with the attributes analyse reads."""
    frames = np.stack([state.position, state.position])
    zeros = np.zeros_like(frames)
    data = {"position": (("time", "particle", "xyz"), frames),
            "velocity": (("time", "particle", "xyz"), zeros),
            "angular_velocity": (("time", "particle", "xyz"), zeros),
            "radius": ("particle", state.radius),
            "step_kinetic_energy": ("step", [1.0, 0.0]), "step_rotational_energy": ("step", [0.0, 0.0])}
    coords = {"time": ("time", [0.0, 1.0]), "scaled_time": ("time", [0.0, 1.0]), "step": ("step", [1, 2])}
    base = {"h0": 1.2, "aspect_ratio": 1.5, "mu": 0.577, "mu_r": 0.12, "duration": 1.0, "n_steps": 2,
            "column_solid_fraction": 0.58, "wall_time": 1.0}
    return xr.Dataset(data, coords=coords, attrs={**base, **attrs})


CHANNEL = {"geometry": "channel", "channel_length": 4 * R, "channel_width": 0.5, "wall_mu": 0.3}


def test_a_channel_trajectory_is_normalised_by_the_box_length_and_says_its_geometry():
    result = analysis.analyse_trajectory(_trajectory(_line_along_x(), CHANNEL), AnalysisSettings(), {})
    assert result.attrs["geometry"] == "channel"
    assert {k: result.attrs[k] for k in ("channel_length", "channel_width", "wall_mu")} == \
        {"channel_length": 4 * R, "channel_width": 0.5, "wall_mu": 0.3}
    assert float(result.runout_over_r0) == pytest.approx((10 * R - 4 * R) / (4 * R), abs=EXACT)
    assert float(result.h_inf_over_r0) == pytest.approx(6 * R / (4 * R), abs=EXACT)
    assert float(result.h_top) == pytest.approx(6 * R, abs=EXACT)
    assert "L0" in result.runout_over_r0.attrs["long_name"]
    assert "back wall" in result.radial_bin.attrs["long_name"]
    np.testing.assert_allclose(result.front_position.values, 1.5, atol=EXACT)


def test_a_channel_file_without_its_length_or_with_an_unknown_geometry_is_refused():
    missing = {k: v for k, v in CHANNEL.items() if k != "channel_length"}
    with pytest.raises(ValueError, match="channel_length"):
        analysis.analyse_trajectory(_trajectory(_line_along_x(), missing), AnalysisSettings(), {})
    with pytest.raises(ValueError, match="channel_width"):
        analysis.analyse_trajectory(_trajectory(_line_along_x(), {k: v for k, v in CHANNEL.items()
                                                                  if k != "channel_width"}), AnalysisSettings(), {})
    with pytest.raises(ValueError, match="geometry 'sphere'"):
        analysis.analyse_trajectory(_trajectory(_line_along_x(), {"geometry": "sphere", "r0": 1.0}),
                                    AnalysisSettings(), {})


def test_a_cylinder_file_without_the_attribute_is_analysed_as_before():
    """A file without `geometry` is a cylinder: its analysis equals that of the same file saying
    "cylinder", measures from the axis (hypot) and divides by r0, with the long names it always had."""
    state = _line_along_x(y=0.3)
    old = analysis.analyse_trajectory(_trajectory(state, {"r0": 4 * R}), AnalysisSettings(), {})
    named = analysis.analyse_trajectory(_trajectory(state, {"r0": 4 * R, "geometry": "cylinder"}),
                                        AnalysisSettings(), {})
    xr.testing.assert_identical(old.drop_attrs(), named.drop_attrs())
    assert old.attrs["geometry"] == "cylinder" and "channel_length" not in old.attrs and "h_top" not in old
    reach = np.hypot(9 * R, 0.3) + R
    assert float(old.runout_over_r0) == pytest.approx((reach - 4 * R) / (4 * R), abs=EXACT)
    assert old.runout_over_r0.attrs["long_name"] == "run-out (r_inf - r0) over initial radius"
    assert old.radial_bin.attrs["long_name"] == "distance from the axis"
