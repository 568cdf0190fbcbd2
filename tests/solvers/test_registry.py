"""The solver registry (colsim.solvers.registry): the solver by name and the auto rule (APGD for small
steps, warm or cold; Clarabel for larger ones and at the iteration cap)."""
import numpy as np

from colsim.engine.cones import mean_diameter
from colsim.engine.program import cone_violation
from colsim.engine.stepper import run
from colsim.solvers import AutoSolver, ClarabelSolver, WarmStart, make_solver
from colsim.solvers.apgd import ApgdSolver

from solver_cases import COLLAPSE, collapse_program


def test_auto_picks_apgd_for_small_steps_warm_or_cold(solver_pile):
    program, found = collapse_program(solver_pile)
    reference = ClarabelSolver().solve(program)
    warm = WarmStart.from_step(found, reference.forces).match(found)
    assert AutoSolver().solve(program, warm_start=warm).backend == "apgd"
    assert AutoSolver(scaled_time_step=0.04).solve(program, warm_start=warm).backend == "apgd"
    assert AutoSolver(scaled_time_step=0.08).solve(program, warm_start=warm).backend == "clarabel"
    assert AutoSolver(scaled_time_step=0.08).solve(program).backend == "clarabel"
    cold = AutoSolver(scaled_time_step=0.004).solve(program)                    # no warm start
    assert cold.backend == "apgd" and cold.info["start"] == "cold"
    assert AutoSolver().solve(program, warm_start=np.zeros_like(warm)).backend == "apgd"
    assert isinstance(make_solver("auto"), AutoSolver)


def test_a_cold_step_by_apgd_meets_its_stopping_rule(solver_pile):
    """The cold step auto gives to APGD ends within APGD's stopping rule: forces in the cones
    (exact: a projection), no gap beyond the overlap tolerance (1e-4 mean diameters) and the
    relative complementarity below the tolerance (1e-5). (How close that is to Clarabel's answer
    is a measurement, not a bound: the net force on the spheres within 0.15 % here, 2-7 % on the
    columns of `python -m benchmarks cold_step`, docs/solvers.md.)"""
    program, _ = collapse_program(solver_pile)
    solution = AutoSolver(scaled_time_step=0.004).solve(program)
    violation = cone_violation(program, solution.increments, solution.forces)
    assert violation["dual"] <= 1e-12 * np.abs(solution.forces).max()
    assert violation["primal"] <= AutoSolver.APGD_OVERLAP_TOLERANCE * mean_diameter(program) * (1 + 1e-9)
    assert solution.info["complementarity"] <= AutoSolver.APGD_TOLERANCE


def test_stepper_records_the_backend_of_each_step(solver_pile):
    results = list(run(solver_pile, COLLAPSE, 3, make_solver("apgd")))
    assert [r.solution.info["start"] for r in results] == ["cold", "warm", "warm"]
    backends = [r.diagnostics.solver_backend for r in run(solver_pile, COLLAPSE, 3, AutoSolver())]
    assert backends == ["apgd", "apgd", "apgd"]


def test_auto_falls_back_to_clarabel_at_the_iteration_cap(solver_pile):
    """A step that APGD cannot finish within the cap, cold or warm-started, is solved by Clarabel,
    and the step's diagnostics say so."""
    backends = [r.diagnostics.solver_backend for r in run(solver_pile, COLLAPSE, 3, AutoSolver(max_iter=3))]
    assert backends == ["clarabel-fallback"] * 3


def _solver_settings(parser, argv):
    """The back-end's settings (colsim.stages.settings.SolverSettings) a command line gives."""
    from colsim.cli.flags import stage_settings
    from colsim.stages.settings import SolverSettings
    return stage_settings(parser.parse_args(argv), SolverSettings)


def test_auto_uses_the_length_floor_in_both_stages():
    from colsim.cli import build_parser
    from colsim.cli.commands import _pack_solver, _solver
    assert AutoSolver().apgd.length_floor == AutoSolver.APGD_LENGTH_FLOOR > 0
    assert ApgdSolver().length_floor == 0.0
    parser = build_parser()
    collapse_args = _solver_settings(parser, ["collapse", "--input", "c.nc", "--output", "t.nc"])
    assert _solver(collapse_args, 0.004).apgd.length_floor == AutoSolver.APGD_LENGTH_FLOOR
    pack_args = _solver_settings(parser, ["pack", "--height", "2", "--output", "p.nc"])
    assert _pack_solver(pack_args).apgd.length_floor == AutoSolver.APGD_LENGTH_FLOOR
    chosen = _solver_settings(parser, ["collapse", "--input", "c.nc", "--output", "t.nc", "--solver", "apgd",
                                "--solver-length-floor", "0.5"])
    assert _solver(chosen, 0.004).length_floor == 0.5


def test_auto_loosens_only_the_collapse_primal_by_its_overlap_tolerance():
    """Under auto the collapse's APGD may stop at a largest violation of 1e-4 mean diameters; the
    packing's own primal bound (tolerance 1e-3 x at least 0.1 d) is already that loose, so the
    packing goes without it, and records its settings as before the option existed."""
    from colsim.cli import build_parser
    from colsim.cli.commands import _pack_solver, _solver
    from colsim.solvers.defaults import PACK_APGD_TOLERANCE as APGD_TOLERANCE
    assert AutoSolver().apgd.overlap_tolerance == AutoSolver.APGD_OVERLAP_TOLERANCE > 0
    assert ApgdSolver().overlap_tolerance == 0.0
    assert AutoSolver.APGD_OVERLAP_TOLERANCE <= APGD_TOLERANCE * AutoSolver.APGD_LENGTH_FLOOR
    parser = build_parser()
    collapse_args = _solver_settings(parser, ["collapse", "--input", "c.nc", "--output", "t.nc"])
    assert _solver(collapse_args, 0.004).apgd.overlap_tolerance == AutoSolver.APGD_OVERLAP_TOLERANCE
    pack_args = _solver_settings(parser, ["pack", "--height", "2", "--output", "p.nc"])
    packing = _pack_solver(pack_args)
    assert packing.apgd.overlap_tolerance == 0.0
    assert "overlap_tolerance" not in packing.describe()["apgd"]
    assert _solver(collapse_args, 0.004).describe()["apgd"]["overlap_tolerance"] == 1e-4
    chosen = _solver_settings(parser, ["pack", "--height", "2", "--output", "p.nc", "--solver-overlap-tolerance", "1e-5"])
    assert _pack_solver(chosen).apgd.overlap_tolerance == 1e-5
