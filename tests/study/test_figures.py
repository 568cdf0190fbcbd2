"""colsim.study.figures on small synthetic datasets shaped like colsim's files (no simulation needed)."""
import json

import matplotlib
import numpy as np
import pytest
import xarray as xr
from matplotlib.container import ErrorbarContainer

from colsim.study import figures
from colsim.study.figures import laws, runs, style
from colsim.study.experimental_laws import LAWS
from colsim.study.collect import SUMMARY_VARIABLES

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
    paths = figures.all_figures(summary(), analyses, trajectories, tmp_path / "figures")
    assert [p.name for p in paths] == [f"{name}.png" for name in figures.FIGURES]
    for path in paths:
        assert path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert path.stat().st_size > 5000


def _drawn_figures(tmp_path, data, analyses, trajectories) -> dict:
    """{figure name: the matplotlib Figure all_figures drew for it} (kept by a figure hook)."""
    KEPT.clear()
    with matplotlib.rc_context({"figure.hooks": ["test_figures:keep_figure"]}):
        figures.all_figures(data, analyses, trajectories, tmp_path)
    assert len(KEPT) == len(figures.FIGURES)
    return dict(zip(figures.FIGURES, KEPT))


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
        steps = [line for line in ax.lines if line.get_drawstyle() == "steps-post"]
        assert len(steps) == 2                                          # one per mu_r, lowest seed
        run = analysis(a, 0.0, 1)                                       # bins 0-0.5, 0.5-1, ...
        np.testing.assert_allclose(steps[0].get_xdata(), np.arange(0.0, 6.25, 0.5) / R0)
        np.testing.assert_allclose(steps[0].get_ydata()[:-1], run.deposit_height.values / R0)

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
        x, z, r, colour = runs._slab(run, frame)
        (discs,) = ax.collections
        np.testing.assert_allclose(discs.get_offsets(), np.c_[x, z])
        np.testing.assert_allclose(discs.get_array(), colour)


def test_single_values_and_no_runs_still_plot(tmp_path):
    paths = figures.all_figures(summary((1.0,), (0.12,), (1,), missing=False), [], [], tmp_path)
    assert all(p.stat().st_size > 0 for p in paths)


def test_law_curves_break_at_the_breakpoints():
    a = laws._law_abscissa(5.0)
    assert np.isnan(a).sum() == 3
    assert np.nanmin(a) == 0.0 and np.nanmax(a) == 5.0


def test_seed_spread_ignores_missing_seeds():
    mean, low, high = style._seed_spread([[1.0, 3.0, np.nan], [np.nan, np.nan, np.nan]])
    assert mean[0] == 2.0 and low[0] == 1.0 and high[0] == 1.0
    assert np.isnan(mean[1]) and low[1] == 0.0


def test_package_imports_without_matplotlib():
    import subprocess
    import sys

    code = ("import sys; sys.modules['matplotlib'] = None; import colsim, colsim.study.figures, colsim.study.experimental_laws; "
            "print('ok')")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True).stdout.strip() == "ok"


def _bar_lengths(ax) -> list:
    """(lower, upper) error of every marker of each error-bar series of an axes, in drawing order."""
    lengths = []
    for container in (c for c in ax.containers if isinstance(c, ErrorbarContainer)):
        _, y = container.lines[0].get_data()
        segments = container.lines[2][0].get_segments()
        lengths.append([(yk - seg[0][1], seg[1][1] - yk) for yk, seg in zip(y, segments)])
    return lengths


def _legend_texts(figure) -> list:
    legends = [ax.get_legend() for ax in figure.axes if ax.get_legend()] + list(figure.legends)
    return [text.get_text() for legend in legends for text in [legend.get_title(), *legend.get_texts()]]


def settled(ratios=(0.5, 1.0, 2.0), mu_rs=(0.0, 0.12), seeds=(1, 2)):
    """summary() with every run at rest and a whole main mass (nothing flagged)."""
    data = summary(ratios, mu_rs, seeds, missing=False)
    data["final_to_peak_kinetic_energy"][:] = 1e-4
    data["n_particles"][:] = 100.0
    data["n_main_mass"][:] = 90.0
    return data


