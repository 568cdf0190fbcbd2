"""The warm start's matching on one GPU (issue 46, item 3): :meth:`colsim.engine.warm_start.WarmStart.match`
with the last step's pairs in a hash table on the device instead of a sorted array on the host.

The stored pairs' keys (the CPU's: particle i and the other body, one int64 each) go into an
open-addressing table of a power-of-two size at least twice their number (linear probing, each
slot claimed by an atomic compare-and-swap), with their row beside them. Then one thread a new
contact looks its key up, and where it is found re-expresses the stored force and rolling force in
the contact's frame and projects them onto its cone (the same scalar projection the CPU's match
runs, :func:`colsim.engine.cones.project_point`). A key is stored once (a pair carries one force),
so which slot holds it does not change the answer: the same every run, whatever the order of the
atomic operations. Without a GPU the kernels run on numba's CUDA simulator (the tests).
"""
from __future__ import annotations

import numpy as np

from .cuda_operator import THREADS, blocks_for, cuda, frame_on_device, full_on_device, project_point_on_device
from .program import ROWS_PER_CONTACT
from .warm_start import WarmStart, _pair_keys

EMPTY = -1   # a free slot of the table (keys are >= 0)


def match_on_device(warm: WarmStart, contacts, n_particles: int) -> np.ndarray:
    """(m, 5) = :meth:`WarmStart.match` (the stored forces of the pairs in `contacts`, in their frames,
    projected onto their cones; zeros for new pairs), matched on the GPU."""
    out = np.zeros((contacts.m, ROWS_PER_CONTACT))
    if warm.m == 0 or contacts.m == 0:
        return out
    # three copies to the device: the stored and the new keys, the stored forces, the coefficients
    keys = cuda.to_device(np.concatenate([_pair_keys(warm.i, warm.j, warm.family, n_particles),
                                          _pair_keys(contacts.i, contacts.j, contacts.family, n_particles)]))
    stored, keys = keys[:warm.m], keys[warm.m:]
    forces = cuda.to_device(np.stack([warm.force, warm.rolling]).astype(float, copy=False))
    coefficients = cuda.to_device(np.stack([contacts.mu, contacts.mu_r]).astype(float, copy=False))
    size = 1 << int(2 * warm.m - 1).bit_length()       # a power of two >= 2 m
    table_key = full_on_device(size, EMPTY, np.int64)
    table_row = cuda.device_array(size, dtype=np.int64)   # read only where a key was stored
    _insert_kernel[blocks_for(warm.m), THREADS](stored, table_key, table_row)
    d_out = full_on_device((contacts.m, ROWS_PER_CONTACT), 0.0)
    frames = [frame_on_device(array) for array in (contacts.normal, contacts.tangent1, contacts.tangent2)]
    _match_kernel[blocks_for(contacts.m), THREADS](keys, table_key, table_row, forces[0], forces[1], *frames,
                                                   coefficients[0], coefficients[1], d_out)
    return d_out.copy_to_host()


@cuda.jit(device=True)
def _slot(key, size):
    """The first slot to probe for `key` (a power-of-two `size`): its particle and other body mixed."""
    return ((key >> 32) * 73856093 ^ (key & 0xFFFFFFFF) * 19349663) & (size - 1)


@cuda.jit
def _insert_kernel(keys, table_key, table_row):
    """Stored pair r into the table: the first free slot from its hash claims its key, and takes r."""
    r = cuda.grid(1)
    if r >= keys.shape[0]:
        return
    size = table_key.shape[0]
    s = _slot(keys[r], size)
    while True:
        if cuda.atomic.cas(table_key, s, EMPTY, keys[r]) == EMPTY:
            table_row[s] = r
            return
        s = (s + 1) & (size - 1)


@cuda.jit
def _match_kernel(keys, table_key, table_row, force, rolling, normal, tangent1, tangent2, mu, mu_r, out):
    """out[k] = contact k's stored force and rolling force in its frame, projected onto its cone
    (left zero when its pair is not stored)."""
    k = cuda.grid(1)
    if k >= keys.shape[0]:
        return
    size = table_key.shape[0]
    s = _slot(keys[k], size)
    while table_key[s] != keys[k]:
        if table_key[s] == EMPTY:
            return
        s = (s + 1) & (size - 1)
    r = table_row[s]
    p = q1 = q2 = r1 = r2 = 0.0
    for d in range(3):
        p += force[r, d] * normal[k, d]
        q1 += force[r, d] * tangent1[k, d]
        q2 += force[r, d] * tangent2[k, d]
        r1 += rolling[r, d] * tangent1[k, d]
        r2 += rolling[r, d] * tangent2[k, d]
    out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4] = project_point_on_device(p, q1, q2, r1, r2, mu[k], mu_r[k])
