"""The contact operator on one GPU: B u, B' S z and diag(B Mbar^-1 B') as
numba.cuda kernels, the arithmetic of :mod:`colsim.engine.operator` line for line, and dot products
summed in a fixed order.

- B u: one thread a contact (:func:`_gradient_kernel`).
- B' S z: one thread a contact for its wrench (force on the second body, moments on both), then one
  thread a body that sums its contacts' wrenches in contact order (:func:`_transpose_kernel`, from
  the same start/entry lists as the CPU kernel). No atomic add: the sums are the CPU's, bit for bit,
  and the same every run.
- diag(B Mbar^-1 B'): one thread a contact.
- a . b: each block sums its slice in shared memory by a fixed tree, then the host adds the blocks'
  sums in block order (:func:`dot`): the same bits every run on one device, for one block size.

Without a GPU the kernels run on numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1), which is how the
tests check them against the CPU kernels (tests/cuda_simulator.py sets the simulator up for that). APGD's iterations on the GPU use them
(:mod:`colsim.engine.cuda_apgd`); detection and the warm start follow (docs/performance.md, "One H100/H200").
"""
from __future__ import annotations

import math
import os
import weakref

import numpy as np

if not hasattr(np, "row_stack"):   # numba-cuda 0.30.4 calls np.row_stack, which numpy 2.5 removed
    np.row_stack = np.vstack       # (the same function; numpy 2.4, this project's lock, still has it)

from numba import config as numba_config  # noqa: E402
from numba import cuda  # noqa: E402 (after the alias)

from .cones import project_point
from .cuda_launch import launch
from .operator import ContactGeometry, body_sums, contact_wrench, diagonal_row, gradient_values

#: numba-cuda warns of every grid under 128 blocks ("will likely result in GPU under-utilization"),
#: once for each size. colsim's one-block launches (a decision, a scan) are small by design, and its
#: small columns' contacts fill fewer blocks: an r0 = 6 pour's log held hundreds of them. Off unless the environment sets NUMBA_CUDA_LOW_OCCUPANCY_WARNINGS
#: (set here too, so that numba's reload of its configuration keeps it).
LOW_OCCUPANCY_WARNINGS = "NUMBA_CUDA_LOW_OCCUPANCY_WARNINGS"
if LOW_OCCUPANCY_WARNINGS not in os.environ:
    os.environ[LOW_OCCUPANCY_WARNINGS] = "0"
    numba_config.CUDA_LOW_OCCUPANCY_WARNINGS = 0

#: threads a block; a power of two (the dot product's tree halves it). 32 on numba's simulator, which
#: runs each thread as a Python thread and polls a block's threads at every sync: the same kernels, 2.4x
#: faster there, and more of the tests' small launches span several blocks (their sums across blocks)
THREADS = 32 if numba_config.ENABLE_CUDASIM else 128


#: one thread's projection onto a contact's coupled cone (the CPU's scalar code, compiled for the GPU)
project_point_on_device = cuda.jit(device=True)(getattr(project_point, "py_func", project_point))


def blocks_for(count: int) -> int:
    """Blocks of THREADS threads for one thread an item."""
    return max(1, math.ceil(count / THREADS))


#: device copies of host arrays that never change once made, by the host array's identity
#: (:func:`device_copy_of`)
_device_copies: dict = {}

#: the contacts' frames: each goes to the device on its own, one copy that the operator and the warm
#: start share (:func:`contact_arrays_on_device`)
SHARED_FRAMES = ("normal", "tangent1", "tangent2")


def device_copy_of(array: np.ndarray):
    """The device's copy of a host array that is not changed after it is made (a step's contact
    frames, its contacts' pair keys, the solver's forces), made at the first call for that array
    (or given by :func:`keep_device_copy`) and shared by the later ones: the warm start's matching,
    the solver's operator and the next step's matching take the same copy, one copy from the host
    at most. The copy goes when the host array does."""
    copy = _device_copies.get(id(array))
    if copy is None:
        copy = cuda.to_device(np.ascontiguousarray(array))
        keep_device_copy(array, copy)
    return copy


def kept_device_copy(array: np.ndarray):
    """The device copy of `array` that :func:`device_copy_of` would give, if one is kept (else None)."""
    return _device_copies.get(id(array))


