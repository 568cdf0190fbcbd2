"""The benchmarks' one entry point.

    python -m benchmarks list                        # the benchmarks, one line each
    python -m benchmarks NAME [ARGS...]              # one benchmark, with its own arguments
    python -m benchmarks NAME --help                 # its arguments
    python -m benchmarks all --quick                 # the set at small sizes (minutes)
    python -m benchmarks all                         # the set at its default sizes (many hours)
    python -m benchmarks --results DIR NAME ...      # records into DIR (default results/benchmarks/)

Every benchmark prints its tables and writes them, with the machine, the versions, the commit and
the arguments, to a JSON record (benchmarks/record.py). `all` runs each benchmark in its own
process, in the order below (packings and columns first: the others use them), goes on past a
failure and ends with a summary; the benchmarks that need a column (a `colsim trim` file) get the
one collapse.py makes (r0 = 1, a = 2 with --quick; r0 = 2, a = 5 without).
Run from the repository root (or with it on PYTHONPATH).
"""
from __future__ import annotations

import importlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:   # the scripts import each other as plain modules (packings, record)
    sys.path.insert(0, str(HERE))

import record   # noqa: E402

#: the benchmarks, in the order `all` runs them
NAMES = ("packings", "step", "solvers", "collapse", "apgd_iteration", "threads", "crossover",
         "stopping", "trajectory", "tolerance", "cold_step", "study_cost", "cuda_operator", "gpu",
         "device_copies", "ptx", "host_work", "scatter", "kernel_trace", "checkpoints")

#: the column of `all` (collapse.column_file's r0, aspect ratio, seed, packing solver and dt)
COLUMN = {"quick": (1.0, 2.0, 1, "auto", 0.02), "full": (2.0, 5.0, 1, "auto", 0.02)}


def arguments_for_all(name: str, quick: bool, column: Path | None, scratch: Path) -> list[str] | None:
    """A benchmark's arguments in `all` (quick: seconds each on a 100-200 sphere packing); None: skip it."""
    c = [str(column)] if column is not None else []
    if quick:
        r0, a = COLUMN["quick"][:2]
        return {
            "packings": ["100"],
            "step": ["--sizes", "100", "--configs", "faer:1", "--repeat", "1"],
            "solvers": ["--sizes", "100", "--mid-steps", "2"],
            "collapse": ["--r0", f"{r0:g}", "--aspect-ratio", f"{a:g}", "--runs", "clarabel-1000"],
            "apgd_iteration": [*c, "--iterations", "20"],
            "threads": [*c, "--threads", "1", "--steps", "5", "--iterations", "20"],
            "crossover": [*c, "--scaled-dt", "0.04", "--steps", "5"],
            "stopping": [*c, "--steps", "2", "--n-steps", "100"],
            "trajectory": [*c, "--steps", "3", "--length-floors", "0.1"],
            "tolerance": [*c, "--tolerances", "1e-3", "--steps", "100", "--record",
                          str(scratch / "tolerance.jsonl")],
            "cold_step": c,
            "study_cost": _study_results(),
            "cuda_operator": _cuda(["--spheres", "200", "--repeat", "1"]),
            "gpu": _cuda(["--spheres", "100", "--iterations", "3"]),
            "device_copies": _cuda(["--steps", "1"]),
            "ptx": _card_compiler([]),
            "host_work": [*c, "--repeat", "1"],
            "scatter": None,
            "kernel_trace": None,
            "checkpoints": [*c, "--steps", "100", "--every", "50"],
        }[name]
    r0, a = COLUMN["full"][:2]
    return {
        "packings": ["1000", "4000"], "step": [], "solvers": [], "collapse": [],
        "apgd_iteration": [], "threads": c, "crossover": c, "stopping": [*c, "--steps", "2", "50", "300", "900"],
        "trajectory": c, "tolerance": [*c, "--record", str(scratch / "tolerance.jsonl")], "cold_step": c,
        "study_cost": _study_results(),
        "cuda_operator": _cuda([]),
        "gpu": _cuda([]),
        "device_copies": _cuda([]),
        "ptx": _card_compiler([]),
        "host_work": c,
        "scatter": None,
        "kernel_trace": None,
        "checkpoints": c,
    }[name]


