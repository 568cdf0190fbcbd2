"""The documentation's results tables, made from the datasets kept in docs/data (`colsim docs`).

A table in README.md or a page of docs/ that comes from data sits between two marker lines,

    <!-- NAME: made by `colsim docs` from docs/data; do not edit by hand -->
    ...the table...
    <!-- end of NAME -->

and :func:`regenerate` rewrites what lies between them from the CSV files of docs/data, so a
number in those tables is the data's, never a copy that can drift from it. Each CSV file opens with
`#` lines saying what it holds and where it came from; the errors against the experimental laws are
computed here from the values the file holds (:mod:`colsim.study.experimental_laws`).
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

from .experimental_laws import lajeunesse_height, lajeunesse_runout, lube_height, lube_runout

#: the files, relative to the repository's root, and the tables each holds (by marker name)
TARGETS = {
    "README.md": ("results-table",),
    "docs/validation/rolling-lever.md": ("default-study-table",),
    "docs/validation/column-size.md": ("column-size-tables",),
}
DEFAULT_STUDY = "docs/data/default-study.csv"
COLUMN_SIZE = "docs/data/column-size-limits.csv"
#: the rolling coefficient of the README's table (the paper's hexagon gives 0.131)
README_MU_R = 0.12
SIZES = (2, 3, 4, 5, 6)


class DocsDataError(ValueError):
    """A docs/data file or a marked table that cannot be read as it must be."""


def read_rows(path: Path) -> list[dict]:
    """The rows of a docs/data CSV file (its `#` lines skipped), numbers as floats, empty cells None."""
    try:
        lines = [line for line in path.read_text(encoding="utf-8").splitlines() if not line.startswith("#")]
    except FileNotFoundError:
        raise DocsDataError(f"{path} is missing: the docs' tables are made from it") from None
    rows = list(csv.DictReader(lines))
    if not rows:
        raise DocsDataError(f"{path} holds no rows")
    return [{key: _number(value, path) for key, value in row.items()} for row in rows]


def _number(text: str, path: Path):
    if text in ("", None):
        return None
    try:
        return float(text)
    except ValueError:
        return text


def percent(value: float, law: float) -> str:
    """The relative error of `value` against `law`, whole per cent with its sign ("-0 %" stays)."""
    return f"{100 * (value / law - 1):+.0f} %"


def _row(cells) -> str:
    return "| " + " | ".join(cells) + " |"


def _table(header, rows) -> str:
    return "\n".join([_row(header), "|" + "---|" * len(header), *(_row(r) for r in rows)])


def _interval(row: dict) -> str:
    exponent = "" if row["exponent"] == 1 else f" (p = {row['exponent']:g})"
    return f"{row['limit']:.3f} [{row['limit_low']:.3f}, {row['limit_high']:.3f}]{exponent}"


def _limits(limits: list[dict], variable: str) -> dict:
    return {row["aspect_ratio"]: row for row in limits if row["variable"] == variable}


def readme_table(default: list[dict], limits: list[dict]) -> str:
    """The README's table: the default study at mu_r = README_MU_R beside the column-size limits,
    each against Lube et al."""
    heights, runouts = _limits(limits, "h_inf_over_r0"), _limits(limits, "runout_over_r0")
    rows = []
    for run in (r for r in default if math.isclose(r["mu_r"], README_MU_R)):
        a = run["aspect_ratio"]
        if a not in heights or a not in runouts:
            raise DocsDataError(f"{COLUMN_SIZE} has no limits at a = {a:g}")
        cells = [f"{a:g}"]
        for name, limit, law in (("h_inf_over_r0", heights[a], lube_height(a)),
                                 ("runout_over_r0", runouts[a], lube_runout(a))):
            cells += [f"{run[name]:.3f} ({run[name + '_spread']:.3f})", _interval(limit).split(" (p")[0],
                      f"{law:.3f}", f"{percent(run[name], law)} / {percent(limit['limit'], law)}"]
        rows.append(cells)
    header = ["a", "h_inf/r0 at r0 = 3 (spread)", "limit [95 %]", "Lube", "error r0 = 3 / limit",
              "run-out/r0 at r0 = 3 (spread)", "limit [95 %]", "Lube", "error r0 = 3 / limit"]
    return _table(header, rows)


def default_study_table(default: list[dict]) -> str:
    """The default study at every mu_r and a against Lube et al. and Lajeunesse et al."""
    rows = []
    for run in default:
        a = run["aspect_ratio"]
        cells = [f"{run['mu_r']:g}", f"{a:g}"]
        for name, lube, lajeunesse in (("h_inf_over_r0", lube_height(a), lajeunesse_height(a)),
                                       ("runout_over_r0", lube_runout(a), lajeunesse_runout(a))):
            cells += [f"{run[name]:.3f} ({run[name + '_spread']:.3f})", f"{lube:.3f}", percent(run[name], lube),
                      percent(run[name], lajeunesse)]
        rows.append(cells)
    header = ["mu_r", "a", "h_inf/r0 (spread)", "Lube", "error", "Lajeunesse error", "run-out/r0 (spread)", "Lube",
              "error", "Lajeunesse error"]
    return _table(header, rows)


def _sizes(row: dict) -> str:
    return " / ".join("-" if row[f"r0_{r}"] is None else f"{row[f'r0_{r}']:.3f}" for r in SIZES)


def _largest_against_limit(row: dict) -> str:
    largest = max(r for r in SIZES if row[f"r0_{r}"] is not None)
    text = f"{100 * (row[f'r0_{largest}'] / row['limit'] - 1):+.1f} %"
    return text if largest == SIZES[-1] else f"{text} (r0 = {largest})"


def column_size_tables(limits: list[dict]) -> str:
    """The column-size study's two tables: the heights and the run-outs at each size, their limits
    with both intervals, and the limits against the laws."""
    heights = [[f"{a:g}", _sizes(r), _interval(r), f"[{r['limit_low_p1']:.3f}, {r['limit_high_p1']:.3f}]",
                percent(r["limit"], lube_height(a))] for a, r in _limits(limits, "h_inf_over_r0").items()]
    runouts = [[f"{a:g}", _sizes(r), _interval(r), f"[{r['limit_low_p1']:.3f}, {r['limit_high_p1']:.3f}]",
                percent(r["limit"], lube_runout(a)), percent(r["limit"], lajeunesse_runout(a)),
                _largest_against_limit(r), f"{r['r0_within_5pc']:g} / {r['r0_within_2pc']:g}"]
               for a, r in _limits(limits, "runout_over_r0").items()]
    sizes = " / ".join(str(r) for r in SIZES)
    return "\n\n".join([
        _table(["a", f"h_inf/r0 at r0 = {sizes}", "limit [95 %]", "at p = 1", "vs Lube"], heights),
        _table(["a", f"run-out/r0 at r0 = {sizes}", "limit [95 %]", "at p = 1", "vs Lube", "vs Lajeunesse",
                "r0 = 6 vs limit", "r0 for 5 % / 2 %"], runouts)])


def tables(root: Path) -> dict[str, str]:
    """Every marked table, by marker name, made from root's docs/data."""
    default, limits = read_rows(root / DEFAULT_STUDY), read_rows(root / COLUMN_SIZE)
    return {"results-table": readme_table(default, limits), "default-study-table": default_study_table(default),
            "column-size-tables": column_size_tables(limits)}


def replace_block(text: str, name: str, table: str, where: str = "the text") -> str:
    """`text` with what lies between the marker lines of `name` replaced by `table`."""
    lines = text.splitlines(keepends=True)
    starts = [k for k, line in enumerate(lines) if line.startswith(f"<!-- {name}:")]
    ends = [k for k, line in enumerate(lines) if line.strip() == f"<!-- end of {name} -->"]
    if len(starts) != 1 or len(ends) != 1 or ends[0] < starts[0]:
        raise DocsDataError(f"{where}: expected one '<!-- {name}: ... -->' line and one '<!-- end of {name} -->' "
                            f"line after it, found {len(starts)} and {len(ends)}")
    return "".join(lines[: starts[0] + 1]) + table + "\n\n" + "".join(lines[ends[0]:])


def regenerate(root: Path) -> dict[Path, str]:
    """{file: its text with every marked table made from docs/data}, for each file of TARGETS."""
    made = tables(root)
    texts = {}
    for relative, names in TARGETS.items():
        path = root / relative
        text = path.read_text(encoding="utf-8")
        for name in names:
            text = replace_block(text, name, made[name], relative)
        texts[path] = text
    return texts
