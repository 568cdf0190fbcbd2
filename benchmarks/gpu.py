"""APGD's iterations on one GPU against the CPU's, on the same program from the same start: the
same decisions (colsim.engine.apgd_iteration.decide) made on the device between the CUDA kernels
(colsim.engine.cuda_apgd) and in the compiled CPU loop (the process's numba threads), with a
residual check every 10 iterations as a solve makes it.

    python -m benchmarks gpu --spheres 73000 704000 2000000 --iterations 60
    python -m benchmarks gpu --spheres --columns r0_3_a5.nc r0_6_a5.nc --steps 20

First, what a launch of an empty kernel (1 or 13 arguments, plain or specialised) and a small copy
to the host cost (:func:`launch_costs`): a small column's iteration is made of them. Then the swept
pairs of contact detection on the same lattice, every sphere moving up to 0.01 of its
diameter in a random direction (a collapse step's): the CPU's (a k-d tree, the swept test on numba's
threads) against the GPU's (a uniform grid, colsim.engine.cuda_contacts; the copies to and from the
device included), best of three, and whether the two lists are the same; and the warm start's
matching of forces stored for every lattice contact to those contacts (WarmStart.match on the host,
a sorted array; on the GPU, a hash table: colsim.engine.cuda_warm_start), best of three, and the
largest difference over the largest force.

With --trajectories (finished `colsim collapse` files, e.g. the collapses to rest that
gpu_machine.sh runs on the GPU), where their steps' wall time went (:func:`step_times`).
With --columns (`colsim trim` files), also the first --steps steps of each column's collapse (the
default study's settings: mu_r = 0.12, dt/sqrt(h0/g) = 0.004, `auto`, warm-started from the
packing's forces) with APGD on the CPU's threads and on the GPU (`--device cuda`): seconds a step,
APGD's share of them, iterations a step, and how far the two end positions are apart over a mean
diameter (one step of each first, to compile the kernels), and where the GPU's step spends the rest
(detection, assembly, the warm start's matching, the solver's set-up, the overlap check), and the
share of the GPU's steps in which a kernel ran (NVML's utilisation, sampled: the issue's "kernels at
least 80 % of a step"; :func:`kernels_busy`); with --profile
FOLDER, cProfile's statistics of each column's steps on each device; with --kernel-trace FOLDER, the
first --trace-steps steps on the GPU again with every kernel traced (benchmarks/kernel_trace.py: the
card's busy share read from its own record, its idle gaps by length, the kernels of most GPU time).

The column is cuda_operator.py's synthetic lattice (about 3 contacts a sphere, aspect ratio 5), its
spheres of unit mass and inertia, loaded by gravity over one step (dt 1e-3): c = S (B u_free + gap),
preconditioned as APGD does (colsim.engine.cones.scales_of_diagonal). Both start from zero forces,
each with its own Lipschitz estimate (the same power iteration, on its own kernels: equal to rounding). Reported: milliseconds an iteration (the whole run over the
iterations, wall time, the GPU synchronised), their ratio, the iterate's largest difference over its
largest entry after the run, and the restarts and backtracks of each (the same on both when the
rounding of their sums does not flip a decision). The GPU's reads of its control array (one a
round of trial steps, CudaIteration.iterate) are inside its time. Beside them: the bytes an iteration must move
(:func:`iteration_bytes`, counted from the kernels' arrays at the run's backtracks and checks) and
how many times the time to move them the GPU took, at the card's nominal bandwidth and at that of a
1 GiB device-to-device copy; and the GPU's time with every launch the plain way (numba-cuda's
dispatcher, colsim.engine.cuda_launch.plain_launches) from the same start, whose iterate must be
the same bits. Run the CPU baseline on the same machine, in the same call.
With --storage-variants, the iterations again with some of their arrays stored narrower
(:data:`STORAGE_VARIANTS`: the indices in int32; the iterate x, the bodies' h = T x and the wrenches
in float32; the contacts' geometry in float32 too), each on its own compiled copy of the kernels that
read them: milliseconds an iteration, the bytes it must move, and how far its iterate ends from the
one stored as compiled (int32 indices: the same bits; float32: about 1e-7, its rounding). An
iteration moves its bytes at 1.2-1.5x a copy's time on an H200, so narrower storage is the lever
on its time that is left; the iterate's residuals are not checked here (a solver storing float32
would check them from a float64 T x).
Without a GPU the kernels run on numba's simulator (NUMBA_ENABLE_CUDASIM=1): only to check the
script, at a hundred spheres and a few iterations; its times mean nothing.
"""
from __future__ import annotations

import argparse
import contextlib
import cProfile
import math
import tempfile
import threading
import time

from pathlib import Path

import numpy as np

import kernel_trace
import record
from cuda_operator import DIAMETER, lattice_contacts, lattice_positions
from colsim.engine.cones import scales_of_diagonal
from colsim.engine.cuda_launch import launch, plain_launches
from colsim.engine.contacts import swept_pairs
from colsim.engine.state import ParticleState
from colsim.engine.operator import ContactOperator
from colsim.engine.threads import threads
from colsim.engine.apgd_iteration import CpuIteration

GRAVITY, DT = 9.81, 1e-3
#: bytes of a float64 or an int64, the kernels' only element types
WORD = 8


