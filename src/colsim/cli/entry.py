"""The `colsim` command: one subcommand per stage of the study.

    colsim pack       fill a cylinder by free fall until the packing is taller than --height
    colsim trim       cut a packing at h0 = a r0
    colsim collapse   remove the cylinder and integrate the collapse (checkpointed, resumable)
    colsim analyse    final height, run-out, deposit profile and front of a collapse
    colsim collect    gather analyses into one dataset over (aspect_ratio, mu_r, seed)
    colsim plot       the study's figures from the collected dataset and the analyses
    colsim convergence  time step, end time, column size and seed studies in one table and figure
    colsim compare-laws the same runs under both friction laws, against Lube's laws
    colsim calibrate  which mu_r gives Lube's (and Lajeunesse's) laws in the large-column limit
    colsim length-convergence  a channel study's run-outs at several box lengths L0: converged in L0?
    colsim export-vtk a ParaView time series of a collapse
    colsim status     the runs under a results folder: done, and in progress from their checkpoints
    colsim mu-r       rolling coefficient of a regular polygon (the paper's Eqs. 7-10)

Arguments are parsed before the heavy imports; bad input ends with a one-line error naming the
value and exit status 2, a failed computation with exit status 1, and never leaves an output file.
"""
from __future__ import annotations

import argparse
import difflib
import logging
import os
import sys
from pathlib import Path

from ..engine.state import FRICTION_LAWS
from ..stages import settings
from .flags import (add_settings_arguments, add_settings_file_argument, integer, positive, positive_int)

log = logging.getLogger("colsim")


def _stage_arguments(parser, stage: str) -> None:
    """A stage's --settings file and one flag per setting (colsim.stages.settings), the back-end's
    too where the stage solves cone programs."""
    add_settings_file_argument(parser, stage)
    add_settings_arguments(parser, settings.STAGES[stage])
    if stage in settings.SOLVING_STAGES:
        add_settings_arguments(parser, settings.SolverSettings)


