"""APGD's iterations on one GPU: the kernels of an iteration, its decisions made on the
device, the residual check there, and the iteration state that stays on the device between checks.

Each kernel is its CPU twin's arithmetic (colsim.engine.apgd_iteration, colsim.engine.cones) for one contact
or one body a thread. Sums over contacts or bodies are taken per block by a fixed tree in shared
memory, then the blocks' sums in a fixed order: the same bits every run on one device (they differ
from the CPU's sums by rounding only). A trial step (projection, B' S z, the descent test's sums) is
followed by one block that adds its blocks' sums and decides as the CPU does, with the CPU's code
(:func:`colsim.engine.apgd_iteration.decide`: accept or backtrack, Nesterov's momentum, the restart), on the
iteration's scalars kept in a small device array; an accepted step then moves the iterate (the
roles of three slots move on, nothing is copied); the next trial step takes the gradient at its y
itself, in the projection's kernel: three launches a trial step. So the host launches trial steps
without waiting for any, and reads that array once a round of them (:meth:`CudaIteration.trial_round`,
a round of APGD's one loop): a trial step used to wait for a copy of its sums to the host, which
with the launches was most of a small column's iteration, several times its memory traffic. A
residual check costs one more copy. A solve's start is made on the device as
well (:meth:`CudaIteration.of_program`): the contacts' frames, the gaps, the coefficients and the
warm start go there once (the masses and free forces are made there by a step on the GPU,
:mod:`colsim.engine.cuda_state`), and the row scales, c, the first iterate,
T x and the Lipschitz estimate's power iteration are made by kernels.

Without a GPU the kernels run on numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1), as in the tests.
"""
from __future__ import annotations

import math

import numpy as np

from .cuda_operator import (THREADS, CudaContactOperator, block_reduce, blocks_for,   # first: numba.cuda
                            body_sums_on_device, cast_on_device, contact_arrays_on_device,
                            cuda, dot, for_types, four_block_results, full_on_device,   # cuda: on numpy 2.5
                            gradient_on_device, gradient_values, kept_device_copy, normalise_on_device,
                            project_point_on_device, transpose_on_device, wrench_on_device)
from .cones import combine_residuals, contact_residuals
from .cuda_launch import Prepared, launch
from .cuda_state import host_copy, increments_on_device, inverses_on_device, program_array_on_device
from .solver_contract import ACTIVE_FRACTION, ConeSolution
from .apgd_iteration import decide, extrapolated, lipschitz_estimate, power_start_drawn, run_iterations

#: the iteration's control on the device (float64 entries of CudaIteration.control): the Lipschitz
#: estimate, Nesterov's theta and beta, lip's decay an iteration, whether the last trial step was
#: accepted, which of the three slots holds x (:func:`_slot`), and the counts of accepted trial
#: steps (iterations), backtracks and restarts
LIP, THETA, BETA, LIP_DECAY, ACCEPTED, SLOT, ITERATIONS, BACKTRACKS, RESTARTS = range(9)
CONTROL_SIZE = 9

#: APGD's storages on the GPU, the first the default (colsim.solvers.defaults.GPU_STORAGES). float32: the iterate's three
#: slots, the bodies' three slots of h = T x, the wrenches between them and these contact arrays, as a
#: trial step reads them, hold float32 (half the bytes of an iteration that moves them: its time on a
#: GPU, whose iteration is bound by memory); the kernels' arithmetic stays float64 wherever a float64
#: takes part, and a residual check, the forces and the increments are made in float64 from the stored
#: iterate widened (:meth:`CudaIteration._widen`) and the float64 contact arrays: the same program,
#: checked as exactly as under float64
STORAGES = ("float64", "float32")

#: the contact arrays a float32 iteration stores narrow
NARROW_GEOMETRY = ("s", "normal", "tangent1", "tangent2", "radius_i", "radius_j", "lever")

#: where x, x_prev and x_new are among the three slots of x (and hx, hx_prev, h_new among those of
#: h = T x), from the control's SLOT r: r, r + 2 and r + 1 (mod 3). An accepted trial step moves r
#: on by one: x_new becomes x, x becomes x_prev, and the old x_prev's slot takes the next x_new, so
#: nothing is copied
X, X_PREV, X_NEW = 0, 2, 1


@cuda.jit(device=True)
def _slot(slots_0, slots_1, slots_2, control, role):
    """The slot that holds `role` (X, X_PREV or X_NEW) of the three."""
    index = (int(control[SLOT]) + role) % 3
    if index == 0:
        return slots_0
    if index == 1:
        return slots_1
    return slots_2


