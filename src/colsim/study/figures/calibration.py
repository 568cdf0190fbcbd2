"""The mu_r calibration's figure (:mod:`colsim.study.calibration`): the misfit against mu_r with its
interval band, and the large-column limits against a for each mu_r beside the experimental laws."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..calibration import LAWS
from .style import _pyplot, _save

LAW_NAMES = {"lube": "Lube et al.", "lajeunesse": "Lajeunesse et al."}


def calibration_figure(result, path: Path) -> Path:
    """Left: the misfit (both measures, and each alone) against mu_r for each law, with its interval
    band and the best mu_r marked. Middle and right: the height and run-out limits against a for
    each mu_r, with their intervals, beside Lube's and Lajeunesse's laws."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), layout="constrained")
    mu_r = result.mu_r.values
    ax = axes[0]
    for n, law in enumerate(result.law.values):
        for measure, style in (("both", "-"), ("height", ":"), ("runout", "--")):
            part = result.sel(law=law, measure=measure)
            ax.plot(mu_r, 100 * part.misfit.values, style, marker="o", color=f"C{n}",
                    label=f"{LAW_NAMES[law]}, {measure}")
            if measure == "both":
                ax.fill_between(mu_r, 100 * part.misfit_low.values, 100 * part.misfit_high.values,
                                color=f"C{n}", alpha=0.15, lw=0)
                ax.axvspan(float(part.best_mu_r_low), float(part.best_mu_r_high), color=f"C{n}", alpha=0.1)
                ax.axvline(float(part.best_mu_r), color=f"C{n}", lw=0.8)
    ax.set_xlabel("rolling resistance mu_r")
    ax.set_ylabel("misfit: rms relative error over a [%]")
    ax.set_title("misfit of the large-column limits")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ratios = result.aspect_ratio.values
    fine = np.linspace(ratios.min(), ratios.max(), 200)
    for ax, name, index, label in ((axes[1], "height", 0, "h_inf / r0"), (axes[2], "runout", 1, "(r_inf - r0) / r0")):
        for n, m in enumerate(mu_r):
            part = result.sel(mu_r=m)
            value = part[f"{name}_limit"].values
            ax.errorbar(ratios * (1 + 0.01 * (n - len(mu_r) / 2)), value,
                        yerr=[value - part[f"{name}_low"].values, part[f"{name}_high"].values - value],
                        fmt="o", ms=4, capsize=2, color=plt.cm.viridis(n / max(len(mu_r) - 1, 1)),
                        label=f"mu_r = {m:g}")
        for law, style, marker in (("lube", "k-", "s"), ("lajeunesse", "r--", "^")):
            line, = ax.plot(fine, LAWS[law][index](fine), style, lw=1)
            ax.plot(ratios, LAWS[law][index](ratios), marker, mfc="none", color=line.get_color(), ls=style[1:],
                    lw=1, label=LAW_NAMES[law])   # the markers show the law where the sweep has one a
        ax.set_xlabel("aspect ratio a")
        ax.set_ylabel(f"{label}, large-column limit")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return _save(fig, path)