def iteration_bytes(m: int, n: int, entries: int, trial_steps: int, iterations: int, checks: int,
                    sizes: dict | None = None) -> int:
    """The bytes APGD's CUDA kernels (colsim.engine.cuda_apgd, colsim.engine.cuda_operator) must move
    over `iterations` iterations made of `trial_steps` trial steps (the backtracks' repeats included)
    and `checks` residual checks, for m contacts among n bodies with `entries` (body, contact) entries:
    every array element a kernel reads or writes, counted once (a gathered entry read by several
    threads once too): a lower bound on the traffic to the GPU's memory. `sizes`: the bytes of an
    element of the groups STORED_GROUPS names (:data:`STORAGE_VARIANTS`), 8 for any not given.

    A trial step: the projection reads x, x_prev and the two scaled coefficients and writes x_new
    (17m); the same thread's gradient at y reads hx, hx_prev and inv_mass of its bodies (18n: hy = hx
    + beta (hx - hx_prev) is made there), i, j and c (7m), and with its wrench s, the frame and the
    three lengths, writing 9 a contact (26m); the bodies' sums read their starts, entries and the
    wrenches and write h_new (7n + 1 + entries + 9m); the same thread's part of the descent test
    reads hx, hx_prev and inv_mass (18n). A residual check, one kernel: the gradient at x in registers
    (hx and inv_mass of its bodies, i, j, c, s, the frame and the three lengths: 12n + 24m), x, mu
    and mu_r (7m), every one float64 under any storage; under float32 storage two kernels first widen
    the iterate (5m read at its size, 5m written) and make its T x in float64 (the wrench reads 5m + 17m
    and writes 9m, the bodies' sums read n + 1 + entries + 9m and write 6n). Until 2026-11-29 (the
    storage a solver's option) a check read the trial steps' arrays as stored, and before that day a
    kernel of its own stored the gradient (12n + 29m) and the residual kernel read it back (g, x, s,
    mu and mu_r: 17m). Until 2026-11-28 an accepted trial step was followed by a kernel that took the
    gradient at the new y and wrote it, for the next projection to read
    (18n + 29m an iteration, and 5m more a trial step); until 2026-11-27 the kernels also read back
    x_new and h_new (5m + 6n a trial step), stored hy (18n an iteration) and copied x_new and h_new
    into their slots; the bound counted the first two."""
    size = {group: WORD for group in STORED_GROUPS} | (sizes or {})
    iterate, bodies, work, geometry, indices = (size[g] for g in STORED_GROUPS)
    trial = (iterate * 15 * m + WORD * 2 * m                                  # the projection
             + bodies * 12 * n + WORD * 6 * n + indices * 2 * m + WORD * 5 * m   # the gradient at y
             + geometry * 17 * m + work * 9 * m                                # the wrench
             + indices * (n + 1 + entries) + work * 9 * m + bodies * 6 * n     # the bodies' sums
             + bodies * 12 * n + WORD * 6 * n)                                 # the descent test
    check = WORD * (12 * n + 31 * m)
    if iterate != WORD:   # float32 storage: the iterate widened, its T x made in float64
        check += iterate * 5 * m + WORD * (5 * m + 31 * m + n + 1 + entries + 9 * m + 6 * n)
    return trial_steps * trial + checks * check