@cuda.jit
def _project_kernel(x_0, x_1, x_2, h_0, h_1, h_2, control, inv_mass, c, mu_s, mu_r_s, s, ci, cj, nrm, t1, t2, ri,
                    rj, lever, work, parts):
    """x_new = Proj_K(y - g / lip) at y = x + beta (x - x_prev), one contact a thread (x, x_prev and
    x_new from the three slots x_0, x_1, x_2, lip and beta from the control array), with the
    gradient g = S B Mbar^-1 hy + c at y taken here, in registers, from hy = hx + beta (hx - hx_prev)
    (hx and hx_prev from the slots h_0, h_1, h_2: :func:`colsim.engine.cuda_operator.gradient_values`,
    the CPU's arithmetic); its wrench from the force S x_new into work (m, 9) (the first half of
    T x_new: :func:`colsim.engine.cuda_operator.wrench_on_device`, s and the frames from the contact
    geometry); parts[0] and parts[1] (per block): ||x_new - y||^2 and g . (x_new - x)
    (colsim.engine.apgd_iteration._project_step). A backtrack takes the same gradient again (the same y,
    the same bits): that costs less than a kernel of its own after each accepted step, which
    wrote g for this one to read back."""
    moved = cuda.shared.array(THREADS, dtype=np.float64)
    uphill = cuda.shared.array(THREADS, dtype=np.float64)
    k = cuda.grid(1)
    t = cuda.threadIdx.x
    moved[t] = 0.0
    uphill[t] = 0.0
    if k < mu_s.shape[0]:
        x, x_prev = _slot(x_0, x_1, x_2, control, X), _slot(x_0, x_1, x_2, control, X_PREV)
        x_new = _slot(x_0, x_1, x_2, control, X_NEW)
        beta = control[BETA]
        step = 1.0 / control[LIP]
        g0, g1, g2, g3, g4 = gradient_values(k, _slot(h_0, h_1, h_2, control, X), _slot(h_0, h_1, h_2, control, X_PREV),
                                             beta, True, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever, c)
        o = 5 * k
        y0, y1, y2, y3, y4 = _extrapolated(x, x_prev, o, beta)
        p, q1, q2, r1, r2 = project_point_on_device(y0 - step * g0, y1 - step * g1, y2 - step * g2, y3 - step * g3,
                                                    y4 - step * g4, mu_s[k], mu_r_s[k])
        x_new[o], x_new[o + 1], x_new[o + 2], x_new[o + 3], x_new[o + 4] = p, q1, q2, r1, r2
        wrench_on_device(k, s[o] * p, s[o + 1] * q1, s[o + 2] * q2, s[o + 3] * r1, s[o + 4] * r2, nrm, t1, t2, ri,
                         rj, lever, work)
        moved[t] = ((p - y0) * (p - y0) + (q1 - y1) * (q1 - y1) + (q2 - y2) * (q2 - y2)
                    + (r1 - y3) * (r1 - y3) + (r2 - y4) * (r2 - y4))
        uphill[t] = (g0 * (p - x[o]) + g1 * (q1 - x[o + 1]) + g2 * (q2 - x[o + 2]) + g3 * (r1 - x[o + 3])
                     + g4 * (r2 - x[o + 4]))
    block_reduce(moved, t, False)
    block_reduce(uphill, t, False)
    if t == 0:
        parts[0, cuda.blockIdx.x] = moved[0]
        parts[1, cuda.blockIdx.x] = uphill[0]


@cuda.jit
def _transpose_change_kernel(work, start, entry, h_0, h_1, h_2, control, inv_mass, parts):
    """h_new (6n,) = T x_new from the wrenches in work (the second half of T x_new, one body a thread:
    :func:`colsim.engine.cuda_operator.body_sums_on_device`), and parts[2] (per block of bodies):
    ||h_new - hy||^2 weighted by inv_mass (colsim.engine.apgd_iteration._weighted_change), each body's three
    force entries, then its three moment entries; hx, hx_prev and h_new from the three slots of h,
    and hy = hx + beta (hx - hx_prev) made here, as the CPU's extrapolation makes it."""
    cache = cuda.shared.array(THREADS, dtype=np.float64)
    body = cuda.grid(1)
    t = cuda.threadIdx.x
    n = start.shape[0] - 1
    cache[t] = 0.0
    if body < n:
        hx, hx_prev = _slot(h_0, h_1, h_2, control, X), _slot(h_0, h_1, h_2, control, X_PREV)
        h_new = _slot(h_0, h_1, h_2, control, X_NEW)
        beta = control[BETA]
        body_sums_on_device(body, work, start, entry, h_new)
        change = 0.0
        for first in (3 * body, 3 * n + 3 * body):
            for i in range(first, first + 3):
                dh = h_new[i] - (hx[i] + beta * (hx[i] - hx_prev[i]))
                change += dh * dh * inv_mass[i]
        cache[t] = change
    block_reduce(cache, t, False)
    if t == 0:
        parts[2, cuda.blockIdx.x] = cache[0]


@cuda.jit
def _widen_kernel(x_0, x_1, x_2, control, out):
    """out (5m,) float64 = the iterate x, from the slot the control names (float32 storage)."""
    i = cuda.grid(1)
    if i < out.shape[0]:
        out[i] = _slot(x_0, x_1, x_2, control, X)[i]


_decide_on_device = cuda.jit(device=True)(getattr(decide, "py_func", decide))
#: the extrapolated point y = x + beta (x - x_prev) of one contact (the CPU's scalar code)
_extrapolated = cuda.jit(device=True)(getattr(extrapolated, "py_func", extrapolated))
#: one contact's parts of the residual check (the CPU's scalar code)
_contact_residuals = cuda.jit(device=True)(getattr(contact_residuals, "py_func", contact_residuals))


#: threads of the decision's one block, a power of two: they add the trial step's block sums (up to
#: 33,000 a row at 700,000 spheres) by a fixed assignment and tree, so the same bits every run
DECIDE_THREADS = 1024
#: the block for a row of at most this many sums (4,096 contacts and 682 spheres at most): the same
#: tree without the levels that add zeros, so the same bits as DECIDE_THREADS, and the simulator runs
#: 32 threads, not 1,024 (each a Python thread there)
FEW_DECIDE_THREADS = 32


