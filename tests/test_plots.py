"""colsim.plots on small synthetic datasets shaped like colsim's files (no simulation needed)."""
import matplotlib
import numpy as np
import pytest
import xarray as xr
from matplotlib.container import ErrorbarContainer

from colsim import plots
from colsim.laws import LAWS
from colsim.summary import SUMMARY_VARIABLES

KEPT = []


def keep_figure(figure):
    """matplotlib's figure hook (rcParams figure.hooks): keep every figure pyplot makes."""
    KEPT.append(figure)

R0 = 2.0


def summary(ratios=(0.5, 1.0, 2.0), mu_rs=(0.0, 0.12), seeds=(1, 2), missing=True):
    rng = np.random.default_rng(0)
    shape = (len(ratios), len(mu_rs), len(seeds))
    data = {name: (("aspect_ratio", "mu_r", "seed"), rng.uniform(0.1, 2.0, shape),
                   {"units": "1", "long_name": name.replace("_", " ")}) for name in SUMMARY_VARIABLES}
    if missing and shape[0] > 1:
        data["h_inf_over_r0"][1][1, 0, :] = np.nan  # a run that is missing in every seed
    coords = {"aspect_ratio": list(ratios), "mu_r": list(mu_rs), "seed": list(seeds)}
    return xr.Dataset(data, coords=coords, attrs={"r0": R0, "mu": 0.577})


def analysis(a, mu_r, seed):
    bins = np.arange(0.25, 6.0, 0.5)
    attrs = {"aspect_ratio": a, "mu_r": mu_r, "seed": seed, "r0": R0, "h0": a * R0, "mu": 0.577}
    return xr.Dataset({
        "deposit_height": ("radial_bin", np.clip(a * R0 - 0.3 * bins, 0, None)),
        "front_position": ("time", np.linspace(0, a, 5)),
        "scaled_time": ("time", np.linspace(0, 4, 5)),
    }, coords={"radial_bin": bins}, attrs=attrs)


def trajectory(a, mu_r, seed, n=60):
    rng = np.random.default_rng(seed)
    h0 = a * R0
    start = np.c_[rng.uniform(-R0, R0, (n, 2)), rng.uniform(0.2, h0, n)]
    end = start * [1.5, 1.5, 0.5]
    return xr.Dataset({
        "position": (("time", "particle", "xyz"), np.stack([start, end])),
        "radius": ("particle", rng.uniform(0.125, 0.25, n)),
        "initial_height": ("particle", start[:, 2]),
        "scaled_time": ("time", [0.0, 4.0]),
    }, attrs={"aspect_ratio": a, "mu_r": mu_r, "seed": seed, "r0": R0, "h0": h0})


def test_all_figures_writes_every_png(tmp_path):
    analyses = [analysis(a, m, s) for a in (0.5, 1.0, 2.0) for m in (0.0, 0.12) for s in (1, 2)]
    trajectories = [trajectory(a, 0.12, 1) for a in (0.5, 1.0, 2.0)]
    paths = plots.all_figures(summary(), analyses, trajectories, tmp_path / "figures")
    assert [p.name for p in paths] == [f"{name}.png" for name in plots.FIGURES]
    for path in paths:
        assert path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert path.stat().st_size > 5000


def _drawn_figures(tmp_path, data, analyses, trajectories) -> dict:
    """{figure name: the matplotlib Figure all_figures drew for it} (kept by a figure hook)."""
    KEPT.clear()
    with matplotlib.rc_context({"figure.hooks": ["test_plots:keep_figure"]}):
        plots.all_figures(data, analyses, trajectories, tmp_path)
    assert len(KEPT) == len(plots.FIGURES)
    return dict(zip(plots.FIGURES, KEPT))


def _errorbars(ax) -> list:
    """(x, y) of the markers of each error-bar series of an axes, in drawing order."""
    return [c.lines[0].get_data() for c in ax.containers if isinstance(c, ErrorbarContainer)]