def bandwidth(cuda, gib: float = 1.0, repeat: int = 5) -> tuple[float | None, float]:
    """(the device's nominal memory bandwidth from its memory clock and bus width, or None where the
    driver does not say (the simulator); the best of `repeat` device-to-device copies of `gib` GiB,
    bytes read plus written over the time), both in GB/s."""
    try:   # the clock in kHz, double data rate
        device = cuda.get_current_device()
        nominal = 2.0 * device.MEMORY_CLOCK_RATE * 1e3 * device.GLOBAL_MEMORY_BUS_WIDTH / 8 / 1e9
    except Exception:
        nominal = None
    size = max(1, int(gib * 2**30) // WORD)
    source, target = cuda.to_device(np.ones(size)), cuda.device_array(size)
    best = math.inf
    for _ in range(repeat):
        cuda.synchronize()
        begin = time.perf_counter()
        target.copy_to_device(source)
        cuda.synchronize()
        best = min(best, time.perf_counter() - begin)
    return nominal, 2 * size * WORD / best / 1e9


def start_of(spheres: int) -> tuple[CpuIteration, ContactOperator, np.ndarray, np.ndarray]:
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
    start = CpuIteration(operator.geometry(s.ravel()), c, mu_s, mu_r_s, inv_mass, np.zeros(5 * contacts.m), s, 0.9)
    return start, operator, contacts.mu, contacts.mu_r


#: the launch bounds (threads a block, blocks an SM at least) that --register-variants compiles APGD's
#: projection kernel with, besides none: ptxas for sm_90 (CUDA 13.0, here) gives it 112 registers a
#: thread without bounds (two blocks of 256 an SM: a quarter of the threads an SM can hold), 80 with
#: (256, 3) and 64 with (256, 4), spilling 184 and 308 bytes a thread
REGISTER_VARIANTS = ((256, 3), (256, 4))


def projection_variant(bounds: tuple[int, int]):
    """APGD's projection kernel (colsim.engine.cuda_apgd._project_kernel, the largest of a trial step)
    compiled anew with launch bounds `bounds`, which cap its registers: the same arithmetic, so the
    same iterate; on numba's simulator, which has no launch bounds, compiled without."""
    from numba import cuda
    from numba.core import config as numba_config

    from colsim.engine import cuda_apgd as apgd_cuda

    function = apgd_cuda._project_kernel.py_func
    return cuda.jit(function) if numba_config.ENABLE_CUDASIM else cuda.jit(launch_bounds=bounds)(function)


@contextlib.contextmanager
def kernels_swapped(kernels: dict):
    """colsim.engine.cuda_apgd's kernels named in `kernels` replaced by the ones given while inside:
    the CUDA iterations made there (their trial steps prepared, their checks launched) use them."""
    from colsim.engine import cuda_apgd as apgd_cuda

    before = {name: getattr(apgd_cuda, name) for name in kernels}
    try:
        for name, kernel in kernels.items():
            setattr(apgd_cuda, name, kernel)
        yield
    finally:
        for name, kernel in before.items():
            setattr(apgd_cuda, name, kernel)


#: the groups of an iteration's arrays whose element size --storage-variants changes: the iterate's
#: three slots x (5m each), the bodies' three slots h = T x (6n each), the wrenches (m, 9), the
#: contacts' geometry read as floats (s, the frames, the two radii and the lever: 17m) and the integers
#: (i, j, each body's start and entries)
STORED_GROUPS = ("iterate", "bodies", "work", "geometry", "indices")

#: --storage-variants and --stored: each by its key, a name and the element size of the groups it
#: narrows (the rest stay 8 bytes). float32 holds a stored value to 6e-8 of itself; the kernels'
#: arithmetic stays float64 where a float64 takes part (numba promotes; a difference of two stored
#: values rounds in float32), so what changes is the rounding of what is stored. int32 holds any
#: index below 2**31 exactly.
STORAGE_VARIANTS = {
    "int32": ("indices int32", {"indices": 4}),
    "float32": ("x, T x and the wrenches float32", {"iterate": 4, "bodies": 4, "work": 4}),
    "float32-geometry": ("x, T x, the wrenches and the geometry float32",
                         {"iterate": 4, "bodies": 4, "work": 4, "geometry": 4}),
    "all": ("all of these", {"iterate": 4, "bodies": 4, "work": 4, "geometry": 4, "indices": 4}),
}


def stored_as(run, sizes: dict):
    """`run` (a fresh CudaIteration) with the groups of `sizes` narrowed on the device, its trial steps
    prepared again with them: the floats by the solver's own float32 storage
    (:meth:`colsim.engine.cuda_apgd.CudaIteration.narrow_storage`: the iterate, T x and the wrenches
    together, the geometry with them or not; its checks widen the iterate and make T x in float64), the
    indices in int32 (the trial steps' alone)."""
    from colsim.engine.cuda_operator import cast_on_device

    narrow = {group for group, size in sizes.items() if size != WORD}
    if narrow & {"iterate", "bodies", "work"}:
        if not {"iterate", "bodies", "work"} <= narrow:
            raise ValueError("float32 storage narrows the iterate, T x and the wrenches together")
        run.narrow_storage(geometry="geometry" in narrow)
    if "indices" in narrow:
        geo = run.trial_geometry
        run.trial_geometry = geo._replace(**{name: cast_on_device(getattr(geo, name), np.int32)
                                             for name in ("i", "j", "start", "entry")})
        run.prepare_trial()   # narrow_storage prepares its own
    return run


@contextlib.contextmanager
def every_iteration_stored(key: str):
    """Every APGD iteration on the device made inside the block stored as STORAGE_VARIANTS[key] has it
    (:func:`stored_as`; each variant's kernels compiled for its types), to time a collapse's steps so. Its checks,
    forces and increments are float64, as under the solver's float32 storage (`float32-geometry` is
    that storage: `colsim collapse --gpu-storage float32`)."""
    from colsim.engine.cuda_apgd import CudaIteration

    sizes = STORAGE_VARIANTS[key][1]
    made = CudaIteration.__init__

    def narrowed(self, *args, **kwargs):
        made(self, *args, **kwargs)
        stored_as(self, sizes)

    CudaIteration.__init__ = narrowed
    try:
        yield
    finally:
        CudaIteration.__init__ = made


def registers_of(kernel) -> str:
    """The registers a thread of `kernel` uses on this GPU, as numba-cuda reports them ("-": unknown,
    e.g. on the simulator)."""
    try:
        found = kernel.get_regs_per_thread()
    except Exception:   # the simulator, or a numba-cuda without it
        return "-"
    return str(next(iter(found.values()))) if isinstance(found, dict) and found else str(found)


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


def launch_costs(cuda, repeat: int = 2000) -> dict:
    """Microseconds of what an APGD iteration on the GPU pays besides its memory traffic, each the mean
    over `repeat` back-to-back calls (synchronised once at the end): launching an empty kernel of one
    device-array argument, of 13 (12 device arrays and a float, as the gradient kernel takes), the
    same through a dispatcher specialised to those arguments (`specialize`: no type resolution a
    call), both through colsim.engine.cuda_launch (the arrays' words made once), and a copy of
    3 x 128 float64 to the host (a trial step's round trip, synchronising); then an allocation of
    8 kB on the device and copies of 8 kB and 8 MB from the host, each into a new array (what a
    step's set-up pays for each of the dozens of arrays it makes)."""
    arrays, one, many = empty_kernels(cuda)

    def mean_us(call) -> float:
        return mean_launch_us(cuda, call, repeat)

    parts = cuda.to_device(np.zeros((3, 128)))
    costs = {"1 argument": mean_us(lambda: one[1, 128](arrays[0])),
             "13 arguments": mean_us(lambda: many[1, 128](*arrays, 1.0)),
             "1 argument, marshalled once (cuda_launch)": mean_us(lambda: launch(one, 1, 128, arrays[0])),
             "13 arguments, marshalled once (cuda_launch)": mean_us(lambda: launch(many, 1, 128, *arrays, 1.0))}
    try:
        special = many.specialize(*arrays, 1.0)
        costs["13 arguments, specialised"] = mean_us(lambda: special[1, 128](*arrays, 1.0))
    except Exception as error:   # a numba without it
        print(f"specialize: {error}")
    costs["copy 3 x 128 to the host"] = mean_us(lambda: parts.copy_to_host())
    # what a step's set-up pays for each array it makes on the device (dozens a step: the frames,
    # the solver's start, detection's lists): an allocation (numba-cuda's, freed in batches), and a
    # small and a large copy from the host's (pageable) memory
    small, large = np.zeros(1024), np.zeros(1 << 20)
    costs["allocate 8 kB on the device"] = mean_us(lambda: cuda.device_array(1024))
    costs["copy 8 kB from the host (allocated)"] = mean_us(lambda: cuda.to_device(small))
    costs["copy 8 MB from the host (allocated)"] = mean_us(lambda: cuda.to_device(large))
    return costs


def empty_kernels(cuda) -> tuple:
    """(12 device arrays of 1,024 float64, an empty kernel of one array, one of 12 arrays and a float)."""
    arrays = [cuda.to_device(np.zeros(1024)) for _ in range(12)]

    @cuda.jit
    def one(a):
        pass

    @cuda.jit
    def many(a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, x):
        pass

    return arrays, one, many


def mean_launch_us(cuda, call, repeat: int) -> float:
    """Microseconds a call of `call`, the mean over `repeat` back-to-back calls after one more (which
    compiles), synchronised before and after."""
    call()
    cuda.synchronize()
    begin = time.perf_counter()
    for _ in range(repeat):
        call()
    cuda.synchronize()
    return 1e6 * (time.perf_counter() - begin) / repeat


def detection(spheres: int, repeat: int = 3) -> dict:
    """Best-of-`repeat` seconds of the swept pairs of the lattice of about `spheres` on the CPU and on
    the GPU (the first call of each compiles), the pairs found, and whether both found the same."""
    from colsim.engine.cuda_contacts import swept_pairs_on_device

    position, _ = lattice_positions(spheres)
    state = ParticleState.at_rest(position, np.full(len(position), DIAMETER / 2))
    predicted = np.random.default_rng(1).uniform(-0.01, 0.01, position.shape) * DIAMETER
    found, best = {}, {}
    for name, find in (("cpu", swept_pairs), ("gpu", swept_pairs_on_device)):
        found[name] = find(state, predicted, 0.02 * DIAMETER, 0.5)
        best[name] = min(_timed_call(find, state, predicted, 0.02 * DIAMETER, 0.5) for _ in range(repeat))
    same = all(np.array_equal(a, b) for a, b in zip(found["cpu"], found["gpu"]))
    return {"spheres": state.n, "pairs": len(found["cpu"][0]), "cpu_s": best["cpu"], "gpu_s": best["gpu"], "same": same}


def matching(spheres: int, repeat: int = 3) -> dict:
    """Best-of-`repeat` seconds of the warm start's matching on the lattice of about `spheres`, every
    contact's force stored (in its cone), on the host and on the GPU, and their largest difference.
    The GPU's two ways: from a host record (its keys and forces copied in, the result copied back:
    gpu_s) and as a step now matches, from the forces the step before left on the device
    (:class:`colsim.engine.cuda_warm_start.DeviceWarmStart`) with the result left there for the
    solver (gpu_carried_s: to the end of the kernels)."""
    from numba import cuda

    from colsim.engine.backends import make_backend
    from colsim.engine.warm_start import WarmStart

    backends = {device: make_backend(device) for device in ("cpu", "cuda")}
    contacts, n = lattice_contacts(spheres)
    forces = np.random.default_rng(2).uniform(0.0, 1.0, (contacts.m, 5)) * [1.0, 0.3, 0.3, 0.05, 0.05]
    record_on_host = WarmStart.from_step(contacts, forces)
    record_on_device = backends["cuda"].carried(contacts, forces)

    def matched(device):   # on the host: the GPU's result copied back, so that its time is all in
        out = backends[device].matched(record_on_host, contacts)
        return out.copy_to_host() if device == "cuda" else out

    def matched_on_device():
        out = backends["cuda"].matched(record_on_device, contacts)
        cuda.synchronize()
        return out

    found, best = {}, {}
    for device in ("cpu", "cuda"):
        found[device] = matched(device)
        best[device] = min(_timed_call(matched, device) for _ in range(repeat))
    carried = matched_on_device().copy_to_host()
    best["carried"] = min(_timed_call(matched_on_device) for _ in range(repeat))
    largest = np.abs(found["cpu"]).max()
    difference = float(max(np.abs(found["cuda"] - found["cpu"]).max(), np.abs(carried - found["cpu"]).max()) / largest)
    return {"spheres": n, "contacts": contacts.m, "cpu_s": best["cpu"], "gpu_s": best["cuda"],
            "gpu_carried_s": best["carried"], "difference": difference}


def _timed_call(call, *args) -> float:
    """Wall seconds of call(*args)."""
    begin = time.perf_counter()
    call(*args)
    return time.perf_counter() - begin


#: the phases of a step that its diagnostics time (StepDiagnostics' <phase>_time), in the step's order
PHASES = ("detection", "assembly", "matching", "setup", "solve", "check")


@contextlib.contextmanager
def kernels_busy(interval: float = 0.05):
    """Yields a dict that holds, after the block, "busy": the share of the block's wall time in which
    the GPU ran a kernel, the mean of NVML's utilisation read every `interval` seconds by a thread
    (nvmlDeviceGetUtilizationRates(...).gpu: the percent of its last sample period, 1/6 to 1 s by
    card, in which one or more kernels ran), and "samples", how many; NaN and 0 where NVML or a GPU
    is not at hand (numba's simulator, no nvidia-ml-py). Another process's kernels count too."""
    found = {"busy": math.nan, "samples": 0}
    try:
        import pynvml

        pynvml.nvmlInit()
        handle = pynvml.nvmlDeviceGetHandleByIndex(0)
    except Exception:   # no nvidia-ml-py, no driver or no GPU: nothing to read
        yield found
        return
    readings, stop = [], threading.Event()

    def sample():
        while not stop.wait(interval):
            readings.append(pynvml.nvmlDeviceGetUtilizationRates(handle).gpu)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    try:
        yield found
    finally:
        stop.set()
        sampler.join()
        pynvml.nvmlShutdown()
        if readings:
            found.update(busy=float(np.mean(readings)) / 100.0, samples=len(readings))


def collapse_steps(column: str, steps: int, device: str, profile: str | None = None,
                   trace: str | None = None) -> dict:
    """The first `steps` steps of `column`'s collapse with APGD on `device`: wall seconds a step, the
    shares of the wall time of each of :data:`PHASES` (the rest: redone attempts, the step's update
    and bookkeeping, the collapse's frames and checkpoints between steps; the part of it in redone
    steps, and their count, apart), iterations a step, the end positions, and on a GPU the share of
    the wall time its kernels ran (:func:`kernels_busy`), and by step its seconds, iterations,
    redone attempts, missed contacts, detection margin and contacts (which steps are redone, and
    why); profile: a file for cProfile's statistics
    of the steps (None: none); trace: a file for the steps' kernel trace (benchmarks/kernel_trace.py:
    the card's busy share, idle gaps and kernels; None: none)."""
    from colsim import io
    from colsim.engine.backends import make_backend
    from colsim.solvers import make_solver
    from colsim.stages.collapse import collapse
    from colsim.stages.settings import CollapseSettings

    state, source = io.read_state(column)
    settings = CollapseSettings(mu_r=0.12, checkpoint_every=10**9, frame_every=steps)   # the last step a frame
    backend = make_backend(device)
    solver = make_solver("auto", scaled_time_step=settings.scaled_step, apgd={"backend": backend})
    busy = contextlib.nullcontext({"busy": math.nan, "samples": 0}) if device == "cpu" else kernels_busy()
    start = time.perf_counter()
    with _profiled(profile), busy as kernels, _traced(trace) as traced:
        run = collapse(state, float(source.attrs["h0"]), settings, solver, warm_start=io.contact_forces_of(source),
                       stop_after=steps, backend=backend)
    wall = time.perf_counter() - start
    if trace is not None:
        kernel_trace.write_summary(traced["found"], traced["why"], f"kernel trace of the first {steps} steps of "
                                   f"{column} on {device} ({wall:.1f} s with the trace)", trace)
    d = run.diagnostics
    shares = {name: sum(getattr(x, f"{name}_time") for x in d) / wall for name in PHASES}
    redone = [x for x in d if x.redone]   # their rest: mostly the attempts they threw away
    redone_rest = sum(x.wall_time - sum(getattr(x, f"{name}_time") for name in PHASES) for x in redone) / wall
    last_step, last = run.frames[-1]
    assert last_step == len(d) == steps, (last_step, len(d), steps)   # the end state, not the column's
    return {"spheres": state.n, "s_a_step": wall / len(d), "solve_share": shares["solve"], "shares": shares,
            "redone_steps": len(redone), "redone_rest_share": redone_rest, "kernels_busy": kernels["busy"],
            "busy_samples": kernels["samples"], "s_by_step": [x.wall_time for x in d],
            "by_step": {"iterations": [x.solver_iterations for x in d], "redone": [x.redone for x in d],
                        "missed_contacts": [x.missed_contacts for x in d],
                        "margin": [x.detection_margin for x in d], "contacts": [x.n_contacts for x in d]},
            "iterations": float(np.mean([x.solver_iterations for x in d])), "end": last.position,
            "diameter": 2 * float(state.radius.mean())}


def step_times(trajectory: str) -> dict:
    """Where a finished collapse's steps spent their wall time, from its file's per-step diagnostics
    (a `colsim collapse` trajectory): seconds, the shares of the :data:`PHASES` its file times (a file
    written before matching and check were timed lacks those two; the rest: redone attempts' other
    work, the update and the bookkeeping), mean iterations, steps redone, and seconds a step over
    each third."""
    import xarray as xr

    with xr.open_dataset(trajectory) as d:
        wall = d["step_wall_time"].values
        parts = {name: float(d[f"step_{name}_time"].sum()) for name in PHASES if f"step_{name}_time" in d}
        iterations, redone = d["step_solver_iterations"].values, d["step_redone"].values
        spheres = int(d.sizes.get("particle", 0))
    total = float(wall.sum())
    thirds = [float(np.mean(part)) for part in np.array_split(wall, 3) if len(part)]
    return {"trajectory": trajectory, "spheres": spheres, "steps": len(wall), "wall_s": total,
            "shares": {name: value / total for name, value in parts.items()},
            "iterations": float(np.mean(iterations)), "redone": int(np.count_nonzero(redone)),
            "s_a_step_by_third": thirds}


def _traced(path: str | None):
    """The block's kernels traced (benchmarks/kernel_trace.py), or nothing when path is None."""
    return contextlib.nullcontext({}) if path is None else kernel_trace.kernels_traced()


@contextlib.contextmanager
def _profiled(path: str | None):
    """cProfile the block into `path` (pstats), or nothing when None."""
    if path is None:
        yield
        return
    profile = cProfile.Profile()
    profile.enable()
    try:
        yield
    finally:
        profile.disable()
        profile.dump_stats(path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spheres", type=int, nargs="*", default=[73_000, 704_000, 2_000_000])
    parser.add_argument("--iterations", type=int, default=60)
    parser.add_argument("--columns", nargs="*", default=[], help="column files (colsim trim) to collapse")
    parser.add_argument("--steps", type=int, default=20, help="steps of each column's collapse")
    parser.add_argument("--cpu-steps", type=int, default=None, help="steps of the CPU's collapse of each column "
                        "(default: --steps; 0: the GPU's only)")
    parser.add_argument("--tile", type=float, default=None, metavar="R0", help="collapse columns of radius R0 "
                        "tiled from each of --columns (benchmarks/tiling.py: for timing, not a pour)")
    parser.add_argument("--trajectories", nargs="*", default=[], help="finished collapses (colsim collapse "
                        "files) whose steps' wall time to split by phase, as the rest stage's runs on a GPU")
    parser.add_argument("--profile", default=None, help="a folder for cProfile's statistics of each column's "
                        "collapse steps on each device (COLUMN-DEVICE.pstats)")
    parser.add_argument("--kernel-trace", default=None, metavar="FOLDER", help="after each column's timed GPU "
                        "steps, its first --trace-steps steps again with their kernels traced (slower; "
                        "benchmarks/kernel_trace.py), the tables in FOLDER/COLUMN.kernels")
    parser.add_argument("--trace-steps", type=int, default=20, help="the steps traced (default 20)")
    parser.add_argument("--register-variants", action="store_true", help="also time the iterations on each "
                        "--spheres lattice with APGD's projection kernel compiled with each of REGISTER_VARIANTS' "
                        "launch bounds (fewer registers, more threads an SM), and say whether the iterate is the same")
    parser.add_argument("--storage-variants", action="store_true", help="also time the iterations on each "
                        "--spheres lattice with some of their arrays stored narrower (STORAGE_VARIANTS: int32 "
                        "indices, float32 iterate, bodies' sums, wrenches and geometry), and say how far the "
                        "iterate ends from the float64 one's")
    parser.add_argument("--stored", nargs="*", default=[], choices=sorted(STORAGE_VARIANTS),
                        help="also run each --columns' GPU steps again with APGD's arrays stored as each of these "
                        "STORAGE_VARIANTS has them (e.g. float32: x, T x and the wrenches)")
    args = parser.parse_args(argv)
    from numba import cuda
    from numba.core import config as numba_config

    from colsim.engine import cuda_apgd as apgd_cuda
    from colsim.engine.cuda_apgd import CudaIteration

    device = ("simulator" if numba_config.ENABLE_CUDASIM else cuda.get_current_device().name if cuda.is_available()
              else "no GPU")   # --trajectories alone needs none
    device = device.decode() if isinstance(device, bytes) else str(device)
    record.note("device", device)
    if args.spheres:
        launches = record.table(["what", f"us each ({device})"], title="launch and round-trip costs")
        for what, us in launch_costs(cuda, 5 if numba_config.ENABLE_CUDASIM else 2000).items():
            launches.row(what, f"{us:.1f}", data={"what": what, "us": us, "device": device})
    nominal, copied = bandwidth(cuda, 1e-4 if numba_config.ENABLE_CUDASIM else 1.0) if args.spheres else (None, None)
    if args.spheres:
        record.note("bandwidth", {"nominal_gb_s": nominal, "copy_gb_s": copied})
        print(f"memory bandwidth: nominal {'unknown' if nominal is None else f'{nominal:.0f} GB/s'}, "
              f"a device-to-device copy {copied:.0f} GB/s")
    if args.spheres:
        table = record.table(["spheres", "contacts", f"CPU ms an iteration ({threads()} threads)",
                              f"GPU ms an iteration ({device})", "GPU vs CPU", "iterate difference / largest",
                              "restarts, backtracks (CPU; GPU)", "GB an iteration (counted)",
                              "GPU over the bound (copy bandwidth; nominal)",
                              "GPU ms, plain launches (same iterate)"])
    for spheres in args.spheres:   # none with `--spheres` alone
        for warm_up in range(2):   # the first compiles both kernel sets; all start again from the same point
            cpu, operator, mu, mu_r = start_of(spheres)
            gpu, plain = (CudaIteration.like(cpu, operator, mu, mu_r) for _ in range(2))
            if not warm_up:
                timed(cpu, 1, mu, mu_r)
                timed(gpu, 1, mu, mu_r, cuda.synchronize)
        gpu_s = timed(gpu, args.iterations, mu, mu_r, cuda.synchronize)
        with plain_launches():
            plain_s = timed(plain, args.iterations, mu, mu_r, cuda.synchronize)
        cpu_s = timed(cpu, args.iterations, mu, mu_r)
        x = cpu.host_x()
        difference = float(np.max(np.abs(gpu.host_x() - x)) / max(np.max(np.abs(x)), 1e-300))
        same = bool(np.array_equal(gpu.host_x(), plain.host_x()))
        per_cpu, per_gpu = cpu_s / args.iterations, gpu_s / args.iterations
        moved = iteration_bytes(operator.m, operator.n, len(operator.entry), args.iterations + gpu.backtracks,
                                args.iterations, math.ceil(args.iterations / 10)) / args.iterations
        over = [per_gpu / (moved / (1e9 * rate)) if rate else None for rate in (copied, nominal)]
        table.row(operator.n, operator.m, f"{1e3 * per_cpu:.2f}", f"{1e3 * per_gpu:.2f}", f"{per_cpu / per_gpu:.1f}",
                  f"{difference:.1e}", f"{cpu.restarts}, {cpu.backtracks}; {gpu.restarts}, {gpu.backtracks}",
                  f"{moved / 1e9:.3f}", "; ".join("-" if x is None else f"{x:.1f}" for x in over),
                  f"{1e3 * plain_s / args.iterations:.2f} ({'yes' if same else 'NO'})",
                  data={"plain_launch_gpu_ms": 1e3 * plain_s / args.iterations, "plain_same_iterate": same, "spheres": operator.n, "contacts": operator.m, "cpu_ms": 1e3 * per_cpu,
                        "gpu_ms": 1e3 * per_gpu, "cpu_threads": threads(), "device": device,
                        "simulator": bool(numba_config.ENABLE_CUDASIM), "iterations": args.iterations,
                        "relative_difference": difference, "bytes_an_iteration": moved,
                        "over_copy_bound": over[0], "over_nominal_bound": over[1]})
    if args.spheres and args.register_variants:
        variants = record.table(["spheres", "projection kernel's launch bounds", "registers a thread",
                                 f"GPU ms an iteration ({device})", "same iterate as without bounds"],
                                title="the projection kernel's registers")
    for spheres in args.spheres if args.register_variants else ():
        cpu, operator, mu, mu_r = start_of(spheres)
        reference = None
        for bounds in (None, *REGISTER_VARIANTS):
            try:
                kernel = apgd_cuda._project_kernel if bounds is None else projection_variant(bounds)
                with kernels_swapped({"_project_kernel": kernel}):
                    timed(CudaIteration.like(cpu, operator, mu, mu_r), 1, mu, mu_r, cuda.synchronize)   # compiles it
                    run = CudaIteration.like(cpu, operator, mu, mu_r)
                    seconds = timed(run, args.iterations, mu, mu_r, cuda.synchronize)
            except Exception as error:   # a numba-cuda without launch bounds, say: the others still run
                variants.row(operator.n, bounds, "-", f"failed: {type(error).__name__}: {str(error)[:120]}", "-")
                continue
            reference = run if bounds is None else reference
            same = reference is not None and bool(np.array_equal(run.host_x(), reference.host_x()))
            registers = registers_of(kernel)
            variants.row(operator.n, "none" if bounds is None else f"{bounds[0]} threads, {bounds[1]} blocks an SM",
                         registers, f"{1e3 * seconds / args.iterations:.3f}", "yes" if same else "NO",
                         data={"spheres": operator.n, "contacts": operator.m, "launch_bounds": bounds,
                               "registers": registers, "gpu_ms": 1e3 * seconds / args.iterations,
                               "same_iterate": same, "device": device, "iterations": args.iterations})
    if args.spheres and args.storage_variants:
        stored = record.table(["spheres", "stored", f"GPU ms an iteration ({device})", "GB an iteration (counted)",
                               "GPU over the bound (copy bandwidth)", "iterate difference / largest"],
                              title="APGD's iteration with its arrays stored narrower")
    starts = {spheres: start_of(spheres) for spheres in args.spheres} if args.storage_variants else {}
    reference = {}   # each lattice's iterate as compiled
    for name, sizes in (("as compiled", {}), *STORAGE_VARIANTS.values()) if args.storage_variants else ():
        for spheres, (cpu, operator, mu, mu_r) in starts.items():
            try:
                timed(stored_as(CudaIteration.like(cpu, operator, mu, mu_r), sizes), 1, mu, mu_r,
                      cuda.synchronize)   # compiles this variant's kernels, or warms them up
                run = stored_as(CudaIteration.like(cpu, operator, mu, mu_r), sizes)
                seconds = timed(run, args.iterations, mu, mu_r, cuda.synchronize)
            except Exception as error:   # one variant's failure leaves the others
                stored.row(operator.n, name, f"failed: {type(error).__name__}: {str(error)[:120]}", "-", "-",
                           "-")
                continue
            x = run.host_x().astype(np.float64)
            first = reference.setdefault(spheres, x)
            difference = float(np.max(np.abs(x - first)) / max(np.max(np.abs(first)), 1e-300))
            moved = iteration_bytes(operator.m, operator.n, len(operator.entry), args.iterations + run.backtracks,
                                    args.iterations, math.ceil(args.iterations / 10), sizes) / args.iterations
            per = seconds / args.iterations
            stored.row(operator.n, name, f"{1e3 * per:.3f}", f"{moved / 1e9:.3f}",
                       f"{per / (moved / (1e9 * copied)):.1f}" if copied else "-", f"{difference:.1e}",
                       data={"spheres": operator.n, "contacts": operator.m, "stored": name, "sizes": sizes,
                             "gpu_ms": 1e3 * per, "bytes_an_iteration": moved, "relative_difference": difference,
                             "backtracks": run.backtracks, "device": device, "iterations": args.iterations})
    if args.spheres:
        found = record.table(["spheres", "pairs", f"CPU ms ({threads()} threads)", f"GPU ms ({device})",
                              "GPU vs CPU", "same pairs"], title="the swept pairs of contact detection")
    for spheres in args.spheres:
        d = detection(spheres)
        found.row(d["spheres"], d["pairs"], f"{1e3 * d['cpu_s']:.1f}", f"{1e3 * d['gpu_s']:.1f}",
                  f"{d['cpu_s'] / d['gpu_s']:.1f}", "yes" if d["same"] else "NO",
                  data={**d, "device": device, "cpu_threads": threads(), "simulator": bool(numba_config.ENABLE_CUDASIM)})
    if args.spheres:
        matched = record.table(["spheres", "contacts", "CPU ms (host)", f"GPU ms ({device}), from the host",
                                "GPU ms, carried on the device", "GPU vs CPU (carried)", "difference / largest"],
                               title="the warm start's matching")
    for spheres in args.spheres:
        d = matching(spheres)
        matched.row(d["spheres"], d["contacts"], f"{1e3 * d['cpu_s']:.1f}", f"{1e3 * d['gpu_s']:.1f}",
                    f"{1e3 * d['gpu_carried_s']:.1f}", f"{d['cpu_s'] / d['gpu_carried_s']:.1f}",
                    f"{d['difference']:.1e}",
                    data={**d, "device": device, "simulator": bool(numba_config.ENABLE_CUDASIM)})
    if args.trajectories:
        spent = record.table(["trajectory", "spheres", "steps", "wall s", ", ".join(PHASES) + ", rest",
                              "iterations a step", "steps redone", "s a step by third"],
                             title="where whole collapses spent their steps' time")
    for trajectory in args.trajectories:
        t = step_times(trajectory)
        shares = t["shares"]
        spent.row(Path(trajectory).name, t["spheres"], t["steps"], f"{t['wall_s']:.1f}",
                  ", ".join([f"{shares[name]:.0%}" if name in shares else "-" for name in PHASES]
                            + [f"{1.0 - sum(shares.values()):.0%}"]),
                  f"{t['iterations']:.0f}", t["redone"], ", ".join(f"{x:.3f}" for x in t["s_a_step_by_third"]),
                  data={**t, "device": device})
    if args.columns:
        collapse_table(args, device)


def collapse_table(args, device: str) -> None:
    """The table of the first `args.steps` collapse steps of each column on both devices."""
    steps = record.table(["column", "spheres", f"CPU s a step ({threads()} threads)", "APGD share (CPU)",
                          f"GPU s a step ({device})", "APGD share (GPU)", "GPU busy (NVML)", "GPU vs CPU",
                          "iterations a step (CPU; GPU)",
                          "end positions apart / mean diameter",
                          "GPU's " + ", ".join(name for name in PHASES if name != "solve")
                          + ", rest (shares; the rest's in redone steps)"],
                         title=f"the first {args.steps} collapse steps")
    if args.stored:
        narrow = record.table(["column", "spheres", "stored", f"GPU s a step ({device}), as compiled", "stored so",
                               "APGD share (as compiled; stored so)", "iterations a step (as compiled; stored so)",
                               "redone steps (as compiled; stored so)", "end positions apart / mean diameter"],
                              title=f"the first {args.steps} collapse steps with APGD's arrays stored narrower")
    if args.profile:
        Path(args.profile).mkdir(parents=True, exist_ok=True)
    cpu_steps = args.steps if args.cpu_steps is None else args.cpu_steps
    for column in args.columns:
        if args.tile:
            column = _tiled(column, args.tile)
        runs = {"cpu": cpu_steps, "cuda": args.steps}
        for where in (where for where, count in runs.items() if count):   # compiles each kernel set first
            collapse_steps(column, 1, where)
        cpu, gpu = (collapse_steps(column, runs[where], where, args.profile and str(
            Path(args.profile) / f"{Path(column).stem}-{where}.pstats")) if runs[where] else None
            for where in ("cpu", "cuda"))
        if args.kernel_trace and args.steps:
            Path(args.kernel_trace).mkdir(parents=True, exist_ok=True)
            collapse_steps(column, min(args.trace_steps, args.steps), "cuda",
                           trace=str(Path(args.kernel_trace) / f"{Path(column).stem}.kernels"))
        for key in args.stored if args.steps else ():
            with every_iteration_stored(key):
                collapse_steps(column, 1, "cuda")   # compiles this variant's kernels
                other = collapse_steps(column, args.steps, "cuda")
            narrowed_apart = float(np.abs(other["end"] - gpu["end"]).max() / gpu["diameter"])
            narrow.row(column, gpu["spheres"], key, f"{gpu['s_a_step']:.3f}", f"{other['s_a_step']:.3f}",
                       f"{gpu['solve_share']:.0%}; {other['solve_share']:.0%}",
                       f"{gpu['iterations']:.0f}; {other['iterations']:.0f}",
                       f"{gpu['redone_steps']}; {other['redone_steps']}", f"{narrowed_apart:.1e}",
                       data={"column": column, "spheres": gpu["spheres"], "stored": key, "steps": args.steps,
                             "device": device, "gpu_s_a_step": gpu["s_a_step"], "stored_s_a_step": other["s_a_step"],
                             "stored_s_by_step": other["s_by_step"], "stored_by_step": other["by_step"],
                             "gpu_solve_share": gpu["solve_share"], "stored_solve_share": other["solve_share"],
                             "gpu_iterations": gpu["iterations"], "stored_iterations": other["iterations"],
                             "stored_redone_steps": other["redone_steps"], "apart_over_diameter": narrowed_apart})
        shares = gpu["shares"]
        rest = 1.0 - sum(shares.values())
        if cpu is None:
            cpu = {"s_a_step": math.nan, "solve_share": math.nan, "iterations": math.nan, "shares": {}}
            apart = math.nan
        else:
            apart = float(np.abs(cpu["end"] - gpu["end"]).max() / cpu["diameter"]) if cpu_steps == args.steps else math.nan
        steps.row(column, gpu["spheres"], _shown(cpu["s_a_step"], ".3f"), _shown(cpu["solve_share"], ".0%"),
                  f"{gpu['s_a_step']:.3f}", f"{gpu['solve_share']:.0%}", _shown(gpu["kernels_busy"], ".0%"),
                  _shown(cpu["s_a_step"] / gpu["s_a_step"], ".1f"),
                  f"{_shown(cpu['iterations'], '.0f')}; {gpu['iterations']:.0f}", _shown(apart, ".1e"),
                  ", ".join(f"{x:.0%}" for x in [shares[name] for name in PHASES if name != "solve"] + [rest])
                  + f" ({gpu['redone_rest_share']:.0%} in {gpu['redone_steps']} redone)",
                  data={"column": column, "spheres": gpu["spheres"], "steps": args.steps, "cpu_steps": cpu_steps,
                        "device": device, "cpu_s_a_step": cpu["s_a_step"], "gpu_s_a_step": gpu["s_a_step"],
                        "gpu_s_by_step": gpu["s_by_step"], "gpu_by_step": gpu["by_step"],
                        "cpu_solve_share": cpu["solve_share"], "gpu_solve_share": gpu["solve_share"],
                        "cpu_iterations": cpu["iterations"], "gpu_iterations": gpu["iterations"],
                        "apart_over_diameter": apart, "cpu_shares": cpu["shares"], "gpu_shares": shares,
                        "gpu_redone_steps": gpu["redone_steps"], "gpu_redone_rest_share": gpu["redone_rest_share"],
                        "gpu_kernels_busy": gpu["kernels_busy"], "gpu_busy_samples": gpu["busy_samples"]})


def _shown(value: float, spec: str) -> str:
    """value in format spec, or "-" for NaN (not measured)."""
    return "-" if math.isnan(value) else format(value, spec)


def _tiled(column: str, r0: float) -> str:
    """A column of radius r0 tiled from `column` (benchmarks/tiling.py), written to the temporary folder."""
    from tiling import tiled_column

    out = Path(tempfile.gettempdir()) / f"{Path(column).stem}-tiled-r0_{r0:g}.nc"
    spheres = tiled_column(column, r0, str(out))
    print(f"{out}: {spheres} spheres tiled from {column} (r0 = {r0:g}; for timing, not a pour)", flush=True)
    return str(out)


if __name__ == "__main__":
    record.run("gpu", main)