@pytest.mark.parametrize("seeds", [(1, 2), (1, 2, 3)])
def test_error_bars_are_the_range_below_three_seeds_and_the_standard_error_from_three(tmp_path, seeds):
    data = settled(seeds=seeds)
    figures = _drawn_figures(tmp_path, data, [], [])
    standard_error = len(seeds) >= 3
    for name, variable in (("final_height", "h_inf_over_r0"), ("runout", "runout_over_r0")):
        ax = figures[name].axes[0]
        for k, bars in enumerate(_bar_lengths(ax)):
            values = data[variable].isel(mu_r=k).values
            mean = values.mean(axis=-1)
            if standard_error:
                expected = np.c_[[values.std(axis=-1, ddof=1) / np.sqrt(len(seeds))] * 2].T
            else:
                expected = np.c_[mean - values.min(axis=-1), values.max(axis=-1) - mean]
            np.testing.assert_allclose(bars, expected, rtol=1e-9, err_msg=name)
        note = ax.get_legend().get_title().get_text()
        assert note == (f"mean of {len(seeds)} seeds, bars: standard error" if standard_error
                        else f"mean of {len(seeds)} seeds, bars: lowest to highest seed")
    assert any("standard error" in t if standard_error else "lowest to highest" in t
               for t in _legend_texts(figures["mu_r_effect"]))
    kind = style._bar_kind(data.h_inf_over_r0.values)
    assert kind == ("se", 3, 3) if standard_error else kind == ("range", 2, 2)


def test_bars_are_the_range_when_any_point_has_fewer_than_three_seeds():
    values = np.array([[1.0, 2.0, 3.0], [1.0, 3.0, np.nan]])
    assert style._bar_kind(values) == ("range", 2, 3)
    mean, low, high = style._bars(values[:1], "se")
    assert mean[0] == 2.0 and low[0] == high[0] == pytest.approx(1.0 / np.sqrt(3))


def test_moving_and_fragment_runs_are_drawn_apart_with_legend_entries(tmp_path):
    data = settled()
    data["at_rest"] = xr.full_like(data.h_inf_over_r0, 1.0)
    data["at_rest"][0, 0, 1] = 0.0                                   # a = 0.5, mu_r = 0: seed 2 still moving
    data["n_main_mass"][2, 1, 0] = 3.0                               # a = 2, mu_r = 0.12: 3 of 100 grains
    figures = _drawn_figures(tmp_path, data, [], [])
    for name, variable in (("final_height", "h_inf_over_r0"), ("runout", "runout_over_r0")):
        ax = figures[name].axes[0]
        (x, y), (x2, y2) = _errorbars(ax)
        opened = [line for line in ax.lines if line.get_label() == "_flag moving"]
        crossed = [line for line in ax.lines if line.get_label() == "_flag fragment"]
        assert len(opened) == 1 and len(crossed) == 1
        np.testing.assert_allclose(opened[0].get_data(), [[x[0]], [y[0]]])
        assert opened[0].get_markerfacecolor() == "white"
        np.testing.assert_allclose(crossed[0].get_data(), [[x2[2]], [y2[2]]])
        assert crossed[0].get_marker() == "x"
        texts = _legend_texts(figures[name])
        assert "open: a seed still moving at the end" in texts
        assert "cross: a seed's main mass < half the grains" in texts
    texts = _legend_texts(figures["mu_r_effect"])
    assert "open: a seed still moving at the end" in texts and "cross: a seed's main mass < half the grains" in texts
    ax = figures["mu_r_effect"].axes[0]
    assert [line.get_data() for line in ax.lines if line.get_label() == "_flag moving"] == [([0.0], [pytest.approx(
        data.h_inf_over_r0.isel(aspect_ratio=0, mu_r=0).mean())])]