@cuda.jit(device=True)
def _decide(parts, control, moved, uphill, change):
    """The decision's block: the trial step's sums (each row of parts, thread t adding blocks t,
    t + threads, ..., then a fixed tree in the shared arrays moved, uphill and change, one value a
    thread) and, in thread 0, APGD's decision (:func:`colsim.engine.apgd_iteration.decide`, the CPU's code)
    into the control array; an accepted step moves the slots' roles on (x_new becomes x)."""
    t = cuda.threadIdx.x
    dd = up = dh = 0.0
    for b in range(t, parts.shape[1], moved.shape[0]):   # entries past a kernel's blocks stay zero
        dd += parts[0, b]
        up += parts[1, b]
        dh += parts[2, b]
    moved[t] = dd
    uphill[t] = up
    change[t] = dh
    block_reduce(moved, t, False)
    block_reduce(uphill, t, False)
    block_reduce(change, t, False)
    if t != 0:
        return
    accepted, lip, theta, beta, restarted = _decide_on_device(moved[0], uphill[0], change[0], control[LIP],
                                                              control[THETA], control[BETA], control[LIP_DECAY])
    control[LIP], control[THETA], control[BETA] = lip, theta, beta
    if accepted:
        control[ACCEPTED] = 1.0
        control[SLOT] = (control[SLOT] + 1.0) % 3.0
        control[ITERATIONS] += 1.0
        if restarted:
            control[RESTARTS] += 1.0
    else:
        control[ACCEPTED] = 0.0
        control[BACKTRACKS] += 1.0


@cuda.jit
def _decide_kernel(parts, control):
    """:func:`_decide` in one block of DECIDE_THREADS threads. (One shared array a line: the simulator
    tells them apart by the line that makes them.)"""
    moved = cuda.shared.array(DECIDE_THREADS, dtype=np.float64)
    uphill = cuda.shared.array(DECIDE_THREADS, dtype=np.float64)
    change = cuda.shared.array(DECIDE_THREADS, dtype=np.float64)
    _decide(parts, control, moved, uphill, change)


@cuda.jit
def _decide_kernel_few(parts, control):
    """:func:`_decide` in one block of FEW_DECIDE_THREADS threads (a row of at most that many sums)."""
    moved = cuda.shared.array(FEW_DECIDE_THREADS, dtype=np.float64)
    uphill = cuda.shared.array(FEW_DECIDE_THREADS, dtype=np.float64)
    change = cuda.shared.array(FEW_DECIDE_THREADS, dtype=np.float64)
    _decide(parts, control, moved, uphill, change)


@cuda.jit
def _residual_kernel(control, h_0, h_1, h_2, x_0, x_1, x_2, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever, c, mu,
                     mu_r, parts):
    """parts[0..3] (per block): at the iterate x (the slot the control names now, and hx = T x its
    slot of h), the largest cone violation of the gaps y = g / s, g = S B Mbar^-1 hx + c (its rows
    in registers: :func:`colsim.engine.cuda_operator.gradient_values`, not extrapolated), and of the
    forces lam = s x, the sum of the positive normal forces and sum_k |lam_k . y_k|
    (colsim.engine.cones._residual_parts); one thread a contact."""
    primal = cuda.shared.array(THREADS, dtype=np.float64)
    dual = cuda.shared.array(THREADS, dtype=np.float64)
    total = cuda.shared.array(THREADS, dtype=np.float64)
    comp = cuda.shared.array(THREADS, dtype=np.float64)
    k = cuda.grid(1)
    t = cuda.threadIdx.x
    primal[t] = -math.inf
    dual[t] = -math.inf
    total[t] = 0.0
    comp[t] = 0.0
    if k < mu.shape[0]:
        hx = _slot(h_0, h_1, h_2, control, X)
        g0, g1, g2, g3, g4 = gradient_values(k, hx, hx, 0.0, False, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever,
                                             c)
        x = _slot(x_0, x_1, x_2, control, X)
        primal[t], dual[t], total[t], comp[t] = _contact_residuals(k, g0, g1, g2, g3, g4, x, s, mu, mu_r)
    four_block_results(parts, t, primal, dual, total, comp, True, True, False, False)


# -- an iteration on the device -----------------------------------------------------------------

def trial_step(x_slots, h_slots, control, c, geometry, mu_s, mu_r_s, inv_mass, parts):
    """The gradient at y, the projection, h_new = T x_new and the descent test's sums per block into
    parts (rows ||x_new - y||^2, g . (x_new - x), ||h_new - hy||^2_{Mbar^-1}); x_slots, h_slots: the
    three slots of x and of h = T x (:data:`X`); c: (5m,) the gradient's constant: two launches (one
    thread a contact, then one a body), nothing waits."""
    for kernel, blocks, threads, arguments in trial_launches(x_slots, h_slots, control, c, geometry, mu_s, mu_r_s,
                                                             inv_mass, parts):
        launch(kernel, blocks, threads, *arguments)