class _Version(argparse.Action):
    """--version: colsim's version and the git commit of its source, asked only when given."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, **kwargs):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        from .. import __version__
        from ..io.provenance import source_commit   # as every file names it (colsim_commit)

        print(f"colsim {__version__}, commit {source_commit()}")
        parser.exit()


def _verbosity_arguments(parser, default) -> None:
    """-v and -q, on the main parser (default False) and on each subcommand (default: leave the main
    parser's value), so that `colsim -v pack` and `colsim pack -v` are the same."""
    parser.add_argument("-v", "--verbose", action="store_true", default=default, help="log every detail")
    parser.add_argument("-q", "--quiet", action="store_true", default=default,
                        help="log warnings and errors only (no progress)")


class _Parser(argparse.ArgumentParser):
    """A parser that takes a flag only as spelled in full (`--step` is not `--steps`), and whose
    subcommands are its own kind."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)


def _unrecognised(extras: list[str], parser: argparse.ArgumentParser) -> str:
    """The error for arguments `parser` (a subcommand's) does not know, with the flag meant where
    one is close (`--mu_r`: `--mu-r`)."""
    flags = [option for action in parser._actions for option in action.option_strings]
    hints = []
    for extra in extras:
        given = extra.split("=", 1)[0]
        if not given.startswith("--"):
            continue
        close = [given.replace("_", "-")] if given.replace("_", "-") in flags else \
            difflib.get_close_matches(given, flags, n=1, cutoff=0.75)
        hints += [f"{given}: did you mean {close[0]}?"] if close else []
    return f"unrecognized arguments: {' '.join(extras)}" + (f" ({'; '.join(hints)})" if hints else "")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="colsim", description=__doc__.split("\n\n")[0])
    _verbosity_arguments(parser, False)
    parser.add_argument("--version", action=_Version, help="show colsim's version and commit, and exit")
    sub = parser.add_subparsers(dest="command", required=True)
    parser.commands = sub.choices   # the subcommands' parsers, which name themselves in their errors

    p = sub.add_parser("pack", help="fill a cylinder by free fall (mu_r = 0, and mu = 0 unless --mu) and let it settle")
    _stage_arguments(p, "pack")
    p.add_argument("--output", required=True, help="packing file to write (netCDF)")
    p.add_argument("--checkpoint", default=None,
                   help="checkpoint file (default: OUTPUT.checkpoint); the same command resumes from it")

    p = sub.add_parser("trim", help="remove the spheres that reach above h0 = a r0 (z + R > h0)")
    p.add_argument("--input", required=True, help="packing file from `colsim pack`")
    _stage_arguments(p, "trim")
    p.add_argument("--output", required=True, help="column file to write (netCDF)")

    p = sub.add_parser("collapse", help="remove the cylinder and integrate the collapse")
    p.add_argument("--input", required=True, help="column file from `colsim trim`")
    _stage_arguments(p, "collapse")
    p.add_argument("--checkpoint", default=None, help="checkpoint file (default: OUTPUT.checkpoint)")
    p.add_argument("--output", required=True, help="trajectory file to write (netCDF)")

    p = sub.add_parser("analyse", help="final height, run-out, deposit profile and front position")
    p.add_argument("--input", required=True, help="trajectory file from `colsim collapse`")
    _stage_arguments(p, "analyse")
    p.add_argument("--output", required=True, help="analysis file to write (netCDF)")

    p = sub.add_parser("collect", help="gather analyses into one dataset over (aspect_ratio, mu_r, seed)")
    p.add_argument("inputs", nargs="+", help="analysis files from `colsim analyse`")
    p.add_argument("--output", required=True, help="summary file to write (netCDF)")
    p.add_argument("--csv", default=None, help="also write the table as CSV here")
    p.add_argument("--markdown", default=None,
                   help="also write h_inf/r0 and the run-out against Lube's laws (mean over seeds) as Markdown here")

    p = sub.add_parser("convergence", help="the convergence study: one table over runs, its figure and relative changes")
    for study in ("time-step", "end-time", "column-size", "seeds"):
        p.add_argument(f"--{study}", nargs="*", default=[], help=f"analysis files of the {study.replace('-', ' ')} study")
    p.add_argument("--default-end", type=positive, required=True,
                   help="the study's end time t/sqrt(h0/g); runs that go on are measured there too")
    p.add_argument("--output", required=True, help="table to write (netCDF)")
    p.add_argument("--csv", default=None, help="also write the table as CSV here")
    p.add_argument("--markdown", default=None, help="also write the relative changes as Markdown here")
    p.add_argument("--figure", default=None, help="also draw the figure (PNG) here")
    p.add_argument("--limits", default=None,
                   help="also write the column-size limits (X = X_inf + k (d/r0)^p per a; netCDF) here")
    p.add_argument("--size-figure", default=None,
                   help="also draw the column-size runs, fits and limits against Lube and Lajeunesse (PNG) here")

    p = sub.add_parser("compare-laws", help="the same runs under the associated and the Coulomb friction law: "
                                            "one table against Lube's laws and a figure")
    for law in FRICTION_LAWS:
        p.add_argument(f"--{law}", nargs="+", required=True, help=f"analysis files of the runs under the {law} law")
    p.add_argument("--output", required=True, help="both summaries over friction_law (netCDF)")
    p.add_argument("--markdown", default=None, help="also write the table as Markdown here")
    p.add_argument("--figure", default=None, help="also draw the figure (PNG) here")

    p = sub.add_parser("calibrate", help="the mu_r calibration: limits per mu_r and a, the misfit to Lube's and "
                                         "Lajeunesse's laws and the mu_r minimising it, with intervals")
    p.add_argument("inputs", nargs="+", help="analysis files of the runs over mu_r, a, r0 (two or more) and seeds")
    p.add_argument("--output", required=True, help="the calibration to write (netCDF)")
    p.add_argument("--markdown", default=None, help="also write its tables as Markdown here")
    p.add_argument("--figure", default=None, help="also draw its figure (PNG) here")
    p.add_argument("--replicates", type=positive_int, default=1000, help="bootstrap replicates (default: %(default)s)")
    p.add_argument("--fit-tolerance", type=positive, default=0.1,
                   help="a limit fits a law within this relative error (default: %(default)s)")

    p = sub.add_parser("length-convergence", help="a channel study's run-outs at each box length L0 and their "
                                                  "spread between the two largest")
    p.add_argument("inputs", nargs="+", help="analysis files of channel runs at two box lengths or more")
    p.add_argument("--output", required=True, help="the run-outs by box length to write (netCDF)")
    p.add_argument("--markdown", default=None, help="also write the table as Markdown here")

    p = sub.add_parser("plot", help="the study's figures")
    p.add_argument("--summary", required=True, help="summary file from `colsim collect`")
    p.add_argument("--analyses", nargs="*", default=[], help="analysis files (profiles and fronts)")
    p.add_argument("--trajectories", nargs="*", default=[], help="trajectory files (side views)")
    p.add_argument("--output-dir", required=True, help="directory for the PNG figures")

    p = sub.add_parser("export-vtk", help="ParaView time series (.vtu per frame + .pvd) of a collapse")
    p.add_argument("--input", required=True, help="trajectory file from `colsim collapse`")
    p.add_argument("--output-dir", required=True, help="directory to write into")

    p = sub.add_parser("status", help="the runs under a results folder: done, and in progress from their checkpoints")
    p.add_argument("folder", nargs="?", default="results",
                   help="the folder holding the runs (default: %(default)s, where every study's runs are)")

    p = sub.add_parser("docs", help="remake the results tables of README.md and docs/ from the datasets in docs/data")
    p.add_argument("--root", default=".", help="the repository's root (default: %(default)s)")
    p.add_argument("--check", action="store_true",
                   help="write nothing; exit 1 and name the files whose tables differ from the data")

    p = sub.add_parser("mu-r", help="rolling coefficient of a regular polygon (the paper's Eqs. 7-10)")
    p.add_argument("--polygon", type=integer, required=True, help="number of sides N >= 3")
    p.add_argument("--method", choices=["paper", "exact"], default="paper",
                   help="paper: linear fall of the resisting moment (pi/(4N)); exact: true lever arm (default: %(default)s)")
    for subparser in sub.choices.values():
        _verbosity_arguments(subparser, argparse.SUPPRESS)
        if subparser.description is None:   # each subcommand's help line heads its own --help
            subparser.description = next(action.help for action in sub._choices_actions
                                         if action.dest == subparser.prog.split()[-1])
    return parser


def environment_problem(environ) -> str | None:
    """One line naming an environment variable that would stop numba as it loads (NUMBA_NUM_THREADS
    not a whole number >= 1: numba's import raises), or None."""
    threads = environ.get("NUMBA_NUM_THREADS")
    if threads is not None and not (threads.strip().isdigit() and int(threads) >= 1):
        return (f"NUMBA_NUM_THREADS={threads!r}: numba needs a whole number >= 1 (or leave it unset for every"
                " core); --threads sets a command's threads")
    return None


def main(argv=None) -> int:
    parser = build_parser()
    args, extras = parser.parse_known_args(argv)
    if extras:   # said by the subcommand's parser, which names itself (`colsim collapse: error: ...`)
        command = parser.commands[args.command]
        command.error(_unrecognised(extras, command))
    if args.verbose and args.quiet:
        parser.error("-v and -q contradict each other")
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s: %(message)s", stream=sys.stderr)
    logging.getLogger("numba").setLevel(logging.WARNING)   # its CUDA driver logs each free at INFO: 16 MB a collapse
    problem = environment_problem(os.environ)
    if problem:
        print(f"colsim {args.command}: error: {problem}", file=sys.stderr)
        return 2
    from . import commands
    from ..io.files import InputError
    from ..engine.solver_contract import SolverError
    from ..engine.stepper import OverlapError

    try:
        _run(commands, args)
    except KeyboardInterrupt:
        print(f"colsim {args.command}: interrupted; {_interrupted(args)}", file=sys.stderr)
        return 130
    except OverflowError as error:
        print(f"colsim {args.command}: error: a value is too large to compute with ({error}): check the "
              "lengths, times and step given", file=sys.stderr)
        return 2
    except (InputError, ValueError) as error:
        print(f"colsim {args.command}: error: {error}", file=sys.stderr)
        return 2
    except KeyError as error:
        print(f"colsim {args.command}: error: an input file lacks {error} (not a file colsim wrote?)", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"colsim {args.command}: failed: out of memory (a column or setting too large for this "
              "machine: fewer spheres, a larger --bin-width, ...)", file=sys.stderr)
        return 1
    except OSError as error:
        print(f"colsim {args.command}: failed: {error.strerror or error} ({error.filename or 'no file'})",
              file=sys.stderr)
        return 1
    except (SolverError, OverlapError, RuntimeError) as error:
        print(f"colsim {args.command}: failed: {error}", file=sys.stderr)
        return 1
    return 0


class GpuFailure(RuntimeError):
    """An error of the GPU's driver or its bindings, said in one line (:func:`_gpu_failure`)."""


def _run(commands, args) -> None:
    """Run the command; an error from the GPU becomes a GpuFailure."""
    try:
        commands.check_outputs(args)
        getattr(commands, args.command.replace("-", "_"))(args)
    except Exception as error:
        if _from_the_gpu(error):
            raise GpuFailure(_gpu_failure(error)) from error
        raise


#: the packages whose errors come from the GPU's driver or its bindings (numba-cuda's CudaAPIError,
#: CudaSupportError, ...; cuda.core's CUDAError), named by module: nothing is imported to tell
GPU_ERROR_MODULES = ("numba.cuda", "numba_cuda", "cuda.core", "cuda.bindings")


def _from_the_gpu(error: BaseException) -> bool:
    """Whether `error` was raised by the GPU's driver or its bindings."""
    return type(error).__module__.startswith(GPU_ERROR_MODULES)


def _gpu_failure(error: BaseException) -> str:
    """What a GPU's error means for the run, in one line."""
    if "OUT_OF_MEMORY" in str(error):
        return (f"out of the GPU's memory ({error}): a column too large for this card; --device cpu runs "
                "it on the CPU")
    return f"on the GPU: {type(error).__name__}: {error}"


def _interrupted(args) -> str:
    """What an interrupted command leaves behind, and how to go on."""
    if args.command not in ("collapse", "pack"):
        return "no output was written"
    checkpoint = Path(args.checkpoint or f"{args.output}.checkpoint")
    if not checkpoint.is_file():
        return "no checkpoint was written yet: run the same command again to start over"
    return f"the checkpoint {checkpoint} is kept: run the same command again to resume from it"