def test_nothing_is_flagged_when_every_run_settled(tmp_path):
    figures = _drawn_figures(tmp_path, settled(), [], [])
    for figure in figures.values():
        assert not any(line.get_label().startswith("_flag") for ax in figure.axes for line in ax.lines)
        assert not any(t.startswith(("open:", "cross:")) for t in _legend_texts(figure))


def test_a_law_that_would_squeeze_the_data_leaves_the_frame_with_a_note(tmp_path):
    """Lajeunesse's height law as printed (0.74 a, 4.1 at a = 5.5) is not allowed to push heights of
    about 1 into the bottom quarter; the run-out laws, of the data's size, stay in the frame."""
    ratios = (0.5, 1.0, 2.0, 3.0, 5.5)
    data = settled(ratios=ratios)
    data["h_inf_over_r0"][:] = np.minimum(np.array(ratios), 1.05)[:, None, None]
    data["runout_over_r0"][:] = 1.5 * np.sqrt(np.array(ratios))[:, None, None]
    figures = _drawn_figures(tmp_path, data, [], [])
    ax = figures["final_height"].axes[0]
    bottom, top = ax.get_ylim()
    assert bottom == 0 and 1.17 < top < 1.4                          # Lube's 0.88 a^(1/6) reaches 1.19
    (note,) = [t.get_text() for t in ax.texts]
    assert note.startswith("The law of Lajeunesse et al. (2004) leaves the frame above a = 1.7")
    ax = figures["runout"].axes[0]
    assert not ax.texts and ax.get_ylim()[1] >= np.nanmax(LAWS["runout_over_r0"]["Lajeunesse et al. (2004)"](
        ax.lines[1].get_xdata()))


def test_mu_r_effect_has_lube_lines_a_readable_palette_and_one_legend(tmp_path):
    data = settled(ratios=(0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0))
    figure = _drawn_figures(tmp_path, data, [], [])["mu_r_effect"]
    for ax, variable in zip(figure.axes, ("h_inf_over_r0", "runout_over_r0")):
        bars = [c.lines[0] for c in ax.containers if isinstance(c, ErrorbarContainer)]
        for a, line in zip(data.aspect_ratio.values, bars):
            (lube,) = [law for law in ax.lines if law.get_label() == f"Lube et al. (2004), a = {a:g}"]
            np.testing.assert_allclose(lube.get_ydata(), LAWS[variable]["Lube et al. (2004)"](a))
            assert lube.get_color() == line.get_color() and lube.get_linestyle() == "--"
            r, g, b = matplotlib.colors.to_rgb(line.get_color())
            assert 0.299 * r + 0.587 * g + 0.114 * b < 0.75               # no pale yellow on white
        assert ax.get_legend() is None
    (legend,) = figure.legends
    texts = [t.get_text() for t in legend.get_texts()]
    assert [t for t in texts if t.startswith("a = ")] == [f"a = {a:g}" for a in data.aspect_ratio.values]
    assert any(t.startswith("Lube et al. (2004)") for t in texts)


def test_front_only_moves_outward(tmp_path):
    """The main mass's edge can recede (the largest cluster loses grains): the figure draws the
    farthest reach so far, and marks the final main mass's edge apart."""
    run = analysis(1.0, 0.12, 1)
    receding = np.array([0.0, 0.4, 0.9, 0.3, -0.28])
    run["front_position"] = ("time", receding)
    figure = _drawn_figures(tmp_path, settled(), [run], [])["front_position"]
    ax = figure.axes[0]
    (front,) = [line for line in ax.get_lines() if line.get_gid() != "end"]
    np.testing.assert_allclose(front.get_ydata(), [0.0, 0.4, 0.9, 0.9, 0.9])
    assert np.all(np.diff(front.get_ydata()) >= 0)
    (end,) = [line for line in ax.get_lines() if line.get_gid() == "end"]
    np.testing.assert_allclose(end.get_data(), [[4.0], [-0.28]])
    assert "farthest reach" in ax.get_ylabel()
    np.testing.assert_allclose(runs.outward_front([np.nan, 1.0, np.nan, 0.5, 2.0]), [np.nan, 1.0, 1.0, 1.0, 2.0])