def keep_device_copy(array: np.ndarray, copy) -> None:
    """Make `copy`, a device array that holds the same numbers as the host array `array`, the one
    :func:`device_copy_of` gives for it (arrays made on the device and copied back: no copy there)."""
    key = id(array)
    _device_copies[key] = copy
    weakref.finalize(array, _device_copies.pop, key, None)


def contact_arrays_on_device(contacts, names, dtype=np.float64) -> list:
    """The device copies of the arrays `names` of `contacts` (anything that has them by name: a
    Contacts, a ConeProgram, a ContactOperator): the ones made there where it holds them (a GPU
    detection's, :class:`colsim.engine.cuda_contacts.DeviceContacts`), else those kept for its host
    arrays (:func:`kept_device_copy`), else its host arrays in one copy (dtype; one array: its own,
    :func:`device_copy_of`), each kept for its array."""
    made = getattr(contacts, "device", None)
    if made is not None and all(name in made for name in names):
        return [made[name] for name in names]
    host = [getattr(contacts, name) for name in names]
    if len(host) == 1:   # its own copy, of its own dtype
        return [device_copy_of(host[0])]
    kept = [kept_device_copy(array) for array in host]
    if all(copy is not None for copy in kept):
        return kept
    rows = np.stack(host).astype(dtype, copy=False)
    m = rows.shape[1]
    if not m:   # a card cannot index an array of no bytes (it has no pointer): empty views of one row
        rows = np.zeros((len(host), 1) + rows.shape[2:], dtype=dtype)
    stacked = cuda.to_device(rows)
    copies = [stacked[k][:m] for k in range(len(host))]
    for array, copy in zip(host, copies):
        keep_device_copy(array, copy)
    return copies


@cuda.jit
def _gradient_kernel(h, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever, c, out):
    """out (5m,) = S B Mbar^-1 h + c: contact k's relative motion (colsim.engine.operator.apply_gradient)."""
    k = cuda.grid(1)
    if k < ci.shape[0]:
        gradient_row(k, h, h, 0.0, False, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever, c, out)


@cuda.jit(device=True)
def gradient_row(k, h, h_prev, beta, extrapolate, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever, c, out):
    """out[5k:5k + 5] = contact k's rows of S B Mbar^-1 h + c (of h + beta (h - h_prev) where `extrapolate`)."""
    o = 5 * k
    out[o], out[o + 1], out[o + 2], out[o + 3], out[o + 4] = gradient_values(
        k, h, h_prev, beta, extrapolate, inv_mass, s, ci, cj, nrm, t1, t2, ri, rj, lever, c)


#: contact k's five rows of S B Mbar^-1 h + c (the CPU's scalar code, compiled for the GPU)
gradient_values = cuda.jit(device=True)(getattr(gradient_values, "py_func", gradient_values))
#: contact k's wrench from its force (the CPU's scalar code, compiled for the GPU)
wrench_on_device = cuda.jit(device=True)(getattr(contact_wrench, "py_func", contact_wrench))


@cuda.jit
def _wrench_kernel(z, s, nrm, t1, t2, ri, rj, lever, work):
    """work (m, 9): each contact's wrench (:func:`wrench_on_device`) from its force S z."""
    k = cuda.grid(1)
    if k >= ri.shape[0]:
        return
    o = 5 * k
    wrench_on_device(k, s[o] * z[o], s[o + 1] * z[o + 1], s[o + 2] * z[o + 2], s[o + 3] * z[o + 3],
                     s[o + 4] * z[o + 4], nrm, t1, t2, ri, rj, lever, work)


#: one body's sums of its contacts' wrenches (the CPU's scalar code, compiled for the GPU)
body_sums_on_device = cuda.jit(device=True)(getattr(body_sums, "py_func", body_sums))


@cuda.jit
def _transpose_kernel(work, start, entry, out):
    """out (6n,) = B' S z from the contacts' wrenches, one body a thread (:func:`body_sums_on_device`)."""
    body = cuda.grid(1)
    if body < start.shape[0] - 1:
        body_sums_on_device(body, work, start, entry, out)


#: one contact's rows of the diagonal of B Mbar^-1 B' (the CPU's scalar code, compiled for the GPU)
_diagonal_row = cuda.jit(device=True)(getattr(diagonal_row, "py_func", diagonal_row))


