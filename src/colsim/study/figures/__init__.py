"""The study's figures (PNG), from the collected summary, analyses and trajectories, one module per
family: :mod:`.laws` (against the experimental laws), :mod:`.runs` (single runs: profiles, side views,
fronts), :mod:`.convergence` (the convergence and column-size studies), :mod:`.calibration` (the mu_r
calibration); :mod:`.style` holds what they share.

:func:`all_figures` writes the files named in :data:`FIGURES` (colsim.study.figure_names, which the
workflow reads without loading matplotlib) into one directory. matplotlib is imported inside the
functions (Agg back-end), so colsim imports without it. Every function takes xarray Datasets as
colsim writes them and tolerates missing runs (NaN in the summary) and sweeps of a single value.
"""
from __future__ import annotations

from pathlib import Path

from ..figure_names import FIGURES
from ..markdown import size_banner
from .calibration import calibration_figure
from .convergence import column_size_limit_figure, convergence_figure
from .laws import friction_law_figure, law_figure, mu_r_figure
from .runs import deposit_profile_figure, front_figure, side_view_figure
from .style import banner

__all__ = ["FIGURES", "all_figures", "calibration_figure", "column_size_limit_figure", "convergence_figure",
           "deposit_profile_figure", "friction_law_figure", "front_figure", "law_figure", "mu_r_figure",
           "side_view_figure"]


def all_figures(summary, analyses, trajectories, output_dir) -> list[Path]:
    """Write every figure of :data:`FIGURES` into `output_dir` (created); return their paths. Each
    carries the study's size caveat above it (:func:`colsim.study.markdown.size_banner`), so that a
    figure seen alone says what the report's first page does."""
    output_dir = Path(output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    analyses, trajectories = list(analyses), list(trajectories)
    draw = {"final_height": lambda path: law_figure(summary, "h_inf_over_r0", path),
            "runout": lambda path: law_figure(summary, "runout_over_r0", path),
            "mu_r_effect": lambda path: mu_r_figure(summary, path),
            "deposit_profiles": lambda path: deposit_profile_figure(analyses, path),
            "side_views": lambda path: side_view_figure(trajectories, path),
            "front_position": lambda path: front_figure(analyses, path)}
    with banner(size_banner(float(summary.attrs["r0"])) if "r0" in summary.attrs else ""):
        return [draw[name](output_dir / f"{name}.png") for name in FIGURES]