def _cuda(arguments: list[str]) -> list[str] | None:
    """A GPU benchmark's arguments where a GPU (or numba's CUDA simulator) answers, else None (skipped)."""
    try:
        from numba import cuda

        return arguments if cuda.is_available() else None
    except ImportError:
        return None


def _card_compiler(arguments: list[str]) -> list[str] | None:
    """A benchmark's arguments where a card's kernels can be compiled here (numba-cuda and libNVVM,
    benchmarks/ptx.py), else None (skipped)."""
    import ptx

    return None if ptx.compiler_missing() else arguments


def _study_results() -> list[str] | None:
    """study_cost's argument: the repository's results/ when a study has made runs there, else None
    (`all` then skips it: it reads a study's runs and makes none)."""
    results = HERE.parent / "results"
    return [str(results)] if any(results.glob("r0_*/seed_*/pack_*/packing.nc")) else None


def describe(name: str) -> str:
    """The first line of a benchmark's docstring (read without importing it)."""
    import ast

    source = (HERE / f"{name}.py").read_text()
    doc = ast.get_docstring(ast.parse(source)) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def run_one(name: str, argv: list[str]) -> None:
    if name not in NAMES:
        raise SystemExit(f"unknown benchmark {name!r}; `python -m benchmarks list` lists them")
    module = importlib.import_module(name)
    record.run(name, module.main, argv)


def run_all(quick: bool) -> int:
    failed, times = [], {}
    with tempfile.TemporaryDirectory(prefix="colsim-benchmarks-") as scratch:
        column = None
        for name in NAMES:
            if name not in ("packings", "step", "solvers", "collapse") and column is None:
                import collapse

                column = collapse.column_file(*COLUMN["quick" if quick else "full"])
            argv = arguments_for_all(name, quick, column, Path(scratch))
            if argv is None:
                why = {"study_cost": "no study's runs under results/",
                       "cuda_operator": "no GPU; NUMBA_ENABLE_CUDASIM=1 runs it on numba's simulator",
                       "gpu": "no GPU; NUMBA_ENABLE_CUDASIM=1 runs it on numba's simulator",
                       "device_copies": "no GPU; NUMBA_ENABLE_CUDASIM=1 runs it on numba's simulator",
                       "scatter": "a study of collapses on a given column and run settings, not a timing",
                       "kernel_trace": "a trace of a command on a GPU (benchmarks/gpu_machine.sh's POUR_PROFILE)"}[name]
                print(f"\n## {name}: skipped ({why})", flush=True)
                continue
            print(f"\n## {name} {' '.join(argv)}", flush=True)
            start = time.perf_counter()
            done = subprocess.run([sys.executable, "-m", "benchmarks", name, *argv], cwd=HERE.parent,
                                  env={**os.environ, "PYTHONPATH": _pythonpath()})
            times[name] = time.perf_counter() - start
            if done.returncode != 0:
                failed.append(name)
    print("\n| benchmark | wall s | result |\n|---|---|---|")
    for name, seconds in times.items():
        print(f"| {name} | {seconds:.0f} | {'FAILED' if name in failed else 'ok'} |")
    return 1 if failed else 0


def _pythonpath() -> str:
    """The repository root first, so that `-m benchmarks` resolves from any folder."""
    parts = [str(HERE.parent), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    return os.pathsep.join(parts)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--results"] and len(argv) >= 2:
        os.environ[record.RESULTS_ENV] = str(Path(argv[1]).resolve())   # children inherit it
        argv = argv[2:]
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(__doc__)
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name == "list":
        width = max(map(len, NAMES))
        for n in NAMES:
            print(f"{n:<{width}}  {describe(n)}")
        return 0
    if name == "all":
        unknown = [a for a in rest if a != "--quick"]
        if unknown:
            raise SystemExit(f"all takes only --quick, not {unknown}")
        return run_all("--quick" in rest)
    run_one(name, rest)
    return 0


if __name__ == "__main__":
    sys.exit(main())