@cuda.jit
def _diagonal_kernel(inv_mass, ci, cj, nrm, t1, t2, ri, rj, lever, out):
    """out (m, 5) = the diagonal of B Mbar^-1 B' (colsim.engine.operator.jacobian_diagonal), a contact a thread."""
    k = cuda.grid(1)
    if k < ci.shape[0]:
        _diagonal_row(k, inv_mass, ci, cj, nrm, t1, t2, ri, rj, lever, out)


@cuda.jit
def _fill_kernel(flat, value):
    """flat[i] = value, one entry a thread."""
    i = cuda.grid(1)
    if i < flat.shape[0]:
        flat[i] = value


#: kernels compiled anew for each set of types they are launched with, by (kernel, types): one signature
#: a dispatcher, so that :func:`launch` takes its fast way (a dispatcher of several launches the plain
#: way, which costs more a launch)
_by_types: dict = {}


def for_types(kernel, *types):
    """`kernel`'s code as a dispatcher of its own for the argument types named by `types` (any hashable)."""
    key = (kernel, *types)
    if key not in _by_types:
        _by_types[key] = cuda.jit(kernel.py_func)
    return _by_types[key]


def full_on_device(shape, value, dtype=np.float64):
    """A device array of `shape` and `dtype` filled with `value`, made there: no host array and no copy
    from the host (which a step's set-up paid for each of its zero arrays, up to tens of MB at
    700,000 spheres)."""
    out = cuda.device_array(shape, dtype=dtype)
    if out.size:
        kind = np.dtype(dtype)
        launch(for_types(_fill_kernel, kind), blocks_for(out.size), THREADS, out.reshape(out.size), kind.type(value))
    return out


@cuda.jit
def _cast_kernel(source, target):
    """target[k] = source[k] in target's type (the nearest float32, an int32's same value), a thread each."""
    k = cuda.grid(1)
    if k < source.shape[0]:
        target[k] = source[k]


def cast_on_device(array, dtype):
    """A new C-contiguous device array of `array`'s shape in numpy type `dtype`, its values cast there."""
    out = cuda.device_array(array.shape, dtype=dtype)
    if array.size:
        kernel = for_types(_cast_kernel, np.dtype(array.dtype), np.dtype(dtype))
        launch(kernel, blocks_for(array.size), THREADS, array.reshape(array.size), out.reshape(array.size))
    return out


@cuda.jit(device=True)
def block_reduce(cache, t, largest):
    """Reduce a block's shared array `cache` (one value a thread, thread t's at cache[t]; its length
    the block's threads, a power of two) into cache[0] by a fixed tree: the sum, or the largest value
    where `largest`. Every thread of the block calls it."""
    cuda.syncthreads()
    half = cache.shape[0] // 2
    while half > 0:
        if t < half:
            cache[t] = max(cache[t], cache[t + half]) if largest else cache[t] + cache[t + half]
        cuda.syncthreads()
        half //= 2


@cuda.jit(device=True)
def four_block_results(parts, t, first, second, third, fourth, largest_1, largest_2, largest_3, largest_4):
    """Reduce a block's four shared arrays (:func:`block_reduce`: the largest where largest_r, else the
    sum) and write their results to parts[0..3, block] (thread 0). Every thread of the block calls it."""
    block_reduce(first, t, largest_1)
    block_reduce(second, t, largest_2)
    block_reduce(third, t, largest_3)
    block_reduce(fourth, t, largest_4)
    if t == 0:
        b = cuda.blockIdx.x
        parts[0, b], parts[1, b], parts[2, b], parts[3, b] = first[0], second[0], third[0], fourth[0]


@cuda.jit
def _block_dot_kernel(u, v, partial):
    """partial[block] = sum of u[i] v[i] over the block's slice, by a fixed tree in shared memory."""
    cache = cuda.shared.array(THREADS, dtype=np.float64)
    i = cuda.grid(1)
    t = cuda.threadIdx.x
    cache[t] = u[i] * v[i] if i < u.shape[0] else 0.0
    block_reduce(cache, t, False)
    if t == 0:
        partial[cuda.blockIdx.x] = cache[0]


@cuda.jit
def _sum_blocks_kernel(partial, out):
    """out[0] = the sum of partial's entries (blocks' sums) in one block of THREADS threads: thread t
    adds entries t, t + THREADS, ..., then a fixed tree."""
    cache = cuda.shared.array(THREADS, dtype=np.float64)
    t = cuda.threadIdx.x
    total = 0.0
    for b in range(t, partial.shape[0], THREADS):
        total += partial[b]
    cache[t] = total
    block_reduce(cache, t, False)
    if t == 0:
        out[0] = cache[0]


