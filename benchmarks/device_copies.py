"""The copies between host and GPU a collapse step makes, by where they are made: what keeping a
step's data on the device has left to remove.

    NUMBA_ENABLE_CUDASIM=1 python -m benchmarks device_copies          # here, on numba's simulator
    python -m benchmarks device_copies --steps 5                        # on a GPU
    NUMBA_ENABLE_CUDASIM=1 python -m benchmarks device_copies --redo 5  # a redone step

A stack of 12 spheres (3 layers of 2 x 2, diameter 0.5) in a cylinder of radius 0.65 on the floor
collapses with mu = 0.577, mu_r = 0.12 and dt = 0.02 by APGD on the device (the CUDA back-end, `make_backend("cuda")`,
`colsim.engine.stepper.run` with the swept pairs, the warm start's matching and the overlap check
there too); after one step to start from, `--steps` more of the same run are counted. Each `cuda.to_device`, device
array's `copy_to_host` and `copy_to_device` from a host array is counted with its bytes, by the
colsim function that made it, and so is each device array made (`cuda.device_array`,
`device_array_like`, `to_device`: an allocation on the device each); on numba's simulator, so is each
kernel's launch, and on a GPU each launch made the plain way (numba-cuda's dispatcher, not
`colsim.engine.cuda_launch.launch`), by kernel. The count of a step's copies depends on its attempts
and on the solver's residual checks, not on the column's size (a small copy's cost hardly depends on its size); the bytes
grow with it.

`--redo SIDE`: one step that is redone instead (:func:`redone_step`), counted after the same step
once uncounted: a sphere flies into a resting one and pushes it into a third that the first attempt
did not list, beside a resting cube of SIDE^3 touching spheres whose contacts every attempt carries.
"""
from __future__ import annotations

import argparse
import collections
import traceback
from pathlib import Path

import numpy as np

import record


def _caller(helpers: tuple = ()) -> str:
    """module:function of the innermost colsim frame of the stack, not counting the modules `helpers`."""
    frames = [f for f in traceback.extract_stack()[:-2] if "colsim" in f.filename and "benchmarks" not in f.filename
              and Path(f.filename).name not in helpers]
    return f"{Path(frames[-1].filename).name}:{frames[-1].name}" if frames else "elsewhere"


#: the modules of launches made for others (the operator's products, fills, prefix sums): a launch or
#: an allocation is counted for their caller
LAUNCH_HELPERS = ("cuda_launch.py", "cuda_operator.py")


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


def counting_allocations():
    """Patch numba.cuda's ways of making a device array (device_array, device_array_like, to_device) to
    count them; returns (counts, bytes), Counters by caller (a small allocation costs about as much
    as a small copy)."""
    from numba import cuda

    counts, sizes = collections.Counter(), collections.Counter()
    makers = {name: getattr(cuda, name) for name in ("device_array", "device_array_like", "to_device")}

    def counted(name):
        make = makers[name]

        def made(*args, **kwargs):
            array = make(*args, **kwargs)
            if not (name == "to_device" and kwargs.get("to") is not None):   # into an array made before
                key = _caller(LAUNCH_HELPERS)   # a fill or a copy made for another: counted for it
                counts[key] += 1
                sizes[key] += int(array.nbytes)
            return array
        return made

    for name in makers:
        setattr(cuda, name, counted(name))
    return counts, sizes


def counting_launches():
    """On numba's simulator, patch its kernels' launches to count them; returns a dict by caller of
    Counters: launches, those made through colsim.engine.cuda_launch.launch (which keeps an array's
    marshalled words for its next launches), and the array arguments of the others, which numba-cuda
    marshals anew at each launch (None on a GPU, where nothing is counted)."""
    from numba import config

    if not config.ENABLE_CUDASIM:
        return None
    from numba.cuda.simulator import kernel

    launches = collections.defaultdict(collections.Counter)
    plain = kernel.FakeCUDAKernel.__call__

    def counted_call(self, *args):
        if not self._device:   # a kernel's launch, not a device function's call
            counts = launches[_caller(LAUNCH_HELPERS)]
            counts["launches"] += 1
            if any(Path(f.filename).name == "cuda_launch.py" for f in traceback.extract_stack()):
                counts["through launch()"] += 1
            else:
                counts["arrays marshalled"] += sum(hasattr(a, "copy_to_host") for a in args)
        return plain(self, *args)

    kernel.FakeCUDAKernel.__call__ = counted_call
    return launches


def stack():
    """(state, settings): 12 spheres at rest in 3 layers of 2 x 2 in a cylinder, the collapse's law."""
    from colsim.engine.state import ContactLaw, ParticleState, StepSettings, Walls

    grid = np.array([[x, y, z] for x in (-0.26, 0.26) for y in (-0.26, 0.26) for z in (0.25, 0.76, 1.27)])
    state = ParticleState.at_rest(grid, np.full(len(grid), 0.25))
    return state, StepSettings(dt=0.02, law=ContactLaw.uniform(0.577, 0.12),
                               walls=Walls(floor=True, cylinder_radius=0.65))


