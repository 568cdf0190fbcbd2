"""The docs' results tables from docs/data (colsim.study.docs_tables, `colsim docs`): every marked
table equals what the data gives, a change in the data shows in the table, the errors against the
laws are the laws' (Lube et al. at a = 1 are 0.88 and 1.24, exactly), and a broken marker or a
missing file is one clear error."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from colsim.study import docs_tables

ROOT = Path(__file__).resolve().parents[2]


def _copy(tmp_path: Path) -> Path:
    """The files `colsim docs` reads and writes, copied under tmp_path."""
    for relative in [*docs_tables.TARGETS, docs_tables.DEFAULT_STUDY, docs_tables.COLUMN_SIZE]:
        (tmp_path / relative).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / relative, tmp_path / relative)
    return tmp_path


@pytest.mark.parametrize("relative", list(docs_tables.TARGETS))
def test_every_marked_table_equals_the_data(relative):
    made = docs_tables.regenerate(ROOT)[ROOT / relative]
    assert made == (ROOT / relative).read_text(encoding="utf-8"), f"{relative}: run `colsim docs`"


def test_a_change_in_the_data_shows_in_the_readme(tmp_path):
    """Bound: the README's a = 2 row carries the data's height at mu_r = 0.12 and its error against
    Lube's 0.88 * 2^(1/6) = 0.988 computed from it."""
    root = _copy(tmp_path)
    data = root / docs_tables.DEFAULT_STUDY
    lines = data.read_text().splitlines()
    row = next(k for k, line in enumerate(lines) if line.startswith("0.12,2,"))
    fields = lines[row].split(",")
    fields[2] = "0.741"
    lines[row] = ",".join(fields)
    data.write_text("\n".join(lines) + "\n")
    readme = docs_tables.regenerate(root)[root / "README.md"]
    (a_2,) = [line for line in readme.splitlines() if line.startswith("| 2 |")]
    assert "| 0.741 (" in a_2 and "| -25 % /" in a_2   # 0.741 / 0.98781 - 1 = -24.99 %


def test_errors_are_against_the_laws():
    assert docs_tables.percent(0.936, 1.24) == "-25 %"
    assert docs_tables.percent(0.499, 0.5) == "-0 %" and docs_tables.percent(0.501, 0.5) == "+0 %"
    default = [{"mu_r": 0.12, "aspect_ratio": 1.0, "h_inf_over_r0": 0.88, "h_inf_over_r0_spread": 0.0,
                "runout_over_r0": 1.24, "runout_over_r0_spread": 0.0}]
    (row,) = docs_tables.default_study_table(default).splitlines()[2:]
    # Lube at a = 1: 0.88 and 1.24 exactly; Lajeunesse: 0.74 and 2.0
    assert row == "| 0.12 | 1 | 0.880 (0.000) | 0.880 | +0 % | +19 % | 1.240 (0.000) | 1.240 | +0 % | -38 % |"


def test_a_broken_marker_or_a_missing_file_is_one_clear_error(tmp_path):
    with pytest.raises(docs_tables.DocsDataError, match="end of results-table"):
        docs_tables.replace_block("<!-- results-table: x -->\n| a |\n", "results-table", "| b |", "README.md")
    with pytest.raises(docs_tables.DocsDataError, match="is missing"):
        docs_tables.read_rows(tmp_path / "nothing.csv")


def test_colsim_docs_checks_and_remakes(tmp_path):
    root = _copy(tmp_path)
    command = [sys.executable, "-m", "colsim.cli", "docs", "--root", str(root)]
    assert subprocess.run([*command, "--check"], capture_output=True, text=True).returncode == 0
    readme = root / "README.md"
    readme.write_text(readme.read_text().replace("| 0.5 | 0.499", "| 0.5 | 0.999"))
    checked = subprocess.run([*command, "--check"], capture_output=True, text=True)
    assert checked.returncode == 1 and "README.md" in checked.stderr
    remade = subprocess.run(command, capture_output=True, text=True)
    assert remade.returncode == 0, remade.stderr
    assert "| 0.5 | 0.499" in readme.read_text()
    elsewhere = subprocess.run([sys.executable, "-m", "colsim.cli", "docs", "--root", str(tmp_path / "none")],
                               capture_output=True, text=True)
    assert elsewhere.returncode == 2 and "docs/data" in elsewhere.stderr
