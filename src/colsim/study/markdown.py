"""A study's tables in Markdown (and the report's reStructuredText): the means over seeds against
Lube et al.'s laws with the other run-out measures and the paper's qualitative claims, and the two
friction laws side by side; from the datasets of :mod:`colsim.study.collect`."""
from __future__ import annotations

import numpy as np

from .collect import FLAGS, MAIN_MASS_SHARE, counted, rest_energy_of, run_status
from ..stages.pour_geometry import geometry_of
from .experimental_laws import REFERENCE, laws_for


def _sd(values) -> float:
    """The sample standard deviation of the finite values; NaN with fewer than two."""
    return np.nanstd(values, ddof=1) if np.isfinite(values).sum() > 1 else np.nan


def claims_markdown(summary) -> str:
    """Markdown table of the paper's qualitative claims, per mu_r and a (mean over seeds): the final
    height over h0 (1 where the top is undisturbed, below 1 where it was eroded), the radius of the
    top disc that did not move, over r0, and the share of grains in the main mass."""
    lines = ["| mu_r | a | h_inf/h0 | undisturbed top radius/r0 | main mass / grains |", "|---|---|---|---|---|"]
    for m in summary.mu_r.values:
        for a in summary.aspect_ratio.values:
            part = summary.sel(mu_r=m, aspect_ratio=a)
            if not _has_runs(part):
                continue
            kept = np.nanmean(part.n_main_mass.values / part.n_particles.values)
            lines.append(f"| {float(m):g} | {a:g} | {np.nanmean(part.h_inf_over_r0.values) / a:.2f} | "
                         f"{np.nanmean(part.undisturbed_top_radius.values):.2f} | {kept:.2f} |")
    return "\n".join(lines) + "\n"