def redone_step(side: int):
    """(state, settings) of a step that is redone once: the train of tests/engine/test_stepper.py (gravity
    off, no walls, margin 1e-6 d, no slack: the struck sphere's push into the third is missed), beside a
    cube of side^3 spheres of radius 0.2 at rest, each pair of neighbours overlapping by 1e-5."""
    from colsim.engine.state import ContactLaw, ParticleState, StepSettings, Walls

    train = np.array([[0.0, 0, 0], [0.401, 0, 0], [0.811, 0, 0]])
    g = np.arange(side) * 0.39999
    cube = np.array([[x, y + 2.0, z] for x in g for y in g for z in g]).reshape(-1, 3)
    position = np.concatenate([train, cube])
    velocity = np.zeros_like(position)
    velocity[0, 0] = 2.0
    state = ParticleState(position, velocity, np.zeros_like(position), np.full(len(position), 0.2))
    return state, StepSettings(dt=0.02, gravity=(0.0, 0.0, 0.0), walls=Walls(floor=False),
                               law=ContactLaw.uniform(0.3, 0.0), detection_margin_fraction=1e-6,
                               detection_slack=0.0, max_redo=3)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=2, help="steps counted, after one to start from")
    parser.add_argument("--redo", type=int, metavar="SIDE", help="count one redone step instead, beside a cube "
                        "of SIDE^3 spheres at rest")
    args = parser.parse_args(argv)
    from colsim.engine.backends import make_backend
    from colsim.engine.cuda_launch import plain_counts
    from colsim.engine.stepper import run, step
    from colsim.solvers.apgd import ApgdSolver

    cuda = make_backend("cuda")

    if args.redo:
        state, settings = redone_step(args.redo)
        solver = ApgdSolver(tolerance=1e-8, backend=cuda)
        step(state, settings, solver, 1, backend=cuda)   # not counted: the kernels compiled, the radii's copy kept
        counts, sizes = counting_copies()
        allocations, allocated = counting_allocations()
        launches = counting_launches()
        plain_before = dict(plain_counts)
        results = [step(state, settings, solver, 2, backend=cuda)]
        args.steps = 1
    else:
        state, settings = stack()
        solver = ApgdSolver(backend=cuda)
        steps = run(state, settings, 1 + args.steps, solver, backend=cuda)
        next(steps)   # the first step, not counted: it made the second's first detection, as any step does
        counts, sizes = counting_copies()
        allocations, allocated = counting_allocations()
        launches = counting_launches()
        plain_before = dict(plain_counts)
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
    made = record.table(["made by", "device arrays made a step", "bytes a step"])
    for caller in sorted(allocations, key=lambda c: -allocations[c]):
        made.row(caller, f"{allocations[caller] / args.steps:.1f}", f"{allocated[caller] / args.steps:.0f}",
                 data={"allocations by": caller, "allocations": allocations[caller] / args.steps,
                       "bytes": allocated[caller] / args.steps})
    made.row("all", f"{sum(allocations.values()) / args.steps:.1f}", f"{sum(allocated.values()) / args.steps:.0f}")
    if launches is not None:
        print(f"kernel launches a step, by where they are made ({iterations / args.steps:.0f} APGD iterations "
              "a step; counted on numba's simulator):")
        columns = ("launches", "through launch()", "arrays marshalled")
        launched = record.table(["made by", "launches a step", "of them through launch()",
                                 "array arguments of the others a step"])
        for caller, counts in sorted(launches.items(), key=lambda item: -item[1]["launches"]):
            launched.row(caller, *(f"{counts[c] / args.steps:.1f}" for c in columns),
                         data={"launches by": caller, **{c: counts[c] / args.steps for c in columns}})
        launched.row("all", *(f"{sum(counts[c] for counts in launches.values()) / args.steps:.1f}" for c in columns))
    else:   # a GPU: the launches launch() could not make its way (a kernel with several overloads)
        plain = {name: n - plain_before.get(name, 0) for name, n in plain_counts.items()
                 if n > plain_before.get(name, 0)}
        print("plain launches a step (numba-cuda's dispatcher; the others through launch()):")
        table = record.table(["kernel", "plain launches a step"])
        for name in sorted(plain, key=lambda name: -plain[name]):
            table.row(name, f"{plain[name] / args.steps:.1f}", data={"kernel": name, "plain": plain[name] / args.steps})
        table.row("all", f"{sum(plain.values()) / args.steps:.1f}")


if __name__ == "__main__":
    record.run("device_copies", main)
