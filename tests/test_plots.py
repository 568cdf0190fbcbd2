"""colsim.plots on small synthetic datasets shaped like colsim's files (no simulation needed)."""
import numpy as np
import pytest

pytest.importorskip("matplotlib")
xr = pytest.importorskip("xarray")

from colsim import plots  # noqa: E402
from colsim.summary import SUMMARY_VARIABLES  # noqa: E402

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
