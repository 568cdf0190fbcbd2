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
