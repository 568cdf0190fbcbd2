"""The copies between host and GPU a collapse step makes, by where they are made: what keeping a
step's data on the device (issue 46, "kernels at 80 %") has left to remove.

    NUMBA_ENABLE_CUDASIM=1 python -m benchmarks device_copies          # here, on numba's simulator
    python -m benchmarks device_copies --steps 5                        # on a GPU

A stack of 12 spheres (3 layers of 2 x 2, diameter 0.5) in a cylinder of radius 0.65 on the floor
collapses with mu = 0.577, mu_r = 0.12 and dt = 0.02 by APGD on the device (`ApgdSolver(kernel="cuda")`,
`colsim.engine.stepper.run` with the swept pairs, the warm start's matching and the overlap check
there too); after one step to start from, `--steps` more of the same run are counted. Each `cuda.to_device`, device
array's `copy_to_host` and `copy_to_device` from a host array is counted with its bytes, by the
colsim function that made it. The count of a step's copies depends on its attempts and on the
solver's residual checks, not on the column's size (a copy from the host costs about 0.15 ms on an
H200 whatever its size, docs/performance.md, "The third GPU sitting"); the bytes grow with it.
"""
from __future__ import annotations

import argparse
import collections
import traceback
from pathlib import Path

import numpy as np

import record


def _caller() -> str:
    """module:function of the innermost colsim frame of the stack."""
    frames = [f for f in traceback.extract_stack()[:-2] if "colsim" in f.filename and "benchmarks" not in f.filename]
    return f"{Path(frames[-1].filename).name}:{frames[-1].name}" if frames else "elsewhere"


def counting_copies():
    """Patch numba.cuda's copies to count them; returns (counts, bytes), Counters by (direction, caller)."""
    from numba import cuda

    counts, sizes = collections.Counter(), collections.Counter()
    device_array_type = type(cuda.device_array(1))
    to_device, to_host, into_device = cuda.to_device, device_array_type.copy_to_host, device_array_type.copy_to_device

    def count(direction, nbytes):
        key = (direction, _caller())
        counts[key] += 1
        sizes[key] += int(nbytes)

    def counted_to_device(array, *args, **kwargs):
        count("to the device", np.asarray(array).nbytes)
        return to_device(array, *args, **kwargs)

    def counted_to_host(self, *args, **kwargs):
        count("to the host", self.nbytes)
        return to_host(self, *args, **kwargs)

    def counted_into_device(self, source, *args, **kwargs):
        if not hasattr(source, "copy_to_host"):   # from the host (a copy between device arrays is not counted)
            count("to the device", np.asarray(source).nbytes)
        return into_device(self, source, *args, **kwargs)

    cuda.to_device = counted_to_device
    device_array_type.copy_to_host = counted_to_host
    device_array_type.copy_to_device = counted_into_device
    return counts, sizes


def stack():
    """(state, settings): 12 spheres at rest in 3 layers of 2 x 2 in a cylinder, the collapse's law."""
    from colsim.engine.state import ContactLaw, ParticleState, StepSettings, Walls

    grid = np.array([[x, y, z] for x in (-0.26, 0.26) for y in (-0.26, 0.26) for z in (0.25, 0.76, 1.27)])
    state = ParticleState.at_rest(grid, np.full(len(grid), 0.25))
    return state, StepSettings(dt=0.02, law=ContactLaw.uniform(0.577, 0.12),
                               walls=Walls(floor=True, cylinder_radius=0.65))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=2, help="steps counted, after one to start from")
    args = parser.parse_args(argv)
    from colsim.engine.stepper import run
    from colsim.solvers.apgd import ApgdSolver

    state, settings = stack()
    solver = ApgdSolver(kernel="cuda")
    steps = run(state, settings, 1 + args.steps, solver)
    next(steps)   # the first step, not counted: it made the second's first detection, as any step does
    counts, sizes = counting_copies()
    results = list(steps)
    attempts = sum(r.diagnostics.redone + 1 for r in results)
    iterations = sum(r.diagnostics.solver_iterations for r in results)
    print(f"{state.n} spheres, {args.steps} steps counted: {attempts} attempts, {iterations} APGD iterations, "
          f"{np.mean([r.contacts.m for r in results]):.0f} contacts a step")
    table = record.table(["direction", "made by", "copies a step", "bytes a step"])
    for (direction, caller) in sorted(counts):
        key = (direction, caller)
        table.row(direction, caller, f"{counts[key] / args.steps:.1f}", f"{sizes[key] / args.steps:.0f}",
                  data={"direction": direction, "caller": caller, "copies": counts[key] / args.steps,
                        "bytes": sizes[key] / args.steps})
    table.row("both", "all", f"{sum(counts.values()) / args.steps:.1f}", f"{sum(sizes.values()) / args.steps:.0f}")


if __name__ == "__main__":
    record.run("device_copies", main)