def trial_launches(x_slots, h_slots, control, c, geometry, mu_s, mu_r_s, inv_mass, parts):
    """:func:`trial_step`'s two launches, each (kernel, blocks, threads, arguments); narrower arrays
    (float32 storage, :data:`NARROW_GEOMETRY`; the benchmarks' int32 indices) take the kernels compiled
    anew for their types (:func:`colsim.engine.cuda_operator.for_types`: one signature a dispatcher, so
    that :func:`colsim.engine.cuda_launch.launch` keeps its fast way for each)."""
    geo = geometry
    types = (np.dtype(x_slots[0].dtype), np.dtype(geo.s.dtype), np.dtype(geo.i.dtype))
    project, transpose = _project_kernel, _transpose_change_kernel
    if types != (np.float64, np.float64, np.int64):
        project, transpose = for_types(project, *types), for_types(transpose, *types)
    return ((project, blocks_for(mu_s.shape[0]), THREADS,
             (*x_slots, *h_slots, control, inv_mass, c, mu_s, mu_r_s, geo.s, geo.i, geo.j, geo.normal, geo.tangent1,
              geo.tangent2, geo.radius_i, geo.radius_j, geo.lever, geo.work, parts)),
            (transpose, blocks_for(geo.start.shape[0] - 1), THREADS,
             (geo.work, geo.start, geo.entry, *h_slots, control, inv_mass, parts)))


@cuda.jit
def _scales_kernel(diag, precondition, mu, mu_r, s, mu_s, mu_r_s):
    """Contact k's row scales s (5m,) from diag (m, 5) = diag(B Mbar^-1 B') (1 where a row's is not
    positive; all 1 without `precondition`) and its scaled coefficients mu_s, mu_r_s
    (colsim.engine.cones.scales_of_diagonal, scaled_coefficients)."""
    k = cuda.grid(1)
    if k >= mu.shape[0]:
        return
    o = 5 * k
    normal, sliding, rolling = 1.0, 1.0, 1.0
    if precondition:
        normal, sliding, rolling = diag[k, 0], 0.5 * (diag[k, 1] + diag[k, 2]), 0.5 * (diag[k, 3] + diag[k, 4])
        normal = 1.0 / math.sqrt(normal if normal > 0 else 1.0)
        sliding = 1.0 / math.sqrt(sliding if sliding > 0 else 1.0)
        rolling = 1.0 / math.sqrt(rolling if rolling > 0 else 1.0)
    s[o], s[o + 1], s[o + 2], s[o + 3], s[o + 4] = normal, sliding, sliding, rolling, rolling
    mu_s[k] = mu[k] * normal / sliding
    mu_r_s[k] = mu_r[k] * normal / rolling


@cuda.jit
def _offset_kernel(c, gap, s):
    """c (5m,) = S (B u_free + gap e_n) from c = B u_free, in place (the CPU's order: gap, then S)."""
    k = cuda.grid(1)
    if k >= gap.shape[0]:
        return
    o = 5 * k
    c[o] = (c[o] + gap[k]) * s[o]
    for r in range(1, 5):
        c[o + r] *= s[o + r]


@cuda.jit
def _first_iterate_kernel(warm, s, mu_s, mu_r_s, x, nonzero):
    """x (5m,): the warm start's forces (m, 5) over S, projected onto the scaled cones (the CPU's
    project_compiled); nonzero[0] counts the contacts whose x is not zero (an atomic add)."""
    k = cuda.grid(1)
    if k >= mu_s.shape[0]:
        return
    o = 5 * k
    p, q1, q2, r1, r2 = project_point_on_device(warm[k, 0] / s[o], warm[k, 1] / s[o + 1], warm[k, 2] / s[o + 2],
                                                warm[k, 3] / s[o + 3], warm[k, 4] / s[o + 4], mu_s[k], mu_r_s[k])
    x[o], x[o + 1], x[o + 2], x[o + 3], x[o + 4] = p, q1, q2, r1, r2
    if p != 0.0 or q1 != 0.0 or q2 != 0.0 or r1 != 0.0 or r2 != 0.0:
        cuda.atomic.add(nonzero, 0, 1)


@cuda.jit
def _start_control_kernel(control, lip, lip_decay):
    """The control array of a new iteration: the Lipschitz estimate, theta 1, beta 0, lip's decay,
    slot 0 and no iterations yet (one thread)."""
    for index in range(control.shape[0]):
        control[index] = 0.0
    control[LIP], control[THETA], control[LIP_DECAY] = lip, 1.0, lip_decay


@cuda.jit
def _forces_kernel(s, x, forces):
    """forces (5m,) = S x."""
    i = cuda.grid(1)
    if i < x.shape[0]:
        forces[i] = s[i] * x[i]


#: :func:`colsim.engine.apgd_iteration.power_start`'s numbers on the device (all drawn so far)
_power_start_on_device = None


def _power_start_into(out) -> None:
    """out (size,) = power_start(size), copied on the device from its copy of all the numbers drawn
    so far: one copy from the host a longer draw, not one a solve (9 MB a solve at r0 = 6)."""
    global _power_start_on_device
    size = out.shape[0]
    if _power_start_on_device is None or _power_start_on_device.shape[0] < size:
        _power_start_on_device = cuda.to_device(power_start_drawn(size))
    out.copy_to_device(_power_start_on_device[:size])


def _to_device(array):
    """A float64 copy of a host array on the device; a device array as it is."""
    if hasattr(array, "copy_to_host"):
        return array
    return cuda.to_device(np.ascontiguousarray(array, dtype=float))


def _copy(device_array):
    """A copy of a device array, on the device."""
    out = cuda.device_array_like(device_array)
    out.copy_to_device(device_array)
    return out