def test_front_figure_draws_the_mass_share_front_above_the_main_mass_edge(tmp_path):
    """With the analyses' mass_front_95_over_r0 (issue 32, item 3): a top row of it as measured, frame
    by frame (one line per run, its values exactly), above the main mass's edge as before; an
    analysis made before the variable existed is drawn in the bottom row only."""
    from colsim.stages.analyse import FRONT_MASS_VARIABLE

    runs = [analysis(a, m, 1) for a in (0.5, 2.0) for m in (0.0, 0.12)]
    for run in runs:
        run[FRONT_MASS_VARIABLE] = ("time", np.linspace(0, 1.5 * run.attrs["aspect_ratio"], 5))
    older = analysis(1.0, 0.12, 1)                          # no mass front: bottom row only
    figure = _drawn_figures(tmp_path, settled(), runs + [older], [])["front_position"]
    top, bottom = figure.axes[:2], figure.axes[2:4]
    assert len(figure.axes) == 4                            # 2 rows x 2 mu_r
    for ax, m in zip(top, (0.0, 0.12)):
        assert "95%" in ax.get_ylabel() and f"= {m:g}" in ax.get_title()
        lines = ax.get_lines()
        assert len(lines) == 2                              # a = 0.5, 2; the older run has none
        for line, a in zip(lines, (0.5, 2.0)):
            np.testing.assert_allclose(line.get_ydata(), np.linspace(0, 1.5 * a, 5))
    assert [len(ax.get_lines()) for ax in bottom] == [2, 3]  # the older run at mu_r = 0.12 too
    for ax in bottom:
        assert "farthest reach" in ax.get_ylabel() and ax.get_xlabel() == "t / sqrt(h0/g)"


def test_a_channels_fronts_are_labelled_along_the_channel(tmp_path):
    """Issue 82: a channel's front figure names x from the back wall, L0 and H0, not the cylinder's
    r, r0 and h0."""
    channel = [analysis(a, 0.12, 1) for a in (0.5, 2.0)]
    for run in channel:
        run.attrs.update(geometry="channel", channel_length=R0, channel_width=2.0)
    KEPT.clear()
    with matplotlib.rc_context({"figure.hooks": ["test_figures:keep_figure"]}):
        runs.front_figure(channel, tmp_path / "front.png")
    [figure] = KEPT
    labels = [ax.get_ylabel() for ax in figure.axes] + [figure.axes[-1].get_xlabel()]
    assert labels == ["front (x_front - L0) / L0\n(farthest reach of the main mass so far)", "t / sqrt(H0/g)"]


def test_front_panels_share_one_y_scale_across_mu_r(tmp_path):
    """Issue 48.6: the front reaches 3 at mu_r = 0 and 1 at mu_r = 0.12; both panels span the same
    y range, so the figure compares mu_r at a glance."""
    runs = [analysis(1.0, m, 1) for m in (0.0, 0.12)]
    for run, reach in zip(runs, (3.0, 1.0)):
        run["front_position"] = ("time", np.linspace(0.0, reach, 5))
    axes = _drawn_figures(tmp_path, settled(), runs, [])["front_position"].axes
    assert axes[0].get_ylim() == axes[1].get_ylim() and axes[1].get_ylim()[1] > 3.0


def test_deposit_profile_starts_with_the_bin_at_the_axis(tmp_path):
    run = analysis(1.0, 0.12, 1)                                        # bins of 0.5 centred at 0.25, 0.75, ...
    figure = _drawn_figures(tmp_path, settled(), [run], [])["deposit_profiles"]
    (line,) = [line for line in figure.axes[0].lines if line.get_drawstyle() == "steps-post"]
    x, y = line.get_data()
    assert x[0] == 0.0 and x[1] == pytest.approx(0.5 / R0)
    assert y[0] == pytest.approx(run.deposit_height.values[0] / R0)
    assert x[-1] == pytest.approx(6.0 / R0)                           # and the last bin to its outer edge


