"""Compare the cone-program back-ends (Clarabel, APGD, ADMM, SCS) on one step of settled columns.

    python benchmarks/solvers.py                      # 1,000 and 4,000 spheres
    python benchmarks/solvers.py --sizes 1000 4000 16000 64000 --skip-clarabel-above 20000
    python benchmarks/solvers.py --scs                # add SCS (force form, eps 1e-6)
    python benchmarks/solvers.py --no-apgd            # Clarabel and ADMM only (ADMM steps to 'mid')

For each size: a settled packing (benchmarks/packings.py's settled_packing when it is there,
otherwise poured here and cached under benchmarks/.cache), with the cylinder removed and the
collapse law (mu = 0.577, mu_r = 0.12). Two programs:
  - "release": the first step after release (cold start for every solver);
  - "mid": a step some steps into the collapse, solved cold and warm (APGD and ADMM warm-started
    from the previous step's forces, matched by contact pair).
Printed per solver: seconds per step, iterations, milliseconds per iteration, peak memory of the
solve (tracemalloc: Python/numpy allocations; Clarabel's own Rust allocations are not seen, so the
process's peak RSS is printed as well) and the relative difference of the increments from Clarabel.
For ADMM also: its rho at the end, refactorisations, factorisation seconds and linear-solve seconds.
"""
from __future__ import annotations

import argparse
import os
import pickle
import resource
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

import record
from colsim.stages.pack import starting_cloud

from colsim.solvers.admm import AdmmSolver
from colsim.solvers.apgd import ApgdSolver
from colsim.engine.contacts import detect
from colsim.engine.program import assemble
from colsim.solvers import ClarabelSolver, SolverError, WarmStart
from colsim.engine.state import ContactLaw, ParticleState, StepSettings, Walls
from colsim.engine.backend import predicted_displacement
from colsim.engine.stepper import run, step

HERE = Path(__file__).resolve().parent
CACHE = record.cache_dir()
COLLAPSE = StepSettings(dt=0.02, law=ContactLaw.uniform(0.577, 0.12))


def radius_for(n: int) -> float:
    """Cylinder radius r0 giving a settled column about 2 r0 high for n spheres (d in [0.25, 0.5])."""
    return 0.204 * n ** (1.0 / 3.0)


def pour(n: int, seed: int = 0, max_steps: int = 2000, verbose=True) -> ParticleState:
    """n spheres poured into a cylinder (mu = mu_r = 0) until at rest; APGD does the pouring."""
    r0 = radius_for(n)
    state = starting_cloud(n, r0, seed)
    settings = StepSettings(dt=0.02, walls=Walls(cylinder_radius=r0))
    weight_scale = float(np.mean(state.mass)) * 9.81 * 2 * float(np.mean(state.radius))
    solver = ApgdSolver(tolerance=1e-4)
    for result in run(state, settings, max_steps, solver):
        state = result.state
        d = result.diagnostics
        energy = (d.kinetic_energy + d.rotational_energy) / n
        if verbose and d.step % 20 == 0:
            print(f"  pour {n}: step {d.step}, {d.n_contacts} contacts, energy/particle "
                  f"{energy / weight_scale:.2e} m g d, {d.solve_time:.2f} s", flush=True)
        if d.step > 50 and energy < 1e-6 * weight_scale:
            break
    state.velocity[:] = 0.0
    state.angular_velocity[:] = 0.0
    state.time = 0.0
    return state


def packing(n: int, seed: int = 0) -> ParticleState:
    """A settled packing of about n spheres: benchmarks/packings.py if present, else poured here."""
    sys.path.insert(0, str(HERE))
    try:
        from packings import settled_packing  # type: ignore
    except ImportError:
        settled_packing = None
    if settled_packing is not None:
        return settled_packing(n, seed)
    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"poured_{n}_{seed}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())  # noqa: S301 (our own cache)
    state = pour(n, seed)
    path.write_bytes(pickle.dumps(state))
    return state


def program_of(state: ParticleState, settings: StepSettings = COLLAPSE):
    margin = settings.detection_margin_fraction * 2 * float(state.radius.min())
    found = detect(state, settings.walls, settings.law, predicted_displacement(state, settings),
                   margin, settings.detection_slack)
    return assemble(state, found, settings.dt, settings.gravity), found


def measure(solver, program, warm=None, step_number=None):
    """(solution or error, seconds, peak traced MB)."""
    tracemalloc.start()
    start = time.perf_counter()
    try:
        solution = solver.solve(program, warm_start=warm, step=step_number)
    except SolverError as error:
        solution = error
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return solution, seconds, peak


#: every solve reported, for the table at the end (and the record)
ROWS: list[dict] = []