@pytest.mark.filterwarnings("ignore:Mean of empty slice")
def test_every_figure_plots_the_values_of_its_data(tmp_path):
    """Each figure's lines and markers hold the numbers of the data given (seed means where the
    figure averages), not merely some picture."""
    data = summary()
    analyses = [analysis(a, m, s) for a in (0.5, 1.0) for m in (0.0, 0.12) for s in (1, 2)]
    trajectories = [trajectory(a, 0.12, 1) for a in (0.5, 1.0)]
    figures = _drawn_figures(tmp_path, data, analyses, trajectories)

    for name, variable in (("final_height", "h_inf_over_r0"), ("runout", "runout_over_r0")):
        ax = figures[name].axes[0]
        series = _errorbars(ax)
        assert len(series) == data.sizes["mu_r"]
        for k, (x, y) in enumerate(series):
            expected = np.nanmean(data[variable].isel(mu_r=k).values, axis=-1)
            np.testing.assert_allclose(y, expected, equal_nan=True, err_msg=name)
            np.testing.assert_allclose(x - x[0], data.aspect_ratio.values - data.aspect_ratio.values[0])
        laws = {line.get_label(): line for line in ax.lines if line.get_label() in LAWS[variable]}
        assert set(laws) == set(LAWS[variable])
        for label, line in laws.items():
            a, y = line.get_data()
            np.testing.assert_allclose(y, LAWS[variable][label](a), equal_nan=True)

    for ax, variable in zip(figures["mu_r_effect"].axes, ("h_inf_over_r0", "runout_over_r0")):
        series = _errorbars(ax)
        assert len(series) == data.sizes["aspect_ratio"]
        for k, (x, y) in enumerate(series):
            np.testing.assert_allclose(x, data.mu_r.values)
            np.testing.assert_allclose(y, np.nanmean(data[variable].isel(aspect_ratio=k).values, axis=-1),
                                       equal_nan=True)

    profiles = figures["deposit_profiles"].axes
    for ax, a in zip(profiles, (0.5, 1.0)):
        steps = [line for line in ax.lines if line.get_drawstyle() == "steps-mid"]
        assert len(steps) == 2                                          # one per mu_r, lowest seed
        run = analysis(a, 0.0, 1)
        np.testing.assert_allclose(steps[0].get_xdata(), run.radial_bin.values / R0)
        np.testing.assert_allclose(steps[0].get_ydata(), run.deposit_height.values / R0)

    fronts = figures["front_position"].axes
    for ax in fronts[:2]:
        lines = ax.get_lines()
        assert len(lines) == 4                                          # two a times two seeds
        for line, (a, seed) in zip(lines, [(0.5, 1), (0.5, 2), (1.0, 1), (1.0, 2)]):
            np.testing.assert_allclose(line.get_xdata(), np.linspace(0, 4, 5))
            np.testing.assert_allclose(line.get_ydata(), np.linspace(0, a, 5))

    views = figures["side_views"].axes[:4]                              # 2 runs x (before, deposit)
    for ax, (run, frame) in zip(views, [(trajectories[0], 0), (trajectories[0], -1),
                                        (trajectories[1], 0), (trajectories[1], -1)]):
        x, z, r, colour = plots._slab(run, frame)
        (discs,) = ax.collections
        np.testing.assert_allclose(discs.get_offsets(), np.c_[x, z])
        np.testing.assert_allclose(discs.get_array(), colour)


def test_single_values_and_no_runs_still_plot(tmp_path):
    paths = plots.all_figures(summary((1.0,), (0.12,), (1,), missing=False), [], [], tmp_path)
    assert all(p.stat().st_size > 0 for p in paths)


def test_law_curves_break_at_the_breakpoints():
    a = plots._law_abscissa(5.0)
    assert np.isnan(a).sum() == 3
    assert np.nanmin(a) == 0.0 and np.nanmax(a) == 5.0


def test_seed_spread_ignores_missing_seeds():
    mean, low, high = plots._seed_spread([[1.0, 3.0, np.nan], [np.nan, np.nan, np.nan]])
    assert mean[0] == 2.0 and low[0] == 1.0 and high[0] == 1.0
    assert np.isnan(mean[1]) and low[1] == 0.0


def test_package_imports_without_matplotlib():
    import subprocess
    import sys

    code = ("import sys; sys.modules['matplotlib'] = None; import colsim, colsim.plots, colsim.laws; "
            "print('ok')")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip() == "ok"