@cuda.jit
def _divide_by_root_kernel(v, square):
    """v /= sqrt(square[0]), one entry a thread."""
    i = cuda.grid(1)
    if i < v.shape[0]:
        v[i] /= math.sqrt(square[0])


def normalise_on_device(v, partial, square) -> None:
    """v /= ||v|| on the device, the norm summed in a fixed order (the same bits every run), with no
    copy to the host: partial (blocks_for(len(v)),) and square (1,) are device arrays it writes."""
    launch(_block_dot_kernel, blocks_for(v.shape[0]), THREADS, v, v, partial)
    launch(_sum_blocks_kernel, 1, THREADS, partial, square)
    launch(_divide_by_root_kernel, blocks_for(v.shape[0]), THREADS, v, square)


def dot(u, v, partial=None) -> float:
    """u . v of two device (or host) vectors: the blocks' sums (fixed trees), added on the host in
    block order, so the result is the same every run. partial: a device array of the blocks' count
    for those sums, kept by a caller that takes many products of one length (None: a new one)."""
    blocks = blocks_for(u.shape[0])
    if partial is None:
        partial = cuda.device_array(blocks, dtype=np.float64)
    launch(_block_dot_kernel, blocks, THREADS, u, v, partial)
    return float(np.sum(partial.copy_to_host()))


def gradient_on_device(geometry: ContactGeometry, h, inv_mass, c, out) -> None:
    """out (5m,) = S B Mbar^-1 h + c, every array on the device (colsim.engine.operator.gradient_of)."""
    g = geometry
    if g.i.shape[0]:
        launch(_gradient_kernel, blocks_for(g.i.shape[0]), THREADS, h, inv_mass, g.s, g.i, g.j, g.normal,
               g.tangent1, g.tangent2, g.radius_i, g.radius_j, g.lever, c, out)


def transpose_on_device(geometry: ContactGeometry, z, out) -> None:
    """out (6n,) = B' S z, every array on the device (colsim.engine.operator.transpose_of)."""
    g = geometry
    if g.i.shape[0]:
        launch(_wrench_kernel, blocks_for(g.i.shape[0]), THREADS, z, g.s, g.normal, g.tangent1, g.tangent2,
               g.radius_i, g.radius_j, g.lever, g.work)
    launch(_transpose_kernel, blocks_for(g.start.shape[0] - 1), THREADS, g.work, g.start, g.entry, out)


@cuda.jit
def _count_entries_kernel(i, j, count):
    """count[b] += 1 for each contact entry on body b (its first body i, its second j where j >= 0)."""
    k = cuda.grid(1)
    if k < i.shape[0]:
        cuda.atomic.add(count, i[k], 1)
        if j[k] >= 0:
            cuda.atomic.add(count, j[k], 1)


@cuda.jit
def _block_totals_kernel(count, totals):
    """totals[block] = the sum of count over the block's slice."""
    cache = cuda.shared.array(THREADS, dtype=np.int64)
    b = cuda.grid(1)
    t = cuda.threadIdx.x
    cache[t] = count[b] if b < count.shape[0] else 0
    block_reduce(cache, t, False)
    if t == 0:
        totals[cuda.blockIdx.x] = cache[0]


@cuda.jit(device=True)
def _block_inclusive_scan(cache, t):
    """cache (THREADS,) in shared memory -> its inclusive running sums (Hillis and Steele); every
    thread of the block calls it, thread t with its own value at cache[t]."""
    cuda.syncthreads()
    step = 1
    while step < THREADS:
        before = cache[t - step] if t >= step else 0
        cuda.syncthreads()
        cache[t] += before
        cuda.syncthreads()
        step *= 2


@cuda.jit
def _exclusive_scan_kernel(totals):
    """totals -> their exclusive running sums, in place, by one block: thread t sums its stretch of
    totals, the block scans those sums, then each thread writes its stretch's running sums."""
    cache = cuda.shared.array(THREADS, dtype=np.int64)
    t = cuda.threadIdx.x
    stretch = (totals.shape[0] + THREADS - 1) // THREADS
    first, last = t * stretch, min((t + 1) * stretch, totals.shape[0])
    total = 0
    for b in range(first, last):
        total += totals[b]
    cache[t] = total
    _block_inclusive_scan(cache, t)
    running = cache[t] - total
    for b in range(first, last):
        here = totals[b]
        totals[b] = running
        running += here