def report(label, solution, seconds, peak, reference=None, spheres=None, stage=None):
    row = {"spheres": spheres, "stage": stage, "solver": label, "seconds": seconds, "peak_traced_mb": peak}
    ROWS.append(row)
    if isinstance(solution, Exception):
        row["status"] = f"FAILED: {solution}"
        print(f"    {label:<16} FAILED after {seconds:7.2f} s: {solution}", flush=True)
        return
    it = max(solution.iterations, 1)
    diff = ""
    if reference is not None and not isinstance(reference, Exception):
        du = np.linalg.norm(solution.increments - reference.increments) / np.linalg.norm(reference.increments)
        diff = f"  |du|/|u| vs clarabel {du:.1e}"
        row["du_vs_clarabel"] = float(du)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    row.update(iterations=solution.iterations, ms_per_iteration=1e3 * seconds / it, rss_mb=rss,
               status=str(solution.status))
    extra = ""
    if "factor_time" in solution.info:
        i = solution.info
        extra = (f"  [rho {i['rho']:.3g}, {i['refactors']} refactor, factor {i['factor_time']:.2f} s,"
                 f" solves {i['linear_solve_time']:.2f} s]")
    print(f"    {label:<16} {seconds:8.3f} s  {solution.iterations:6d} it  {1e3 * seconds / it:8.2f} ms/it"
          f"  peak {peak:7.1f} MB (rss {rss:6.0f} MB)  {solution.status}{diff}{extra}", flush=True)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 4000])
    parser.add_argument("--mid-steps", type=int, default=5, help="collapse steps before the 'mid' program")
    parser.add_argument("--skip-clarabel-above", type=int, default=10**9,
                        help="do not run Clarabel above this many spheres (minutes per solve)")
    parser.add_argument("--scs", action="store_true", help="also run SCS on the force form")
    parser.add_argument("--tolerance", type=float, default=ApgdSolver().tolerance)
    parser.add_argument("--admm-tolerance", type=float, default=AdmmSolver().tolerance)
    parser.add_argument("--no-apgd", action="store_true", help="skip APGD (ADMM steps to 'mid')")
    parser.add_argument("--no-admm", action="store_true", help="skip ADMM")
    args = parser.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")   # as when run as a script (python -m benchmarks solvers)
    ROWS.clear()

    apgd = None if args.no_apgd else ApgdSolver(tolerance=args.tolerance)
    admm = None if args.no_admm else AdmmSolver(tolerance=args.admm_tolerance)
    stepper = apgd or admm or ClarabelSolver()
    for n in args.sizes:
        state = packing(n)
        reach = float(np.max(np.hypot(state.position[:, 0], state.position[:, 1]) + state.radius))
        print(f"{state.n} spheres (radial extent {reach:.2f}, height "
              f"{np.max(state.position[:, 2] + state.radius):.2f})", flush=True)
        clarabel = ClarabelSolver() if state.n <= args.skip_clarabel_above else None
        # the mid-collapse state: steps with APGD (else ADMM), keeping the last step's forces for
        # the warm start
        mid, warm = state, None
        for k in range(args.mid_steps):
            result = step(mid, COLLAPSE, stepper, k, warm_start=warm)
            warm = WarmStart.from_step(result.contacts, result.solution.forces)
            mid = result.state
        for stage, current in (("release", state), ("mid", mid)):
            program, found = program_of(current)
            print(f"  {stage}: {program.m} contacts ({2 * program.m / state.n:.2f} per sphere)", flush=True)
            reference = None
            if clarabel is not None:
                reference, seconds, peak = measure(clarabel, program)
                report("clarabel", reference, seconds, peak, spheres=state.n, stage=stage)
            guess = warm.match(found) if stage == "mid" else None
            for label, solver in (("apgd", apgd), ("admm", admm)):
                if solver is None:
                    continue
                report(f"{label} cold", *measure(solver, program), reference, spheres=state.n, stage=stage)
                if guess is not None:
                    report(f"{label} warm", *measure(solver, program, guess), reference, spheres=state.n,
                           stage=stage)
            if args.scs:
                report("scs", *measure(_Scs(), program), reference, spheres=state.n, stage=stage)
    print()
    table = record.table(["spheres", "program", "solver", "s", "iterations", "ms/iteration", "traced peak MB",
                          "RSS MB", "status", "du vs Clarabel"])
    for r in ROWS:
        du = r.get("du_vs_clarabel")
        table.row(r["spheres"], r["stage"], r["solver"], f"{r['seconds']:.3f}", r.get("iterations", "-"),
                  f"{r['ms_per_iteration']:.2f}" if "ms_per_iteration" in r else "-", f"{r['peak_traced_mb']:.1f}",
                  f"{r['rss_mb']:.0f}" if "rss_mb" in r else "-", r["status"], "-" if du is None else f"{du:.1e}",
                  data=r)


class _Scs:
    """SCS on the force form (eps 1e-6), built from Clarabel's force-form matrices."""

    def solve(self, program, warm_start=None, step=None):
        import scs
        import scipy.sparse as sp

        from colsim.solvers import ConeSolution

        P, c, A, b, cones, unpack = ClarabelSolver._force_form(program)
        # Clarabel's cone list -> SCS's: zero cones first, then nonnegative, then second-order
        kinds = [type(k).__name__ for k in cones]
        rows = np.cumsum([0] + [_cone_dim(k) for k in cones])
        order = ([i for i, kind in enumerate(kinds) if kind == "ZeroConeT"]
                 + [i for i, kind in enumerate(kinds) if kind == "NonnegativeConeT"]
                 + [i for i, kind in enumerate(kinds) if kind == "SecondOrderConeT"])
        picked = np.concatenate([np.arange(rows[i], rows[i + 1]) for i in order])
        A = sp.csc_matrix(A)[picked]
        b = b[picked]
        z = sum(_cone_dim(cones[i]) for i in order if kinds[i] == "ZeroConeT")
        nonnegative = sum(_cone_dim(cones[i]) for i in order if kinds[i] == "NonnegativeConeT")
        q = [3] * sum(1 for kind in kinds if kind == "SecondOrderConeT")
        solver = scs.SCS({"P": sp.csc_matrix(P + sp.triu(P, 1).T), "A": A, "b": b, "c": c},
                         {"z": z, "l": nonnegative, "q": q}, eps_abs=1e-6, eps_rel=1e-6, verbose=False,
                         max_iters=100000)
        start = time.perf_counter()
        sol = solver.solve()
        u, forces = unpack(sol["x"], sol["y"])
        return ConeSolution(u, forces, sol["info"]["status"], sol["info"]["iter"], 0.0,
                            time.perf_counter() - start)


def _cone_dim(cone) -> int:
    return int(cone.dim)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    record.run("solvers", main)