def test_flagged_profiles_are_dashed_and_say_why(tmp_path):
    run = analysis(1.0, 0.12, 1).assign(h_inf_over_r0=1.0, final_to_peak_kinetic_energy=0.2, n_main_mass=10.0,
                                        n_particles=100.0)
    figure = _drawn_figures(tmp_path, settled(), [run], [])["deposit_profiles"]
    (line,) = [line for line in figure.axes[0].lines if line.get_drawstyle() == "steps-post"]
    assert line.get_linestyle() == "--"
    assert line.get_label() == "$\\mu_r$ = 0.12 (still moving, main mass < half the grains)"


def test_a_negative_run_out_stays_in_the_frame(tmp_path):
    """A main mass that ends inside r0 (a fragment) has a negative run-out: it is drawn, not cut off."""
    data = settled()
    data["runout_over_r0"][0, 0, :] = -0.28
    ax = _drawn_figures(tmp_path, data, [], [])["runout"].axes[0]
    assert ax.get_ylim()[0] < -0.28
    assert ax.get_ylim()[0] == pytest.approx(1.1 * -0.28)


def test_the_side_views_name_the_last_frame_as_run_status_calls_the_run():
    """The side view's last panel: "deposit" at rest, "end (still moving)" for a run moving at its end
    (flag 0, or rest not checked and the energy left above rest_energy of its peak), "end" when
    neither the flag nor the step energies tell."""
    from colsim.study.figures.runs import _end_name

    def trajectory(at_rest=None, energy=None):
        data = {} if energy is None else {"step_kinetic_energy": ("step", energy)}
        if at_rest is not None:
            data["at_rest"] = xr.DataArray(np.int8(at_rest))
        return xr.Dataset(data, attrs={"config": json.dumps({"command": "collapse", "rest_energy": 0.01})})

    assert _end_name(trajectory(1)) == "deposit"
    assert _end_name(trajectory(0)) == "end (still moving)"
    assert _end_name(trajectory(-1)) == "end"
    assert _end_name(trajectory(-1, [1.0, 0.5])) == "end (still moving)"
    assert _end_name(trajectory(None, [1.0, 0.001])) == "deposit"


@pytest.mark.parametrize("r0, words", [(1.0, "SMOKE TEST, NOT A RESULT: r0 = 1"),
                                       (3.0, "Not converged in the column size (r0 = 3)"), (13.0, None)])
def test_every_figure_says_the_study_s_size_caveat_above_it(tmp_path, r0, words):
    """Issue 79.2: a figure opened from the report says what the landing page's caveat does (that page
    can open scrolled past it); a study at the converged size draws no banner."""
    data = settled()
    data.attrs["r0"] = r0
    for name, figure in _drawn_figures(tmp_path, data, [], []).items():
        texts = [text.get_text() for text in figure.texts]
        if words is None:
            assert not any("SMOKE" in t or "converged" in t for t in texts), (name, texts)
        else:
            assert any(t.startswith(words) for t in texts), (name, texts)


def test_a_channels_law_figure_names_its_walls_friction(tmp_path):
    """Issue 82: a channel's run-out doubles from walls as rough as the floor to frictionless ones
    (docs/validation/channel.md), so the law figure's title names wall_mu beside L0 and W."""
    from colsim.study.figures.laws import law_figure

    dims = ("aspect_ratio", "mu_r", "seed")
    summary = xr.Dataset({"runout_over_r0": (dims, [[[1.0]], [[2.0]]]), "h_inf_over_r0": (dims, [[[1.0]], [[1.3]]])},
                         coords={"aspect_ratio": [1.0, 2.0], "mu_r": [0.12], "seed": [1]},
                         attrs={"geometry": "channel", "channel_length": 6.0, "channel_width": 2.0, "wall_mu": 0.25,
                                "mu": 0.577})
    KEPT.clear()
    with matplotlib.rc_context({"figure.hooks": ["test_figures:keep_figure"]}):
        law_figure(summary, "runout_over_r0", tmp_path / "runout.png")
    [figure] = KEPT
    assert figure.axes[0].get_title().startswith("L0 = 6, W = 2, wall_mu = 0.25, mu = 0.577")
