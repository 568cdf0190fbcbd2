"""What the study's figures share: matplotlib loaded on demand (Agg), the file written atomically,
the seeds' spread and its error bars, the markers of flagged runs (:func:`colsim.study.collect.run_status`:
an open marker where a seed was still moving at the end, a black cross where a seed's main mass holds
less than half the grains), colours, empty panels and grids of panels."""
from __future__ import annotations

import contextlib
import contextvars
import logging
from pathlib import Path

import numpy as np

from ..collect import FLAGS, counted, run_status


log = logging.getLogger(__name__)


MARKERS = "osD^vP*X<>"


QUANTITY_LABELS = {"h_inf_over_r0": "$h_\\infty/r_0$", "runout_over_r0": "$(r_\\infty - r_0)/r_0$"}


STANDARD_ERROR_SEEDS = 3
"""From this many seeds on, error bars are the standard error of the mean; below, the range."""


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _label(variable, fallback: str) -> str:
    """An axis label from a variable's long_name and units (units "1" are left out)."""
    name = variable.attrs.get("long_name", fallback) if variable is not None else fallback
    units = variable.attrs.get("units", "1") if variable is not None else "1"
    return name if units in ("1", "") else f"{name} [{units}]"


#: a line above every figure saved while it is set (:func:`banner`): the study's size caveat
_BANNER: contextvars.ContextVar[str] = contextvars.ContextVar("banner", default="")


@contextlib.contextmanager
def banner(text: str):
    """Figures saved inside this block carry `text` above them, in bold red (nothing when empty)."""
    token = _BANNER.set(text)
    try:
        yield
    finally:
        _BANNER.reset(token)


def _save(fig, path: Path) -> Path:
    from ...io.files import atomic_path

    if _BANNER.get():   # above a suptitle too; bbox_inches="tight" keeps it in the PNG
        fig.text(0.5, 1.04, _BANNER.get(), ha="center", va="bottom", color="#b00000", weight="bold", fontsize=11)
    with atomic_path(path) as tmp:   # a killed plot leaves no PNG that looks finished
        fig.savefig(tmp, format="png", dpi=120, bbox_inches="tight")
    _pyplot().close(fig)
    log.info("wrote %s", path)
    return path


def _seed_spread(values):
    """(mean, lower error, upper error) over the last axis, ignoring NaN (missing seeds)."""
    import warnings

    values = np.asarray(values, dtype=float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: a run that is missing
        mean = np.nanmean(values, axis=-1)
        low = mean - np.nanmin(values, axis=-1)
        high = np.nanmax(values, axis=-1) - mean
    return mean, np.nan_to_num(low), np.nan_to_num(high)


def _bar_kind(*arrays) -> tuple[str, int, int]:
    """("se" or "range", fewest, most seeds) over the points of `arrays` (each (..., seed)) that have
    a run: "se" when every such point has STANDARD_ERROR_SEEDS seeds or more."""
    counts = np.concatenate([np.isfinite(np.asarray(v, dtype=float)).sum(axis=-1).ravel() for v in arrays])
    counts = counts[counts > 0]
    fewest, most = (int(counts.min()), int(counts.max())) if counts.size else (0, 0)
    return ("se" if fewest >= STANDARD_ERROR_SEEDS else "range"), fewest, most


def _bars(values, kind: str):
    """(mean, lower error, upper error) over the last axis, ignoring NaN: the standard error of the
    mean (sample sd / sqrt(n)) on both sides for kind "se", the spread to the lowest and the highest
    seed for "range"."""
    import warnings

    mean, low, high = _seed_spread(values)
    if kind == "se":
        values = np.asarray(values, dtype=float)
        n = np.isfinite(values).sum(axis=-1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            error = np.nanstd(values, axis=-1, ddof=1) / np.sqrt(n)
        low = high = np.nan_to_num(error)
    return mean, low, high


def _bar_note(kind: str, fewest: int, most: int) -> str:
    """What the error bars are, for a legend's title."""
    seeds = counted(fewest, "seed", most)
    if most <= 1:
        return f"{seeds}: no error bars"
    if kind == "se":
        return f"mean of {seeds}, bars: standard error"
    return f"mean of {seeds}, bars: lowest to highest seed"


def _flags_of(summary) -> dict:
    """{flag: bool array over the summary's other dimensions}: any seed of the point flagged."""
    return {name: flag.any("seed") if "seed" in flag.dims else flag for name, flag in run_status(summary).items()}


def _draw_flags(ax, x, y, flags: dict, colour, marker: str, ms: float = 6) -> None:
    """Over the markers (x, y) already drawn: open markers where flags["moving"], a black cross where
    flags["fragment"]."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    moving, fragment = (np.asarray(flags.get(name, np.zeros(len(x), bool)), bool) for name in ("moving", "fragment"))
    if moving.any():
        ax.plot(x[moving], y[moving], marker, ls="none", ms=ms, color=colour, mfc="white", zorder=3,
                label="_flag moving")
    if fragment.any():
        ax.plot(x[fragment], y[fragment], "x", ls="none", ms=ms + 1, mew=1.3, color="k", zorder=4,
                label="_flag fragment")


def _flag_handles(flags: dict) -> list:
    """Legend entries for the flags that are set anywhere in `flags` ({flag: bool array})."""
    from matplotlib.lines import Line2D

    handles = []
    if np.any(flags.get("moving", False)):
        handles.append(Line2D([], [], marker="o", ls="none", mfc="white", mec="0.3",
                              label=f"open: a seed {FLAGS['moving']} at the end"))
    if np.any(flags.get("fragment", False)):
        handles.append(Line2D([], [], marker="x", ls="none", color="k", mew=1.3,
                              label=f"cross: a seed's {FLAGS['fragment']}"))
    return handles


def _colours(n: int) -> list:
    """n colours that read on white: tab10's, then tab20's (no pale yellow)."""
    plt = _pyplot()
    palette = list(plt.cm.tab10.colors) + [c for k, c in enumerate(plt.cm.tab20.colors) if k % 2]
    return [palette[k % len(palette)] for k in range(n)]


def _by_key(datasets):
    """{(aspect_ratio, mu_r, seed): dataset}."""
    return {(float(d.attrs["aspect_ratio"]), float(d.attrs["mu_r"]), int(d.attrs.get("seed", 0))): d
            for d in datasets}


def _empty(ax, text: str):
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes)
    ax.set_axis_off()


def _grid(plt, n: int, width: float, height: float):
    columns = min(n, 3)
    rows = max(1, int(np.ceil(n / columns)))
    fig, axes = plt.subplots(rows, columns, figsize=(width * columns, height * rows), squeeze=False,
                             layout="constrained")
    for ax in axes.flat[n:]:
        ax.set_axis_off()
    return fig, axes.flat
