"""APGD's iterations on one GPU against the CPU's, on the same program from the same start: the
control flow colsim.solvers.apgd.apgd_iterations driving the CUDA kernels (colsim.solvers.apgd_cuda)
and the compiled CPU kernels (the process's numba threads), with a residual check every 10 iterations
as a solve makes it.

    python -m benchmarks gpu --spheres 73000 704000 2000000 --iterations 60

The column is cuda_operator.py's synthetic lattice (about 3 contacts a sphere, aspect ratio 5), its
spheres of unit mass and inertia, loaded by gravity over one step (dt 1e-3): c = S (B u_free + gap),
preconditioned as APGD does (colsim.engine.cones.scales_of_diagonal). Both start from zero forces
with the same Lipschitz estimate. Reported: milliseconds an iteration (the whole run over the
iterations, wall time, the GPU synchronised), their ratio, the iterate's largest difference over its
largest entry after the run, and the restarts and backtracks of each (the same on both when the
rounding of their sums does not flip a decision). The GPU's one host round trip an iteration (the
trial step's sums) is inside its time. Run the CPU baseline on the same machine, in the same call.
Without a GPU the kernels run on numba's simulator (NUMBA_ENABLE_CUDASIM=1): only to check the
script, at a hundred spheres and a few iterations; its times mean nothing.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import record
from cuda_operator import lattice_contacts
from colsim.engine.cones import scales_of_diagonal
from colsim.engine.operator import ContactOperator
from colsim.engine.threads import threads
from colsim.solvers.apgd import _Iteration

GRAVITY, DT = 9.81, 1e-3


def start_of(spheres: int) -> tuple[_Iteration, ContactOperator, np.ndarray, np.ndarray]:
    """(the APGD start on the CPU, its operator, mu, mu_r) of the lattice column of about `spheres`."""
    contacts, n = lattice_contacts(spheres)
    operator = ContactOperator(contacts, n)
    inv_mass = np.ones(6 * n)
    s = scales_of_diagonal(operator.diagonal(inv_mass))
    u_free = np.zeros(6 * n)
    u_free[2:3 * n:3] = -GRAVITY * DT * DT   # the step's fall under gravity, each sphere
    c = operator.apply(u_free)
    c[::5] += contacts.gap
    c *= s.ravel()
    mu_s, mu_r_s = contacts.mu * s[:, 0] / s[:, 1], contacts.mu_r * s[:, 0] / s[:, 3]
    start = _Iteration(None, None, c, mu_s, mu_r_s, inv_mass, np.zeros(5 * contacts.m), s, 0.9, operator=operator)
    return start, operator, contacts.mu, contacts.mu_r


def timed(run, iterations: int, mu, mu_r, synchronise=lambda: None) -> float:
    """Seconds of `iterations` iterations with a residual check every 10."""
    synchronise()
    begin = time.perf_counter()
    done = 0
    while done < iterations:
        step = min(10, iterations - done)
        run.iterate(step)
        run.residuals(mu, mu_r, 1.0, 1e-12)
        done += step
    synchronise()
    return time.perf_counter() - begin


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spheres", type=int, nargs="+", default=[73_000, 704_000, 2_000_000])
    parser.add_argument("--iterations", type=int, default=60)
    args = parser.parse_args(argv)
    from numba import cuda
    from numba.core import config as numba_config

    from colsim.solvers.apgd_cuda import CudaIteration

    device = "simulator" if numba_config.ENABLE_CUDASIM else cuda.get_current_device().name
    device = device.decode() if isinstance(device, bytes) else str(device)
    record.note("device", device)
    table = record.table(["spheres", "contacts", f"CPU ms an iteration ({threads()} threads)",
                          f"GPU ms an iteration ({device})", "GPU vs CPU", "iterate difference / largest",
                          "restarts, backtracks (CPU; GPU)"])
    for spheres in args.spheres:
        for warm_up in range(2):   # the first compiles both kernel sets; both start again from the same point
            cpu, operator, mu, mu_r = start_of(spheres)
            gpu = CudaIteration(cpu, operator, mu, mu_r)
            if not warm_up:
                timed(cpu, 1, mu, mu_r)
                timed(gpu, 1, mu, mu_r, cuda.synchronize)
        gpu_s = timed(gpu, args.iterations, mu, mu_r, cuda.synchronize)
        cpu_s = timed(cpu, args.iterations, mu, mu_r)
        x = cpu.host_x()
        difference = float(np.max(np.abs(gpu.host_x() - x)) / max(np.max(np.abs(x)), 1e-300))
        per_cpu, per_gpu = cpu_s / args.iterations, gpu_s / args.iterations
        table.row(operator.n, operator.m, f"{1e3 * per_cpu:.2f}", f"{1e3 * per_gpu:.2f}", f"{per_cpu / per_gpu:.1f}",
                  f"{difference:.1e}", f"{cpu.restarts}, {cpu.backtracks}; {gpu.restarts}, {gpu.backtracks}",
                  data={"spheres": operator.n, "contacts": operator.m, "cpu_ms": 1e3 * per_cpu,
                        "gpu_ms": 1e3 * per_gpu, "cpu_threads": threads(), "device": device,
                        "simulator": bool(numba_config.ENABLE_CUDASIM), "iterations": args.iterations,
                        "relative_difference": difference})


if __name__ == "__main__":
    record.run("gpu", main)
