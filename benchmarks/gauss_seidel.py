"""Projected Gauss-Seidel ordered by height against APGD: sweeps and seconds to APGD's stopping rule.

    python benchmarks/gauss_seidel.py COLUMN.nc --steps 2 50 150 400

Issue 30, item 4 asks whether Gauss-Seidel-like sweeps ordered by height take fewer passes than
APGD on tall columns (a sweep from the top down hands the weight of the column to its base in one
pass, where a gradient method needs about one iteration per layer). The column (from `colsim trim`)
collapses with mu = 0.577, mu_r = 0.12 at dt/sqrt(h0/g) = 4 / `--n-steps` under `auto`; at each
named step the step's cone program is solved from the same warm start by

- APGD with `auto`'s settings (tolerance 1e-5, length floor 0.1 d, overlap tolerance 1e-4 d), and
- projected block Gauss-Seidel in APGD's scaled forces: contact by contact, the 5 x 5 block of the
  scaled Delassus operator is formed from the contact's frame, `--inner` projected-gradient steps of
  length 1/(its Gershgorin bound) solve the contact's own cone program, and the two bodies'
  velocities are updated at once. Orders: `down` (contact heights, top first), `sym` (top-down then
  bottom-up) and `given` (detection's order).

Both stop by the same rule (APGD's residuals, checked every 5 sweeps or 10 iterations). Gauss-Seidel
runs on one thread by nature (compiled with numba), and APGD on `--threads` (default 1); the table
gives each its passes and seconds.
The sweep kernel lives here, not in the package: it measured slower (docs/performance.md,
"Fewer iterations a step").
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import record
from colsim import io
from colsim.engine.cones import project_point
from colsim.engine.compiled import HAVE_NUMBA, numba
from colsim.engine.records import Carry
from colsim.engine.solver_contract import Solver
from colsim.engine.stepper import run
from colsim.engine.threads import use_threads
from colsim.solvers import make_solver
from colsim.solvers.registry import AutoSolver
from colsim.stages.collapse import CollapseSettings

ORDERS = ("down", "sym", "given")


def sweep(order, z, v, s, a, b, ci, cj, nrm, t1, t2, ri, rj, lever, c, inv_mass, inner):
    """One Gauss-Seidel pass over the contacts in `order`, in place: z (5m,) scaled forces, v (6n,)
    Mbar^-1 B' S z; s, a, b, c, inv_mass and the frames as APGD's (colsim.solvers.apgd)."""
    rot = len(v) // 2
    J = np.zeros((2, 5, 6))
    W = np.zeros((5, 5))
    g, z0, zl, y = np.zeros(5), np.zeros(5), np.zeros(5), np.zeros(5)
    for idx in range(len(order)):
        k = order[idx]
        o = 5 * k
        for side in range(2):       # the rows of B for each body: translation, then rotation
            sign = -1.0 if side == 0 else 1.0
            radius = ri[k] if side == 0 else rj[k]
            for d in range(3):
                J[side, 0, d], J[side, 1, d], J[side, 2, d] = sign * nrm[k, d], sign * t1[k, d], sign * t2[k, d]
                J[side, 3, d] = J[side, 4, d] = J[side, 0, 3 + d] = 0.0
                J[side, 1, 3 + d], J[side, 2, 3 + d] = -radius * t2[k, d], radius * t1[k, d]
                J[side, 3, 3 + d], J[side, 4, 3 + d] = sign * lever[k] * t1[k, d], sign * lever[k] * t2[k, d]
        lip = 0.0
        for r in range(5):
            acc = 0.0
            for side in range(2):
                body = ci[k] if side == 0 else cj[k]
                if body >= 0:
                    for d in range(3):
                        acc += J[side, r, d] * v[3 * body + d] + J[side, r, 3 + d] * v[rot + 3 * body + d]
            g[r] = s[o + r] * acc + c[o + r]
            z0[r] = zl[r] = z[o + r]
            row = 0.0
            for q in range(5):
                w = 0.0
                for side in range(2):
                    body = ci[k] if side == 0 else cj[k]
                    if body >= 0:
                        for d in range(3):
                            w += J[side, r, d] * J[side, q, d] * inv_mass[3 * body + d]
                            w += J[side, r, 3 + d] * J[side, q, 3 + d] * inv_mass[rot + 3 * body + d]
                W[r, q] = s[o + r] * w * s[o + q]
                row += abs(W[r, q])
            lip = max(lip, row)
        for _ in range(inner):
            for r in range(5):
                acc = g[r]
                for q in range(5):
                    acc += W[r, q] * (zl[q] - z0[q])
                y[r] = zl[r] - acc / lip
            zl[0], zl[1], zl[2], zl[3], zl[4] = project_point(y[0], y[1], y[2], y[3], y[4], a[k], b[k])
        for side in range(2):
            body = ci[k] if side == 0 else cj[k]
            if body >= 0:
                for d in range(6):
                    acc = 0.0
                    for r in range(5):
                        acc += J[side, r, d] * s[o + r] * (zl[r] - z0[r])
                    e = 3 * body + d if d < 3 else rot + 3 * body + d - 3
                    v[e] += inv_mass[e] * acc
        for r in range(5):
            z[o + r] = zl[r]


if HAVE_NUMBA:
    sweep = numba.njit(cache=True)(sweep)


def gauss_seidel(program, warm_start, height, order: str, inner: int, apgd, max_sweeps: int = 5000):
    """(sweeps, seconds, converged) to APGD's stopping rule; height (m,) each contact's height."""
    start = time.perf_counter()
    run_ = apgd.prepare(program, warm_start)
    scale, floor, primal_tolerance = apgd.stopping_scales(program)
    _, ci, cj, nrm, t1, t2, ri, rj, lever = run_.geometry[:9]
    down = np.argsort(-height, kind="stable").astype(np.int64)
    passes = {"down": [down], "sym": [down, down[::-1].copy()],
              "given": [np.arange(program.m, dtype=np.int64)]}[order]
    z, s = run_.x.copy(), run_.scaling.ravel()
    v = run_.inv_mass * run_.apply_T(z)
    done = 0
    while done < max_sweeps:
        for _ in range(5):
            for p in passes:
                sweep(p, z, v, s, run_.mu_s, run_.mu_r_s, ci, cj, nrm, t1, t2, ri, rj, lever, run_.c, run_.inv_mass, inner)
            done += 1
        run_.x, run_.hx = z, run_.apply_T(z)
        res = run_.residuals(program.mu, program.mu_r, scale, floor)
        if res["primal"] <= primal_tolerance and res["complementarity"] <= apgd.tolerance:
            return done, time.perf_counter() - start, True
    return done, time.perf_counter() - start, False


class Probe(Solver):
    """`inner` for every step; at the steps named, APGD and the Gauss-Seidel variants first."""

    uses_warm_start = True

    def __init__(self, inner: Solver, steps: set[int], variants, table):
        self.inner, self.steps, self.variants, self.table = inner, steps, variants, table
        self.name, self.z = inner.name, None

    def solve(self, program, warm_start=None, step=None):
        if step in self.steps and warm_start is not None and program.operator is not None:
            self.steps.discard(step)   # a redone step is measured once, at its first attempt
            apgd = self.inner.apgd
            started = time.perf_counter()
            reference = apgd.solve(program, warm_start, step=step)
            apgd_s = time.perf_counter() - started
            cells, data = [step, f"{program.m:,}", reference.iterations, f"{apgd_s:.3f}"], {}
            height = contact_height(program.contacts, self.z)
            for order, inner in self.variants:
                sweeps, seconds, converged = gauss_seidel(program, warm_start, height, order, inner, apgd)
                cells.append(f"{sweeps}{'' if converged else '+'} / {seconds:.3f}")
                data[f"{order}-{inner}"] = {"sweeps": sweeps, "seconds": seconds, "converged": converged}
            self.table.row(*cells, data={"step": step, "contacts": program.m, "apgd_iterations": reference.iterations,
                                         "apgd_seconds": apgd_s, **data})
        return self.inner.solve(program, warm_start=warm_start, step=step)


def contact_height(contacts, z) -> np.ndarray:
    """(m,) a contact's height: the mean of its particles' heights (its particle's, on a wall)."""
    height = z[contacts.i].copy()
    pair = contacts.j >= 0
    height[pair] = 0.5 * (z[contacts.i[pair]] + z[contacts.j[pair]])
    return height


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", type=Path)
    parser.add_argument("--steps", type=int, nargs="+", required=True, help="the steps probed")
    parser.add_argument("--n-steps", type=int, default=1000,
                        help="steps to t/sqrt(h0/g) = 4, which sets dt (default: %(default)s)")
    parser.add_argument("--variants", nargs="+", default=["down:1", "sym:1", "down:5", "given:1"],
                        help="ORDER:INNER, ORDER one of down, sym, given (default: %(default)s)")
    parser.add_argument("--threads", type=int, default=1,
                        help="APGD's threads (default: %(default)s, as Gauss-Seidel's one)")
    args = parser.parse_args(argv)
    use_threads(args.threads)
    variants = [(v.split(":")[0], int(v.split(":")[1])) for v in args.variants]
    if any(order not in ORDERS for order, _ in variants):
        raise SystemExit(f"orders are {', '.join(ORDERS)}")
    state, source = io.read_state(args.column)
    settings = CollapseSettings(mu_r=0.12, n_steps=args.n_steps)
    solver = make_solver("auto", scaled_time_step=settings.duration / args.n_steps)
    assert isinstance(solver, AutoSolver)
    print(f"{args.column}: {state.n} spheres, dt/sqrt(h0/g) = {settings.duration / args.n_steps:g}; "
          "cells: sweeps / seconds (+: not converged in 5,000 sweeps)")
    table = record.table(["step", "contacts", "APGD iterations", "APGD s",
                          *(f"GS {order}, {inner} inner" for order, inner in variants)])
    probe = Probe(solver, set(args.steps), variants, table)
    probe.z = state.position[:, 2].copy()
    steps = run(state, settings.step_settings(float(source.attrs["h0"])), max(args.steps), probe,
                carry=Carry(io.contact_forces_of(source)))
    for result in steps:
        probe.z = result.state.position[:, 2].copy()   # the next step starts here


if __name__ == "__main__":
    record.run("gauss_seidel", main)
