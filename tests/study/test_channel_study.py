"""A channel study's summary, tables and figures compare its runs with the channel laws (Lube et al.
2005, Lajeunesse et al. 2005), where a cylinder study's compare with the 2004 laws; a summary holds
one geometry."""
import matplotlib
import numpy as np
import pytest
import xarray as xr

from colsim.study import experimental_laws as laws
from colsim.study.collect import collect_analyses
from colsim.study.figures import laws as law_figures
from colsim.study.markdown import lube_markdown, lube_rst

KEPT = []


def keep_figure(figure):
    """matplotlib's figure hook (rcParams figure.hooks): keep every figure pyplot makes."""
    KEPT.append(figure)


CHANNEL = {"geometry": "channel", "channel_length": 6.0, "channel_width": 2.0, "wall_mu": 0.577}


def _analysis(a: float, seed: int, **attrs) -> xr.Dataset:
    """A minimal analysis of one run whose results are the Lube et al. (2005) values at a (a run-out of
    3 between Lube's two regimes, where the law gives none)."""
    base = {"aspect_ratio": a, "mu_r": 0.12, "seed": seed, "mu": 0.577, "friction_law": "associated",
            "rolling_lever": "paper", "solver_backends": '{"apgd": 10}'}
    height, runout = laws.lube_2005_height(a), laws.lube_2005_runout(a)
    runout = 3.0 if np.isnan(runout) else runout
    return xr.Dataset({"h_inf_over_r0": ((), height, {"units": "1", "long_name": "H_inf/L0"}),
                       "runout_over_r0": ((), runout, {"units": "1", "long_name": "(L_inf - L0)/L0"})},
                      attrs={**base, **attrs})


def _channel_summary(ratios=(0.5, 1.0, 2.0, 3.0)):
    return collect_analyses([_analysis(a, s, **CHANNEL) for a in ratios for s in (1, 2)])


def test_a_channel_summary_says_its_geometry_and_carries_the_channel_not_a_radius():
    summary = _channel_summary()
    assert summary.attrs["geometry"] == "channel" and "r0" not in summary.attrs
    assert {k: summary.attrs[k] for k in ("channel_length", "channel_width", "wall_mu")} == \
        {"channel_length": 6.0, "channel_width": 2.0, "wall_mu": 0.577}
    cylinder = collect_analyses([_analysis(1.0, 1, r0=3.0)])
    assert "geometry" not in cylinder.attrs and cylinder.attrs["r0"] == 3.0   # as before channels existed


def test_a_summary_refuses_runs_of_two_geometries():
    with pytest.raises(ValueError, match="more than one geometry"):
        collect_analyses([_analysis(1.0, 1, **CHANNEL), _analysis(2.0, 1, r0=3.0)])


def test_the_channel_table_is_against_the_2005_laws():
    """Runs equal to Lube et al. (2005) read +0 % against it (a = 2 lies between Lube's two run-out
    regimes: no law, no error, "-"), and the Lajeunesse columns hold Lajeunesse et al. (2005)."""
    text = lube_markdown(_channel_summary())
    assert "nan" not in text
    # a = 1: height 1 (+0 %), run-out 1.2 (+0 %); Lajeunesse 2005: height 1 (a^(1/3)), run-out 1.8 (-33 %)
    assert "| 1 | 1.000 | 0.000 | 1.000 | +0 % | 1.200 | 0.000 | 1.200 | +0 % | 1.000 | +0 % | 1.800 | -33 % |" in text
    row = next(line for line in text.splitlines() if line.startswith("| 2 |"))
    assert row.split(" | ")[7:9] == ["-", "-"]   # Lube 2005's run-out and its error at a = 2: none
    assert "### Exponents against the channel laws" in text
    assert "Exponents" not in lube_markdown(collect_analyses([_analysis(1.0, 1, r0=3.0)]))
    rst = lube_rst(_channel_summary(), 0.12)
    assert "against Lube et al. (2005)" in rst and "2004" not in rst


def test_the_channel_law_figure_draws_the_channel_laws(tmp_path):
    KEPT.clear()
    with matplotlib.rc_context({"figure.hooks": ["test_channel_study:keep_figure"]}):
        path = law_figures.law_figure(_channel_summary(), "runout_over_r0", tmp_path / "runout.png")
    assert path.exists() and len(KEPT) == 1
    ax = KEPT[0].axes[0]
    names = [line.get_label() for line in ax.get_lines()]
    assert "Lube et al. (2005)" in names and "Lajeunesse et al. (2005)" in names
    assert not any("2004" in name for name in names)
    assert ax.get_xlabel() == "aspect ratio a = H0/L0" and "L0 = 6, W = 2" in ax.get_title()
    lube = ax.get_lines()[names.index("Lube et al. (2005)")]
    x, y = (np.asarray(v, dtype=float) for v in lube.get_data())
    gap = (x > 1.8) & (x < 2.8)
    assert gap.any() and np.isnan(y[gap]).all()   # nothing drawn between Lube's two regimes


def _channel_run(a: float, mu_r: float, seed: int):
    """(analysis, trajectory) of a channel run shaped as colsim writes them, with no r0 attribute:
    a deposit falling from H0 at the back wall to the floor at 3 L0, grains spread in 0 < x < L0."""
    length, h0 = CHANNEL["channel_length"], a * CHANNEL["channel_length"]
    attrs = {"aspect_ratio": a, "mu_r": mu_r, "seed": seed, "h0": h0, "mu": 0.577, **CHANNEL}
    bins = np.arange(0.25, 3 * length, 0.5)
    analysis = xr.Dataset({"deposit_height": ("radial_bin", np.clip(h0 - h0 * bins / (3 * length), 0, None)),
                           "front_position": ("time", np.linspace(0, 2, 5)),
                           "scaled_time": ("time", np.linspace(0, 4, 5))},
                          coords={"radial_bin": bins}, attrs=attrs)
    rng = np.random.default_rng(seed)
    start = np.c_[rng.uniform(0.25, length, 40), rng.uniform(-0.75, 0.75, 40), rng.uniform(0.25, h0, 40)]
    end = start * [2.0, 1.0, 0.5]
    trajectory = xr.Dataset({"position": (("time", "particle", "xyz"), np.stack([start, end])),
                             "radius": ("particle", np.full(40, 0.2)),
                             "initial_height": ("particle", start[:, 2]),
                             "scaled_time": ("time", [0.0, 4.0])}, attrs=attrs)
    return analysis, trajectory


def test_the_single_run_figures_measure_a_channel_along_it_in_box_lengths(tmp_path):
    """The deposit profile and the side view of channel runs (no r0) scale by L0 and say so; the side
    view starts at the back wall, x = 0."""
    from colsim.study.figures import runs as run_figures

    analysis, trajectory = _channel_run(2.0, 0.12, 1)
    KEPT.clear()
    with matplotlib.rc_context({"figure.hooks": ["test_channel_study:keep_figure"]}):
        run_figures.deposit_profile_figure([analysis], tmp_path / "profiles.png")
        run_figures.side_view_figure([trajectory], tmp_path / "side.png")
    profile, side = KEPT
    assert profile.axes[0].get_xlabel() == "x / L0" and profile.axes[0].get_ylabel() == "deposit height / L0"
    x, y = profile.axes[0].get_lines()[0].get_data()
    assert y[0] == pytest.approx(2.0, rel=0.05)    # H0/L0 = a = 2 at the back wall
    assert side.axes[0].get_xlim()[0] == 0.0 and side.axes[1].get_xlabel() == "x / L0"