@cuda.jit
def _starts_kernel(count, offsets, start):
    """start[b + 1] = count[0] + ... + count[b]: the block's offset plus a scan of its slice in shared
    memory (Hillis and Steele); start[0] = 0."""
    cache = cuda.shared.array(THREADS, dtype=np.int64)
    b = cuda.grid(1)
    t = cuda.threadIdx.x
    cache[t] = count[b] if b < count.shape[0] else 0
    _block_inclusive_scan(cache, t)
    if b < count.shape[0]:
        start[b + 1] = offsets[cuda.blockIdx.x] + cache[t]
    if b == 0:
        start[0] = 0


@cuda.jit
def _place_entries_kernel(i, j, start, filled, entry):
    """Each contact's entries (2 k on its first body, 2 k + 1 on its second) into a free place of
    their body's range of entry, in the order the atomic additions come (sorted next)."""
    k = cuda.grid(1)
    if k < i.shape[0]:
        entry[start[i[k]] + cuda.atomic.add(filled, i[k], 1)] = 2 * k
        if j[k] >= 0:
            entry[start[j[k]] + cuda.atomic.add(filled, j[k], 1)] = 2 * k + 1


@cuda.jit(device=True)
def sort_range_on_device(values, first, end):
    """values[first:end] in increasing order, in place, by one thread: an insertion sort (for the few
    tens of entries of one body's contacts or one particle's partners)."""
    for k in range(first + 1, end):
        value = values[k]
        f = k - 1
        while f >= first and values[f] > value:
            values[f + 1] = values[f]
            f -= 1
        values[f + 1] = value


@cuda.jit
def _sort_bodies_kernel(start, entry):
    """Each body's entries in increasing order (contact order), one body a thread."""
    b = cuda.grid(1)
    if b < start.shape[0] - 1:
        sort_range_on_device(entry, start[b], start[b + 1])


def prefix_sums_on_device(count):
    """(len(count) + 1,) int64 device array: 0 and the running sums of `count` ((n,) int64, on the
    device), made there: each block's total, their exclusive sums by one block, then each block's
    scan in shared memory. Integer sums, so exact and the same in any order."""
    n = count.shape[0]
    start = full_on_device(n + 1, 0, np.int64)
    if n:
        offsets = cuda.device_array(blocks_for(n), dtype=np.int64)
        launch(_block_totals_kernel, blocks_for(n), THREADS, count, offsets)
        launch(_exclusive_scan_kernel, 1, THREADS, offsets)
        launch(_starts_kernel, blocks_for(n), THREADS, count, offsets, start)
    return start


def body_contacts_on_device(i, j, n: int, entries: int):
    """:func:`colsim.engine.operator.body_contacts` made on the device, for contacts' (m,) int64 device
    arrays i and j (j < 0: no second body) among n bodies with `entries` entries in all (m plus the
    contacts with j >= 0): (start (n + 1,), entry (entries,)) as int64 device arrays. A counting
    sort: each body's entries counted (atomic additions), the starts from their prefix sums
    (:func:`prefix_sums_on_device`), the entries placed, then each body's sorted into contact order.
    Integer sums are exact and the sort fixes the order, so the lists are the CPU's whatever order
    the atomic operations take."""
    m = i.shape[0]
    entry = cuda.device_array(max(entries, 1), dtype=np.int64)[:entries]
    if m == 0 or n == 0:
        return full_on_device(n + 1, 0, np.int64), entry
    count = full_on_device(n, 0, np.int64)
    launch(_count_entries_kernel, blocks_for(m), THREADS, i, j, count)
    start = prefix_sums_on_device(count)
    filled = full_on_device(n, 0, np.int64)
    launch(_place_entries_kernel, blocks_for(m), THREADS, i, j, start, filled, entry)
    launch(_sort_bodies_kernel, blocks_for(n), THREADS, start, entry)
    return start, entry