class CudaIteration:
    """The APGD state on the device: the fields and methods of :class:`colsim.engine.apgd_iteration.CpuIteration`,
    as device arrays, from the same arguments (host or device arrays): the scaled problem (c (5m,),
    mu_s, mu_r_s (m,), inv_mass (6n,), the scaling (m, 5) or (5m,)) and the first iterate x (5m,);
    hx = T x and the Lipschitz estimate (the same power iteration,
    :func:`lipschitz_estimate`) are made on the device. operator: the program's CPU operator (its
    frames are copied) or their copy on the device; mu, mu_r: the program's coefficients, for the
    residual check; warm: whether x holds a force (None: look). :meth:`of_program` makes the scaled
    problem on the device too.

    The iteration's scalars (lip, theta, beta) and its decisions live on the device too (`control`,
    :func:`_decide`): a trial step is three launches that never wait for the host, and the
    host reads the control array once a round (:meth:`iterate`). x, x_prev and x_new are three slots
    that trade roles on the device (:data:`X`), and so are hx, hx_prev and h_new (y and hy = T y are
    made where they are read); `x`, `x_prev`, `x_new`, `hx` and `h_new` are the slots in those roles
    at the last read, `lip`, `theta`, `beta`, `backtracks` and `restarts` are the control array's
    now (a copy from the device when a trial step ran since the last read).

    storage: 'float64', or 'float32' (:data:`NARROW_GEOMETRY`): the trial steps then read and write
    float32 slots and contact arrays (`trial_geometry`), and `x` and `hx` are the float64 iterate and
    T x widened from the stored iterate (:meth:`_widen`), where a check, the forces and the increments
    read them."""

    def __init__(self, c, mu_s, mu_r_s, inv_mass, x, scaling, lip_decay, operator, mu, mu_r, warm=None,
                 storage: str = "float64"):
        if storage not in STORAGES:
            raise ValueError(f"APGD's storage on the GPU is {' or '.join(STORAGES)}, not {storage!r}")
        self.m = len(mu_s)
        device = operator if isinstance(operator, CudaContactOperator) else CudaContactOperator.from_operator(operator)
        self.geometry = device.geometry(_to_device(scaling).reshape(5 * self.m))
        self.warm = warm
        for name, array in (("c", c), ("mu_s", mu_s), ("mu_r_s", mu_r_s), ("inv_mass", inv_mass), ("mu", mu),
                            ("mu_r", mu_r)):
            setattr(self, name, _to_device(array))
        x = _to_device(x)
        hx = cuda.device_array(len(inv_mass), dtype=np.float64)
        transpose_on_device(self.geometry, x, hx)
        # the slots of x, x_new, x_prev (:data:`X` at SLOT 0) and of h = T x: x_prev = x, so y = x
        self.x_slots = (x, cuda.device_array_like(x), _copy(x))
        self.h_slots = (hx, cuda.device_array_like(hx), _copy(hx))
        lip = self._lipschitz_estimate()
        self.trial_geometry = self.geometry   # the contact arrays as a trial step reads them
        self._wide = None   # float32 storage: the float64 iterate and T x (:meth:`_widen`)
        self._wide_current = False   # ... made from the stored iterate since its last trial step
        # what the host reads: the control array, then the residual check's block sums (one copy a check)
        self.readout = cuda.device_array(CONTROL_SIZE + 4 * blocks_for(self.m), dtype=np.float64)
        self.control = self.readout[:CONTROL_SIZE]
        self.residual_parts = self.readout[CONTROL_SIZE:].reshape(4, blocks_for(self.m))
        launch(_start_control_kernel, 1, 1, self.control, lip, float(lip_decay))   # made there: no copy
        self._read = np.zeros(CONTROL_SIZE)   # the control array as last read: the slots' roles, the iterations
        self._read[[LIP, THETA, BETA, LIP_DECAY]] = lip, 1.0, 0.0, float(lip_decay)
        self._stale = False          # launched trial steps since that read
        self._readout = None         # the whole readout as last read with a residual check
        # the trial step's blocks' sums: its kernels write their own blocks, the rest stay zero
        self.parts = full_on_device((3, max(blocks_for(self.m), blocks_for(len(inv_mass) // 6))), 0.0)
        if storage == "float32":
            self.narrow_storage()   # prepares the trial step with the narrowed arrays
        else:
            self.prepare_trial()

    @classmethod
    def of_program(cls, program, warm_start, precondition: bool, lip_decay: float,
                   storage: str = "float64") -> "CudaIteration":
        """The iteration of :meth:`colsim.solvers.apgd.ApgdSolver.prepare` for a program with m > 0
        contacts, made on the device: the row scales from the device's diagonal of B Mbar^-1 B', the
        scaled coefficients, c = S (B Mbar^-1 fbar + gap e_n) and the first iterate (the warm start's
        (m, 5) forces projected onto the scaled cones, or zero) by the CPU's arithmetic, 1 / mass
        too; storage: 'float64' or 'float32' (:class:`CudaIteration`). A step on the GPU has every
        array there already: the contacts' (its detection's), the masses and free forces
        (:mod:`colsim.engine.cuda_state`), the warm start (its matching's) and a Coulomb fixed point's
        last forces; others are copied once."""
        m = program.m
        device = CudaContactOperator(program.contacts, program.n_unknowns // 6)   # no host operator
        # the masses and free forces: made on the device by a step there (cuda_state), else copied once
        fbar = program_array_on_device(program, "fbar")
        d_inv_mass = inverses_on_device(program_array_on_device(program, "mass"))
        shifted = program.gap_shift is not None   # a Coulomb fixed point's gaps are made on the host
        mu, mu_r, gap = contact_arrays_on_device(program if shifted else program.contacts, ("mu", "mu_r", "gap"))
        diagonal = device.diagonal_on_device(d_inv_mass)
        s = cuda.device_array(5 * m, dtype=np.float64)
        mu_s, mu_r_s = cuda.device_array(m, dtype=np.float64), cuda.device_array(m, dtype=np.float64)
        launch(_scales_kernel, blocks_for(m), THREADS, diagonal, bool(precondition), mu, mu_r, s, mu_s, mu_r_s)
        c = cuda.device_array(5 * m, dtype=np.float64)
        gradient_on_device(device.geometry(full_on_device(5 * m, 1.0)), fbar, d_inv_mass, full_on_device(5 * m, 0.0), c)
        launch(_offset_kernel, blocks_for(m), THREADS, c, gap, s)
        x = full_on_device(5 * m, 0.0)
        nonzero = full_on_device(1, 0, np.int64)
        if warm_start is not None and np.shape(warm_start) == (m, 5):
            kept = kept_device_copy(warm_start)   # a Coulomb fixed point's last forces, from the device
            warm = _to_device(warm_start if kept is None else kept)
            launch(_first_iterate_kernel, blocks_for(m), THREADS, warm, s, mu_s, mu_r_s, x, nonzero)
        return cls(c, mu_s, mu_r_s, d_inv_mass, x, s, lip_decay, device, mu, mu_r,
                   warm=bool(nonzero.copy_to_host()[0]), storage=storage)

    @classmethod
    def like(cls, start, operator, mu, mu_r) -> "CudaIteration":
        """The device's iteration from the same arguments as the CPU's `start` (an unstarted
        :class:`colsim.engine.apgd_iteration.CpuIteration`): both begin at the same point."""
        return cls(start.c, start.mu_s, start.mu_r_s, start.inv_mass, start.x, start.scaling, start.lip_decay,
                   operator, mu, mu_r)

    def narrow_storage(self, geometry: bool = True) -> None:
        """Store the trial steps' iterate, T x and wrenches in float32 from now on (float32 storage), and
        with `geometry` the contact arrays of :data:`NARROW_GEOMETRY` too (the benchmarks time the
        share of each); made from the float64 slots on the device, which are kept as the float64 iterate
        and T x that :meth:`_widen` makes anew from the stored one."""
        geo = self.geometry
        narrowed = {name: cast_on_device(getattr(geo, name), np.float32) for name in NARROW_GEOMETRY} if geometry else {}
        self.trial_geometry = geo._replace(work=cuda.device_array(geo.work.shape, dtype=np.float32), **narrowed)
        x, hx = cast_on_device(self.x_slots[0], np.float32), cast_on_device(self.h_slots[0], np.float32)
        self._wide = (self.x_slots[0], self.h_slots[0])   # the float64 start, not yet its float32 rounding
        self._wide_current = False
        self.x_slots = (x, cuda.device_array_like(x), _copy(x))
        self.h_slots = (hx, cuda.device_array_like(hx), _copy(hx))
        self.prepare_trial()

    def _widen(self):
        """Float32 storage: the float64 iterate and its T x (the float64 contact arrays' B' S x), made on
        the device from the slot the control names there now (no wait); returns them."""
        x, hx = self._wide
        if not self._wide_current:
            launch(_widen_kernel, blocks_for(5 * self.m), THREADS, *self.x_slots, self.control, x)
            transpose_on_device(self.geometry, x, hx)
            self._wide_current = True
        return x, hx

    def _lipschitz_estimate(self) -> float:
        """:func:`colsim.engine.apgd_iteration.lipschitz_estimate` with the device's kernels: G T v into one of
        two buffers, so that v and G T v never share one; the norms stay on the device, so the one
        copy to the host is the last product's."""
        zero = full_on_device(5 * self.m, 0.0)
        h = cuda.device_array_like(self.h_slots[0])
        buffers = [cuda.device_array_like(self.x_slots[0]), cuda.device_array_like(self.x_slots[0])]

        def apply_GT(v):
            out = buffers[1] if v is buffers[0] else buffers[0]
            transpose_on_device(self.geometry, v, h)
            gradient_on_device(self.geometry, h, self.inv_mass, zero, out)
            return out

        partial = cuda.device_array(blocks_for(5 * self.m), dtype=np.float64)   # the products' block sums
        square = cuda.device_array(1, dtype=np.float64)
        _power_start_into(buffers[0])
        return lipschitz_estimate(buffers[0], apply_GT, lambda u, v: dot(u, v, partial),
                                  lambda v: normalise_on_device(v, partial, square))

    def iterate(self, n: int, check: bool = False):
        """n more APGD iterations (accepted trial steps), in APGD's one loop
        (:func:`colsim.engine.apgd_iteration.run_iterations`) of :meth:`trial_round`s."""
        run_iterations(self, n, check)

    def trial_round(self, trials: int, check: bool = False):
        """`trials` trial steps launched without waiting, then one read of the control array. check:
        the round also launches the residual check at the iterate it reaches, read in the same copy,
        so that :meth:`iterate_and_check` waits for the host once a check (a round short of its
        iterations wastes its check: a backtrack in its last trial step)."""
        for _ in range(trials):
            self._trial()
        if check:
            self._launch_check()
        self._read_back(check)

    def iterate_and_check(self, n: int, program, scale: float, floor: float) -> dict[str, float]:
        """:meth:`iterate` n, then :meth:`residuals` there (with the coefficients already on the device,
        not `program`'s host ones): one copy from the device a round."""
        self.iterate(n, check=True)
        return self._residuals_read(scale, floor)

    def _launch_check(self) -> None:
        """The residual check's kernel at the iterate the control names (no wait)."""
        geo = self.geometry
        x_slots, h_slots = self.x_slots, self.h_slots
        if self._wide is not None:   # float32 storage: checked at the iterate widened, in float64
            x, hx = self._widen()
            x_slots, h_slots = (x, x, x), (hx, hx, hx)
        launch(_residual_kernel, blocks_for(self.m), THREADS, self.control, *h_slots, *x_slots, self.inv_mass,
               geo.s, geo.i, geo.j, geo.normal, geo.tangent1, geo.tangent2, geo.radius_i, geo.radius_j, geo.lever,
               self.c, self.mu, self.mu_r, self.residual_parts)

    def _read_back(self, check: bool) -> None:
        """Copy the control array (and with `check` the residual check's sums, in the same copy)."""
        if check:
            self._readout = self.readout.copy_to_host()
            self._read = self._readout[:CONTROL_SIZE].copy()
        else:
            self._read = self.control.copy_to_host()
        self._stale = False

    def _residuals_read(self, scale: float, floor: float) -> dict[str, float]:
        """The relative residuals from the check's block sums of the last read."""
        parts = self._readout[CONTROL_SIZE:].reshape(4, -1)
        return combine_residuals(max(0.0, float(parts[0].max())), max(0.0, float(parts[1].max())),
                                 float(parts[2].sum()), float(parts[3].sum()), self.m, scale, floor)

    def _trial(self):
        """One trial step (with its gradient at y) and its decision: three launches, each
        with the same arguments every time (prepared once: :class:`colsim.engine.cuda_launch.Prepared`)."""
        for prepared in self._trial_launches:
            prepared()
        self._stale = True
        self._wide_current = False

    def prepare_trial(self) -> None:
        """Prepare the trial step's launches (:meth:`_trial`) with the slots and the trial steps'
        contact arrays as they are now (again after :meth:`narrow_storage`, or the benchmarks' changes)."""
        self._trial_launches = [Prepared(kernel, blocks, threads, *arguments)
                                for kernel, blocks, threads, arguments in self._launches_of_a_trial()]

    def _launches_of_a_trial(self) -> list:
        """The trial step's two launches and its decision's: each (kernel, blocks, threads, arguments)."""
        decide = ((_decide_kernel_few, 1, FEW_DECIDE_THREADS) if self.parts.shape[1] <= FEW_DECIDE_THREADS
                  else (_decide_kernel, 1, DECIDE_THREADS))
        return [*trial_launches(self.x_slots, self.h_slots, self.control, self.c, self.trial_geometry, self.mu_s,
                                self.mu_r_s, self.inv_mass, self.parts),
                (*decide, (self.parts, self.control))]

    def _role(self, slots, role: int):
        """The slot of `slots` that holds `role` (:data:`X`), as of the control array's last read."""
        return slots[(int(self._read[SLOT]) + role) % 3]

    x = property(lambda self: self._role(self.x_slots, X) if self._wide is None else self._widen()[0],
                 doc="(5m,) device array: the iterate z (as of the control array's last read; float64, widened "
                     "now, under float32 storage).")
    x_prev = property(lambda self: self._role(self.x_slots, X_PREV), doc="(5m,) device array: the iterate before it.")
    x_new = property(lambda self: self._role(self.x_slots, X_NEW), doc="(5m,) device array: the last trial point.")
    hx = property(lambda self: self._role(self.h_slots, X) if self._wide is None else self._widen()[1],
                  doc="(6n,) device array: T x (as x).")
    h_new = property(lambda self: self._role(self.h_slots, X_NEW), doc="(6n,) device array: T x_new.")

    def _scalar(self, index: int) -> float:
        """One of the control array's entries now: read from the device only if a trial step ran since
        the last read (after :meth:`iterate`, whose rounds end on a read, a solve's lip, backtracks and
        restarts cost no copy; they cost three before)."""
        if self._stale:
            self._read = self.control.copy_to_host()
            self._stale = False
        return float(self._read[index])

    lip = property(lambda self: self._scalar(LIP), doc="The Lipschitz estimate now (read from the device).")
    theta = property(lambda self: self._scalar(THETA), doc="Nesterov's theta now.")
    beta = property(lambda self: self._scalar(BETA), doc="Nesterov's beta now.")
    iterations = property(lambda self: int(self._scalar(ITERATIONS)), doc="Iterations (accepted trial steps) so far.")
    backtracks = property(lambda self: int(self._scalar(BACKTRACKS)), doc="Backtracks so far.")
    restarts = property(lambda self: int(self._scalar(RESTARTS)), doc="Restarts so far.")

    def residuals(self, mu, mu_r, scale: float, floor: float) -> dict[str, float]:
        """The relative residuals at the iterate (colsim.engine.cones.relative_residuals), on the
        device; mu, mu_r: the program's (those given at construction are used)."""
        self._launch_check()
        self._read_back(True)
        return self._residuals_read(scale, floor)

    def host_x(self) -> np.ndarray:
        """(5m,) the scaled iterate z on the host."""
        return self.x.copy_to_host()

    def is_warm(self) -> bool:
        """Does the first iterate hold a force (a warm start)? Asked before iterating."""
        return bool(np.any(self.host_x())) if self.warm is None else self.warm

    def increments(self, program):
        """(6n,) device array u = Mbar^-1 (fbar + B' lam) at the iterate, made on the device from
        B' lam = B' S z, the device's hx (the step's update takes it there:
        :func:`colsim.engine.cuda_state.advance_on_device`)."""
        return increments_on_device(program, self.hx)

    def forces(self) -> np.ndarray:
        """(m, 5) the contact forces S z of the iterate, on the host; their device copy is kept
        (:func:`colsim.engine.cuda_operator.keep_device_copy`) for the warm start the step leaves."""
        return host_copy(self.forces_on_device(), read_only=False)

    def forces_on_device(self):
        """(m, 5) the contact forces S z of the iterate, a device array."""
        out = cuda.device_array(5 * self.m, dtype=np.float64)
        launch(_forces_kernel, blocks_for(5 * self.m), THREADS, self.geometry.s, self.x, out)
        return out.reshape(self.m, 5)

    def solution(self, program, iterations: int, setup_time: float, solve_time: float, info: dict) -> "DeviceSolution":
        """The solved program's solution at the iterate, its forces left on the device (times in seconds)."""
        return DeviceSolution(self.increments(program), self.forces_on_device(), "Solved", iterations, setup_time,
                              solve_time, info)


class DeviceSolution(ConeSolution):
    """A :class:`colsim.engine.solver_contract.ConeSolution` whose increments (`increments_on_device`,
    (6n,)) and forces (`on_device`, (m, 5)) stay on the device until read: the host's `increments`
    and `forces` are copied from there when first read (a file, a packing's rest test, a solver on
    the CPU), and keep the device's as their copy. A step on the GPU reads neither: its update takes
    the device's increments (:meth:`resident_increments`), its warm start and a Coulomb fixed point's next
    solve the device's forces (:meth:`resident_forces`), and its count of active contacts is made there
    (:meth:`active_contacts`). m > 0."""

    def __init__(self, increments, on_device, status, iterations, setup_time, solve_time, info=None, backend=""):
        self.increments_on_device, self.on_device, self.status = increments, on_device, status
        self.iterations, self.setup_time, self.solve_time = iterations, setup_time, solve_time
        self.info, self.backend = info or {}, backend

    def __getattr__(self, name):   # only for an attribute not set: a host copy not yet made
        if name == "forces":
            self.forces = host_copy(self.__dict__["on_device"], read_only=False)
            return self.forces
        if name == "increments":
            self.increments = host_copy(self.__dict__["increments_on_device"])
            return self.increments
        raise AttributeError(name)

    def resident_forces(self):
        return self.on_device

    def resident_increments(self):
        return self.increments_on_device

    def active_contacts(self) -> int:
        """:meth:`colsim.engine.solver_contract.ConeSolution.active_contacts`, counted on the device
        (the largest normal force, the threshold and the count there, in the host's arithmetic: the
        same count); only the count comes back."""
        m = self.on_device.shape[0]
        largest = cuda.device_array(blocks_for(m), dtype=np.float64)
        launch(_largest_normal_kernel, blocks_for(m), THREADS, self.on_device, largest)
        threshold = cuda.device_array(1, dtype=np.float64)
        launch(_threshold_kernel, 1, THREADS, largest, threshold)
        count = full_on_device(1, 0, np.int64)
        launch(_count_above_kernel, blocks_for(m), THREADS, self.on_device, threshold, count)
        return int(count.copy_to_host()[0])


@cuda.jit
def _largest_normal_kernel(forces, largest):
    """largest[b] = the largest normal force p = forces[k, 0] of block b's contacts."""
    cache = cuda.shared.array(THREADS, dtype=np.float64)
    k = cuda.grid(1)
    t = cuda.threadIdx.x
    cache[t] = forces[k, 0] if k < forces.shape[0] else -math.inf
    block_reduce(cache, t, True)
    if t == 0:
        largest[cuda.blockIdx.x] = cache[0]


@cuda.jit
def _threshold_kernel(largest, threshold):
    """threshold[0] = ACTIVE_FRACTION max(largest normal force, 0), from the blocks' largest (one block)."""
    cache = cuda.shared.array(THREADS, dtype=np.float64)
    t = cuda.threadIdx.x
    value = -math.inf
    for b in range(t, largest.shape[0], THREADS):
        value = max(value, largest[b])
    cache[t] = value
    block_reduce(cache, t, True)
    if t == 0:
        threshold[0] = ACTIVE_FRACTION * max(cache[0], 0.0)


@cuda.jit
def _count_above_kernel(forces, threshold, count):
    """count[0] += the contacts whose normal force exceeds threshold[0] (an atomic add each)."""
    k = cuda.grid(1)
    if k < forces.shape[0] and forces[k, 0] > threshold[0]:
        cuda.atomic.add(count, 0, 1)