def runout_measures_markdown(summary) -> str:
    """Markdown table per mu_r and a: Lube's run-out, r_inf at each contact tolerance and the radius
    holding each share of the mass, as (r - r0)/r0, mean over seeds, with the error against Lube."""
    tolerances = summary.contact_tolerance.values
    shares = summary.mass_share.values
    header = (["mu_r", "a", "Lube"] + [f"connected, gap <= {100 * t:g} % d_min" for t in tolerances]
              + [f"{100 * s:g} % of the mass" for s in shares])
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for m in summary.mu_r.values:
        for a in summary.aspect_ratio.values:
            part = summary.sel(mu_r=m, aspect_ratio=a)
            if not _has_runs(part):
                continue
            law = float(_reference(summary, "runout_over_r0")(a))
            values = list(np.nanmean(part.runout_over_r0_by_tolerance.values, axis=0)) + list(
                np.nanmean(part.mass_front_over_r0.values, axis=0))
            cells = [f"{v:.2f} ({_error(v, law)})" for v in values]
            lines.append(f"| {float(m):g} | {a:g} | {_law_cell(law, 2)} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _flag_cell(flags, seeds) -> str:
    """The flags of one (mu_r, a) row over its seeds: "still moving (seeds 1, 2)"; "" when none."""
    cells = []
    for name, flagged in flags.items():
        which = [f"{int(s)}" for s, f in zip(seeds, np.atleast_1d(flagged)) if f]
        if which:
            cells.append(f"{FLAGS[name]} (seed{'s' if len(which) > 1 else ''} {', '.join(which)})")
    return "; ".join(cells)


def _reference(summary, variable: str):
    """The law of :data:`REFERENCE` for the summary's geometry that predicts `variable`."""
    return laws_for(geometry_of(summary.attrs))[variable][REFERENCE[geometry_of(summary.attrs)]]


def _other(summary, variable: str):
    """The second law of the summary's geometry for `variable` (Lajeunesse et al.'s)."""
    return [law for name, law in laws_for(geometry_of(summary.attrs))[variable].items()
            if name != REFERENCE[geometry_of(summary.attrs)]][0]


def lube_markdown(summary) -> str:
    """Markdown table: mean over seeds of h_inf/r0 and the run-out against Lube et al., per mu_r and
    a, with the error against Lajeunesse et al. beside (its height law as the paper prints it), and a
    flags column naming the seeds whose runs :func:`run_status` flags (explained under the tables).
    The laws are the geometry's (:func:`colsim.study.experimental_laws.laws_for`): 2004's for a
    cylinder, 2005's for a channel, where r0 stands for the box length L0."""
    lines = []
    height, runout = _reference(summary, "h_inf_over_r0"), _reference(summary, "runout_over_r0")
    other_height, other_runout = _other(summary, "h_inf_over_r0"), _other(summary, "runout_over_r0")
    flags = run_status(summary)
    seed_values = summary.seed.values if "seed" in summary.coords else [0]
    for m in summary.mu_r.values:
        part = summary.sel(mu_r=m)
        counts = np.isfinite(part.h_inf_over_r0.values).sum(axis=-1)
        counts = counts[counts > 0]   # a partial study: the aspect ratios run (every mu_r has one)
        seeds = counted(int(counts.min()), "seed", int(counts.max()))
        lines += [f"### mu_r = {float(m):g} (mean of {seeds}; spread = max - min)", "",
                  "| a | h_inf/r0 | spread | Lube | error | (r_inf - r0)/r0 | spread | Lube | error "
                  "| Lajeunesse h_inf/r0 | error | Lajeunesse run-out | error | flags |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for a in part.aspect_ratio.values:
            if not _has_runs(part.sel(aspect_ratio=a)):
                continue
            h = part.h_inf_over_r0.sel(aspect_ratio=a).values
            r = part.runout_over_r0.sel(aspect_ratio=a).values
            h_mean, r_mean = np.nanmean(h), np.nanmean(r)
            cells = [f"{a:g}"]
            for mean, values, law in ((h_mean, h, height(a)), (r_mean, r, runout(a))):
                cells += [f"{mean:.3f}", f"{np.nanmax(values) - np.nanmin(values):.3f}", _law_cell(law),
                          _error(mean, law)]
            for mean, law in ((h_mean, other_height(a)), (r_mean, other_runout(a))):
                cells += [_law_cell(law), _error(mean, law)]
            cells.append(_flag_cell({name: flag.sel(mu_r=m, aspect_ratio=a).values for name, flag in flags.items()},
                                    seed_values))
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    if any(bool(flag.any()) for flag in flags.values()):
        lines += [f"Flags: *{FLAGS['moving']}*: the run was not at rest at its end (it reached max_duration "
                  f"moving or, with a fixed end time, its kinetic energy was still above {rest_energy_of(summary):g} "
                  f"of its peak), so its h_inf and run-out are not those of a final deposit; "
                  f"*{FLAGS['fragment']}*: the main mass (the largest connected cluster) holds less than "
                  f"{100 * MAIN_MASS_SHARE:g} % of the grains, so its h_inf and run-out describe a fragment. The means "
                  f"include these runs; the figures draw them with open markers (moving) or a cross (fragment).",
                  ""]
    if "runout_over_r0_by_tolerance" in summary and "mass_front_over_r0" in summary:
        lines += ["### Run-out by other measures (mean over seeds; error against Lube)", "",
                  runout_measures_markdown(summary)]
    if "undisturbed_top_radius" in summary and "n_main_mass" in summary:
        lines += ["### The paper's qualitative claims", "", claims_markdown(summary)]
    if geometry_of(summary.attrs) == "channel":
        from .channel import exponents_markdown

        lines += ["### Exponents against the channel laws (fitted over every seed)", "", exponents_markdown(summary)]
    return "\n".join(lines)


#: the column sizes the column-size study measured against its limit (docs/validation/column-size.md):
#: below SMOKE_TEST_R0 a study only checks that the pipeline runs; below CONVERGED_R0 its run-outs are
#: short of the large-column limit by more than 5 % (how far at each size: that page)
SMOKE_TEST_R0 = 2.0
CONVERGED_R0 = 13.0


def size_caveat(r0: float) -> str:
    """One sentence saying how far a study of cylinder radius r0 (the paper's diameters) is from the
    large-column limit, or "" at or above CONVERGED_R0."""
    if r0 < SMOKE_TEST_R0:
        return (f"**A smoke test, not a result:** r0 = {r0:g} holds a few dozen grains, far below any converged size; "
                "its numbers only show that the pipeline runs (the errors below are expected to be large).")
    if r0 < CONVERGED_R0:
        return (f"**Not converged in the column size:** at r0 = {r0:g} the run-outs fall short of the model's "
                f"large-column limit (by 21-27 % at r0 = 3 and 10-11 % at r0 = 6; 5 % needs r0 of about "
                f"{CONVERGED_R0:g}; docs/validation/column-size.md): read them for trends in a and mu_r.")
    return ""


def size_banner(r0: float) -> str:
    """:func:`size_caveat` in a figure title's few words, or "" at or above CONVERGED_R0."""
    if r0 < SMOKE_TEST_R0:
        return f"SMOKE TEST, NOT A RESULT: r0 = {r0:g}, a few dozen grains"
    if r0 < CONVERGED_R0:
        return f"Not converged in the column size (r0 = {r0:g}): run-outs short of the large-column limit"
    return ""


def lube_rst(summary, mu_r: float) -> str:
    """reStructuredText of the report's landing page: a sentence on the column size
    (:func:`size_caveat`), then a list-table at the swept mu_r nearest `mu_r`, per a, of the mean over
    seeds of h_inf/r0 and the run-out with Lube's values, the errors and the flags of the runs that
    are still moving or a fragment (:func:`colsim.study.collect.run_status`)."""
    m = summary.mu_r.values[np.argmin(np.abs(summary.mu_r.values - mu_r))]
    part = summary.sel(mu_r=m)
    flags = run_status(summary)
    seed_values = summary.seed.values if "seed" in summary.coords else [0]
    rows = [["a", "h_inf/r0", "Lube", "error", "(r_inf - r0)/r0", "Lube", "error", "flags"]]
    height, runout = _reference(summary, "h_inf_over_r0"), _reference(summary, "runout_over_r0")
    for a in part.aspect_ratio.values:
        if not _has_runs(part.sel(aspect_ratio=a)):
            continue
        h = float(np.nanmean(part.h_inf_over_r0.sel(aspect_ratio=a).values))
        r = float(np.nanmean(part.runout_over_r0.sel(aspect_ratio=a).values))
        flag = _flag_cell({name: f.sel(mu_r=m, aspect_ratio=a).values for name, f in flags.items()}, seed_values)
        rows.append([f"{a:g}", f"{h:.3f}", _law_cell(height(a)), _error(h, height(a)),
                     f"{r:.3f}", _law_cell(runout(a)), _error(r, runout(a)), flag or "-"])
    caveat = size_caveat(float(summary.attrs["r0"])) if "r0" in summary.attrs else ""
    lines = ([caveat, ""] if caveat else []) + [
        f".. list-table:: mu_r = {float(m):g}, mean over seeds, against {REFERENCE[geometry_of(summary.attrs)]}",
        "   :header-rows: 1", ""]
    for row in rows:
        lines += [f"   * - {row[0]}"] + [f"     - {cell}" for cell in row[1:]]
    if any(bool(f.sel(mu_r=m).any()) for f in flags.values()):
        lines += ["", f"Flags: *{FLAGS['moving']}*: not at rest at the end, so not a final deposit; "
                      f"*{FLAGS['fragment']}*: the main mass holds under {100 * MAIN_MASS_SHARE:g} % of the grains."]
    return "\n".join(lines) + "\n"


def _has_runs(part) -> bool:
    """Whether any seed of this part of a summary ran (a partial study leaves NaN rows out)."""
    return bool(np.isfinite(part.h_inf_over_r0.values).any())


def _law_cell(law: float, digits: int = 3) -> str:
    """A law's value for a table, "-" where the law gives none."""
    return f"{law:.{digits}f}" if np.isfinite(law) else "-"


def _error(value: float, law: float) -> str:
    """The relative error of value against law, in percent, signed; "-" where the law gives no value
    (outside its range of a, or between the regimes of Lube et al. 2005)."""
    if not np.isfinite(law):
        return "-"
    return f"{100 * (value - law) / law:+.0f} %"


def friction_law_markdown(comparison) -> str:
    """Markdown table per mu_r and a: each law's h_inf/r0 and run-out (mean and sd over seeds) against
    Lube's laws, its main-mass share, cone programs per step and wall time per collapse."""
    lines = []
    for m in comparison.mu_r.values:
        lines += [f"### mu_r = {float(m):g} (mean over seeds, sd = sample standard deviation)", "",
                  "| a | law | seeds | h_inf/r0 (sd) | Lube | error | (r_inf - r0)/r0 (sd) | Lube | error "
                  "| main mass / grains | cone programs a step | wall s a collapse |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for a in comparison.aspect_ratio.values:
            for law in comparison.friction_law.values:
                part = comparison.sel(mu_r=m, aspect_ratio=a, friction_law=law)
                h, r = part.h_inf_over_r0.values, part.runout_over_r0.values
                seeds = int(np.isfinite(h).sum())
                if seeds == 0:
                    continue
                h_law = float(_reference(comparison, "h_inf_over_r0")(a))
                r_law = float(_reference(comparison, "runout_over_r0")(a))
                share = np.nanmean(part.n_main_mass.values / part.n_particles.values)
                programs = (np.nanmean(part.cone_programs_per_step.values)
                            if "cone_programs_per_step" in part else np.nan)
                lines.append(
                    f"| {a:g} | {law} | {seeds} | {np.nanmean(h):.3f} ({_sd(h):.3f}) | {h_law:.3f} | "
                    f"{_error(np.nanmean(h), h_law)} | {np.nanmean(r):.3f} ({_sd(r):.3f}) | "
                    f"{r_law:.3f} | {_error(np.nanmean(r), r_law)} | {share:.2f} | "
                    f"{programs:.1f} | {np.nanmean(part.wall_time.values):.0f} |")
        lines.append("")
    return "\n".join(lines)
