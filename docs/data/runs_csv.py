# What the scripts of docs/data share: a CSV with leading "#" lines (what it holds, where it came from),
# the CPU of a run's collapse and pour beside its analysis file, and the command line
#   python docs/data/SCRIPT.py [--from-analyses FILE ...] [--figures DIR]
# that rewrites a script's runs from a study's analysis files, draws its figures, then prints its tables.
import argparse
import csv
from pathlib import Path


def read_rows(path) -> list:
    """The rows of a CSV file of docs/data as dicts, its leading # lines skipped."""
    with open(path, newline="") as stream:
        return list(csv.DictReader(line for line in stream if not line.startswith("#")))


def calibration_runs(rows):
    """colsim.study.calibration.Runs of CSV rows that have its columns (mu_r, aspect_ratio, r0, seed,
    d_over_r0, height, runout)."""
    from dataclasses import fields

    import numpy as np

    from colsim.study.calibration import Runs

    return Runs(*(np.array([float(row[field.name]) for row in rows]) for field in fields(Runs)))


def write_rows(path, comments: str, columns, rows) -> None:
    """`rows` (tuples in `columns`' order) into `path` under `comments` (# lines); numbers to 10 digits."""
    with open(path, "w", newline="") as stream:
        stream.write("".join(f"# {line}\n" for line in comments.strip().splitlines()))
        writer = csv.writer(stream)
        writer.writerow(columns)
        writer.writerows([f"{value:.10g}" if isinstance(value, float) else value for value in row] for row in rows)


def run_costs(analysis_path) -> tuple[float, float, str]:
    """(CPU seconds of the collapse, CPU seconds of its packing's pour, the collapse's commit, 7 digits)
    of the run whose analysis file is `analysis_path`, from the collapse.nc beside it and the
    packing.nc of its packing folder (results/r0_*/seed_*/pack_*/a_*/mu_r_*/run_*/)."""
    import netCDF4

    path = Path(analysis_path)
    with netCDF4.Dataset(path.parent / "collapse.nc") as collapse, \
            netCDF4.Dataset(path.parents[3] / "packing.nc") as packing:
        return (float(collapse.getncattr("cpu_time")), float(packing.getncattr("cpu_time")),
                str(collapse.getncattr("colsim_commit"))[:7])


def main(description: str, write_runs, report, figures=None) -> None:
    """The scripts' command line: --from-analyses FILE ... calls write_runs(files) first; --figures DIR
    (where the script draws figures) calls figures(DIR); then the report is printed."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--from-analyses", nargs="+", metavar="FILE", help="write the runs' CSV from these first")
    if figures:
        parser.add_argument("--figures", type=Path, metavar="DIR", help="draw the figures into this folder")
    args = parser.parse_args()
    if args.from_analyses:
        write_runs(args.from_analyses)
    if figures and args.figures:
        figures(args.figures)
    print(report())
