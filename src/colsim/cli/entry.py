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
    colsim export-vtk a ParaView time series of a collapse
    colsim status     the runs under a results folder: done, and in progress from their checkpoints
    colsim mu-r       rolling coefficient of a regular polygon (the paper's Eqs. 7-10)

Arguments are parsed before the heavy imports; bad input ends with a one-line error naming the
value and exit status 2, a failed computation with exit status 1, and never leaves an output file.
"""
from __future__ import annotations

import argparse
import logging
import math
import sys
from pathlib import Path

from ..engine.state import FRICTION_LAWS, ROLLING_LEVERS, FrictionLaw
from ..solvers import defaults
from ..stages import collapse_defaults
from ..stages.pack_defaults import CHECKPOINT_EVERY, DEFAULT_MAX_SPHERES, FREEZE_DEPTH, LAYER_HEIGHT

log = logging.getLogger("colsim")

LENGTH = "length units of the particles (the paper: diameters 0.25-0.5)"


def _number(text, kind=float, what="a number"):
    """`text` as a finite `kind`; argparse's one-line error naming the value otherwise."""
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def _positive(text):
    value = _number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def _non_negative(text):
    value = _number(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def _positive_or_none(text):
    """A positive number, or None for 'none'."""
    return None if text.strip().lower() in ("none", "null") else _positive(text)


def _positive_int(text):
    value = _number(text, int, "an integer")
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


def _integer(text):
    return _number(text, int, "an integer")


def _solver_arguments(parser):
    parser.add_argument("--solver", default=defaults.DEFAULT_SOLVER, choices=defaults.SOLVERS,
                        help="cone-program back-end (default: %(default)s: APGD for every step, warm or cold, "
                             f"up to dt/sqrt(h0/g) = {defaults.AUTO_APGD_BELOW:g}, Clarabel above and where APGD "
                             "reaches its cap; see docs/solvers.md)")
    parser.add_argument("--solver-tolerance", type=_positive, default=None,
                        help="solver tolerance (default: the back-end's own; for auto, APGD's)")
    parser.add_argument("--threads", type=_positive_int, default=1,
                        help="threads of APGD's loops over contacts and bodies (default: %(default)s; "
                             "results differ between counts by rounding only, far below the tolerance)")


def _length_floor_argument(parser, under_auto: str):
    parser.add_argument("--solver-length-floor", type=_non_negative, default=None,
                        help="APGD's stopping rule: measure its residuals against the step's free flight "
                             f"or this many mean diameters, whichever is larger (default: {under_auto}; "
                             "apgd 0)")


def _floor_under_auto(tolerance: float, which: str) -> str:
    """The length floor's default under auto, and what it guarantees with `tolerance`."""
    floor = defaults.AUTO_APGD_LENGTH_FLOOR
    return (f"under auto {floor:g}: with {which} {tolerance:g}, each contact's gap to "
            f"{floor * tolerance:.0e} of a mean diameter at least")


def _overlap_tolerance_argument(parser):
    parser.add_argument("--solver-overlap-tolerance", type=_non_negative, default=None,
                        help="APGD's stopping rule: a step's contacts count as feasible once no "
                             "end-of-step gap violates its cone by more than this many mean diameters "
                             "(complementarity keeps the relative tolerance; default: under auto "
                             f"{defaults.AUTO_APGD_OVERLAP_TOLERANCE:g}, apgd 0: the relative tolerance alone)")


class _Version(argparse.Action):
    """--version: colsim's version and the git commit of its source, asked only when given."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, **kwargs):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        from .. import __version__
        from ..io.netcdf import source_commit   # as every file names it (colsim_commit)

        print(f"colsim {__version__}, commit {source_commit()}")
        parser.exit()


def _verbosity_arguments(parser, default) -> None:
    """-v and -q, on the main parser (default False) and on each subcommand (default: leave the main
    parser's value), so that `colsim -v pack` and `colsim pack -v` are the same."""
    parser.add_argument("-v", "--verbose", action="store_true", default=default, help="log every detail")
    parser.add_argument("-q", "--quiet", action="store_true", default=default,
                        help="log warnings and errors only (no progress)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="colsim", description=__doc__.split("\n\n")[0])
    _verbosity_arguments(parser, False)
    parser.add_argument("--version", action=_Version, help="show colsim's version and commit, and exit")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("pack", help="fill a cylinder by free fall (mu = mu_r = 0) and let it settle")
    p.add_argument("--r0", type=_positive, default=2.0, help=f"cylinder radius, {LENGTH} (default: %(default)s)")
    p.add_argument("--height", type=_positive, required=True,
                   help="the settled packing must be taller than this (length); use the tallest h0 = a r0 needed")
    p.add_argument("--seed", type=_integer, default=0, help="run seed (default: %(default)s)")
    p.add_argument("--root-seed", type=_integer, default=0,
                   help="study seed; the stream is numpy default_rng([seed, root_seed]) (default: %(default)s)")
    p.add_argument("--diameter-min", type=_positive, default=0.25, help="smallest diameter, length (default: %(default)s)")
    p.add_argument("--diameter-max", type=_positive, default=0.5, help="largest diameter, length (default: %(default)s)")
    p.add_argument("--density", type=_positive, default=1.0, help="particle density, mass/length^3 (default: %(default)s)")
    p.add_argument("--gravity", type=_positive, default=9.81, help="gravity, length/time^2 (default: %(default)s)")
    p.add_argument("--dt", type=_positive, default=0.02, help="time step of the filling, time (default: %(default)s)")
    p.add_argument("--rest-energy", type=_positive, default=1e-3,
                   help="at rest when 95%% of the particles have kinetic energy < this times m g d "
                        "and 99%% carry a contact force (default: %(default)s)")
    p.add_argument("--max-steps", type=_positive_int, default=5000, help="give up after this many steps (default: %(default)s)")
    p.add_argument("--max-spheres", type=_positive_int, default=DEFAULT_MAX_SPHERES,
                   help="refuse, before any work, a packing expected to hold more spheres than this "
                        "(default: %(default)s, about 4 GB)")
    p.add_argument("--mu", type=_non_negative, default=0.0,
                   help="sliding friction between spheres and with the floor while filling; the paper's "
                        "is 0, a small value gives a looser packing (default: %(default)s)")
    p.add_argument("--layer-height", type=_positive_or_none, default=LAYER_HEIGHT,
                   help="fill in clouds that each add about this settled thickness, length (2.5 measured: a "
                        "third of the CPU at r0 = 3); 'none': one cloud for the whole height (default: %(default)s)")
    p.add_argument("--freeze-depth", type=_non_negative, default=FREEZE_DEPTH,
                   help="while filling in layers, spheres at rest more than this below the settled "
                        "surface are fixed and leave the program, length (default: %(default)s)")
    _solver_arguments(p)
    _length_floor_argument(p, _floor_under_auto(defaults.PACK_APGD_TOLERANCE, "the packing's tolerance"))
    _overlap_tolerance_argument(p)
    p.add_argument("--output", required=True, help="packing file to write (netCDF)")
    p.add_argument("--checkpoint-every", type=_positive_int, default=CHECKPOINT_EVERY,
                   help="checkpoint every k steps (default: %(default)s)")
    p.add_argument("--checkpoint", default=None,
                   help="checkpoint file (default: OUTPUT.checkpoint); the same command resumes from it")

    p = sub.add_parser("trim", help="remove the spheres that reach above h0 = a r0 (z + R > h0)")
    p.add_argument("--input", required=True, help="packing file from `colsim pack`")
    p.add_argument("--aspect-ratio", type=_positive, required=True, help="a = h0 / r0, dimensionless")
    p.add_argument("--output", required=True, help="column file to write (netCDF)")

    p = sub.add_parser("collapse", help="remove the cylinder and integrate the collapse")
    p.add_argument("--input", required=True, help="column file from `colsim trim`")
    p.add_argument("--mu", type=_non_negative, default=0.577, help="sliding friction coefficient (default: %(default)s)")
    p.add_argument("--mu-r", type=_non_negative, default=0.12, help="rolling resistance coefficient (default: %(default)s)")
    p.add_argument("--floor-mu", type=_non_negative, default=None, help="floor's mu (default: same as --mu)")
    p.add_argument("--floor-mu-r", type=_non_negative, default=None, help="floor's mu_r (default: same as --mu-r)")
    p.add_argument("--friction-law", choices=FRICTION_LAWS, default="associated",
                   help="associated (the paper's: a sliding contact opens by mu |du_t| a step) or coulomb "
                        "(non-associated: it does not; a fixed point of cone programs) (default: %(default)s)")
    p.add_argument("--friction-tolerance", type=_positive, default=FrictionLaw().tolerance,
                   help="coulomb: stop the fixed point when its gap correction changes by at most this "
                        "many mean diameters, root mean square over the contacts (default: %(default)s)")
    p.add_argument("--rolling-lever", choices=ROLLING_LEVERS, default="paper",
                   help="lever L of the rolling moment L r between two spheres: paper (its Eqs. 6 and 9: "
                        "2 R_i R_j/(R_i + R_j), each radius when equal) or effective (R_eff = R_i R_j/(R_i + R_j), "
                        "the common DEM convention, half of it); R_i at the floor either way (default: %(default)s)")
    p.add_argument("--duration", type=_positive, default=collapse_defaults.DURATION,
                   help="end time t / sqrt(h0/g), dimensionless (default: %(default)s)")
    p.add_argument("--steps", type=_positive_int, default=collapse_defaults.STEPS,
                   help="number of equal steps (default: %(default)s, converged; the paper's is 100)")
    p.add_argument("--max-duration", type=_positive, default=None,
                   help="go on past --duration at the same dt until the deposit is at rest, up to this "
                        "t / sqrt(h0/g) (default: stop at --duration)")
    p.add_argument("--rest-window", type=_positive, default=collapse_defaults.REST_WINDOW,
                   help="at rest: h_inf and r_inf steady over this t / sqrt(h0/g) (default: %(default)s)")
    p.add_argument("--rest-tolerance", type=_positive, default=collapse_defaults.REST_TOLERANCE,
                   help="at rest: h_inf and r_inf moved less than this many mean diameters (default: %(default)s)")
    p.add_argument("--rest-energy", type=_positive, default=collapse_defaults.REST_ENERGY,
                   help="at rest: kinetic energy below this times its peak (default: %(default)s)")
    p.add_argument("--frame-every", type=_positive_int, default=collapse_defaults.FRAME_EVERY,
                   help="keep a frame every k steps (default: %(default)s)")
    p.add_argument("--checkpoint-every", type=_positive_int, default=collapse_defaults.CHECKPOINT_EVERY,
                   help="checkpoint every k steps (default: %(default)s)")
    p.add_argument("--checkpoint", default=None, help="checkpoint file (default: OUTPUT.checkpoint)")
    _solver_arguments(p)
    _length_floor_argument(p, _floor_under_auto(defaults.AUTO_APGD_TOLERANCE, "the tolerance"))
    _overlap_tolerance_argument(p)
    p.add_argument("--output", required=True, help="trajectory file to write (netCDF)")

    p = sub.add_parser("analyse", help="final height, run-out, deposit profile and front position")
    p.add_argument("--input", required=True, help="trajectory file from `colsim collapse`")
    p.add_argument("--contact-tolerance", type=_non_negative, default=0.01,
                   help="particles touch when their gap <= this fraction of the smallest diameter (default: %(default)s)")
    p.add_argument("--check-tolerances", type=_non_negative, nargs="*", default=[0.1, 0.5, 1.0],
                   help="also measure the run-out with these contact tolerances (default: %(default)s)")
    p.add_argument("--mass-shares", type=_positive, nargs="*", default=[0.9, 0.95, 0.99],
                   help="also report the radius holding these shares of the mass (default: %(default)s)")
    p.add_argument("--bin-width", type=_positive, default=None, help="radial bin of the deposit profile, length (default: largest diameter)")
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
    p.add_argument("--default-end", type=_positive, required=True,
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
    p.add_argument("--replicates", type=_positive_int, default=1000, help="bootstrap replicates (default: %(default)s)")
    p.add_argument("--fit-tolerance", type=_positive, default=0.1,
                   help="a limit fits a law within this relative error (default: %(default)s)")

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

    p = sub.add_parser("mu-r", help="rolling coefficient of a regular polygon (the paper's Eqs. 7-10)")
    p.add_argument("--polygon", type=_integer, required=True, help="number of sides N >= 3")
    p.add_argument("--method", choices=["paper", "exact"], default="paper",
                   help="paper: linear fall of the resisting moment (pi/(4N)); exact: true lever arm (default: %(default)s)")
    for subparser in sub.choices.values():
        _verbosity_arguments(subparser, argparse.SUPPRESS)
        if subparser.description is None:   # each subcommand's help line heads its own --help
            subparser.description = next(a.help for a in sub._choices_actions if a.dest == subparser.prog.split()[-1])
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.verbose and args.quiet:
        parser.error("-v and -q contradict each other")
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s: %(message)s", stream=sys.stderr)
    from . import commands
    from ..io.netcdf import InputError
    from ..engine.solver_contract import SolverError
    from ..engine.stepper import OverlapError

    try:
        commands.check_outputs(args)
        getattr(commands, args.command.replace("-", "_"))(args)
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


def _interrupted(args) -> str:
    """What an interrupted command leaves behind, and how to go on."""
    if args.command not in ("collapse", "pack"):
        return "no output was written"
    checkpoint = Path(args.checkpoint or f"{args.output}.checkpoint")
    if not checkpoint.is_file():
        return "no checkpoint was written yet: run the same command again to start over"
    return f"the checkpoint {checkpoint} is kept: run the same command again to resume from it"