class CudaContactOperator:
    """B of m contacts among n bodies on the GPU, its frames copied there once (the contacts of
    :class:`colsim.engine.operator.ContactOperator`: i, j, frames, radii, lever)."""

    def __init__(self, contacts, n_bodies: int):
        """B of `contacts` (:class:`colsim.engine.contacts.Contacts`) among n_bodies bodies: their arrays
        on the device (:func:`contact_arrays_on_device`: none copied where the GPU's detection made
        them) and each body's contacts listed there (:func:`body_contacts_on_device`), so no list is
        made on the host, nor copied."""
        self._copy(contacts, int(n_bodies))
        d = self.device
        d["start"], d["entry"] = body_contacts_on_device(d["i"], d["j"], self.n, self.m + contacts.pair_count)

    @classmethod
    def from_operator(cls, operator) -> "CudaContactOperator":
        """The GPU's copy of a :class:`colsim.engine.operator.ContactOperator` (its lists of each
        body's contacts included)."""
        self = cls.__new__(cls)
        self._copy(operator, int(operator.n))
        self.device.update({name: cuda.to_device(np.ascontiguousarray(getattr(operator, name), dtype=np.int64))
                            for name in ("start", "entry")})
        return self

    def _copy(self, contacts, n_bodies: int) -> None:
        """The contacts' arrays on the device (:func:`contact_arrays_on_device`): i and j in one copy,
        the radii and levers in another, each frame on its own (shared with the warm start's)."""
        self.n, self.m = n_bodies, contacts.m
        self.device = dict(zip(("i", "j"), contact_arrays_on_device(contacts, ("i", "j"), np.int64)))
        self.device.update(zip(("radius_i", "radius_j", "lever"),
                               contact_arrays_on_device(contacts, ("radius_i", "radius_j", "lever"))))
        for name in SHARED_FRAMES:
            self.device[name], = contact_arrays_on_device(contacts, (name,))
        self.work = cuda.device_array((max(self.m, 1), 9), dtype=np.float64)

    def geometry(self, s) -> ContactGeometry:
        """The contacts by name on the device, with the rows' scaling s (5m,) (a device array)."""
        d = self.device
        return ContactGeometry(s, d["i"], d["j"], d["normal"], d["tangent1"], d["tangent2"], d["radius_i"],
                               d["radius_j"], d["lever"], d["start"], d["entry"], self.work)

    def _frames(self):
        d = self.device
        return (d["i"], d["j"], d["normal"], d["tangent1"], d["tangent2"], d["radius_i"], d["radius_j"], d["lever"])

    def apply_on_device(self, u, out, inv_mass=None, s=None, c=None) -> None:
        """out (5m,) = S B Mbar^-1 u + c, every array on the device (inv_mass, s: ones, c: zeros if None)."""
        if not self.m:
            return
        inv_mass = full_on_device(6 * self.n, 1.0) if inv_mass is None else inv_mass
        s = full_on_device(5 * self.m, 1.0) if s is None else s
        c = full_on_device(5 * self.m, 0.0) if c is None else c
        gradient_on_device(self.geometry(s), u, inv_mass, c, out)

    def transpose_on_device(self, z, s, out) -> None:
        """out (6n,) = B' S z, every array on the device."""
        transpose_on_device(self.geometry(s), z, out)

    def apply(self, u) -> np.ndarray:
        """(5m,) B u for u (6n,), from and to the host."""
        out = cuda.device_array(5 * self.m, dtype=np.float64)
        self.apply_on_device(cuda.to_device(np.ascontiguousarray(u, dtype=float)), out)
        return out.copy_to_host()

    def transpose(self, z, scaling=None) -> np.ndarray:
        """(6n,) B' S z for z (5m,) (S = diag(scaling), identity if None), from and to the host."""
        s = np.ones(5 * self.m) if scaling is None else np.ascontiguousarray(scaling, dtype=float)
        out = cuda.device_array(6 * self.n, dtype=np.float64)
        self.transpose_on_device(cuda.to_device(np.ascontiguousarray(z, dtype=float)), cuda.to_device(s), out)
        return out.copy_to_host()

    def diagonal(self, inv_mass) -> np.ndarray:
        """(m, 5) the diagonal of B Mbar^-1 B' (inv_mass: (6n,) the diagonal of Mbar^-1)."""
        return self.diagonal_on_device(cuda.to_device(np.ascontiguousarray(inv_mass, dtype=float))).copy_to_host()[
            : self.m]

    def diagonal_on_device(self, inv_mass):
        """(max(m, 1), 5) device array: the diagonal of B Mbar^-1 B' (inv_mass: (6n,) on the device)."""
        out = cuda.device_array((max(self.m, 1), 5), dtype=np.float64)
        if self.m:
            launch(_diagonal_kernel, blocks_for(self.m), THREADS, inv_mass, *self._frames(), out)
        return out
