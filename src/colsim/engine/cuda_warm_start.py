"""The warm start on one GPU: :meth:`colsim.engine.warm_start.WarmStart.match`
with the last step's pairs in a hash table on the device instead of a sorted array on the host, and
the step's forces carried to the next step there (:class:`DeviceWarmStart`).

The stored pairs' keys (:func:`colsim.engine.state.pair_keys`) go into an open-addressing table of
a power-of-two size at least twice their number (linear probing, each slot claimed by an atomic
compare-and-swap), with their row beside them. Then one thread a new contact looks its key up, and
where it is found re-expresses the stored force and rolling force in the contact's frame and
projects them onto its cone (the same scalar projection the CPU's match runs,
:func:`colsim.engine.cones.project_point`). A key is stored once (a pair carries one force), so which
slot holds it does not change the answer: the same every run, whatever the order of the atomic
operations. The matched forces stay on the device, where the solver's first iterate takes them.

What a step leaves for the next also stays there: its forces turned into the global frame on the
device, from the solver's forces and the contacts' frames already there, and its contacts' keys.
The contacts of a GPU detection hold their keys, frames and coefficients on the device already
(:class:`colsim.engine.cuda_contacts.DeviceContacts`), so a step's matching copies nothing either
way; other contacts' go there once (:func:`colsim.engine.cuda_operator.contact_arrays_on_device`:
24 bytes a contact). Before, the stored keys and forces went out and the matched forces came back
and went out again (153 bytes a contact, four more copies). Without a GPU the kernels run on
numba's CUDA simulator (the tests).
"""
from __future__ import annotations

import numpy as np

from .cuda_launch import launch
from .cuda_operator import (SHARED_FRAMES, THREADS, blocks_for, contact_arrays_on_device, cuda, device_copy_of,
                            full_on_device, project_point_on_device)
from .operator import global_force_row
from .program import ROWS_PER_CONTACT
from .state import pair_keys
from .warm_start import WarmStart

EMPTY = -1   # a free slot of the table (keys are >= 0)

_global_force_row = cuda.jit(device=True)(getattr(global_force_row, "py_func", global_force_row))


class DeviceWarmStart(WarmStart):
    """A :class:`WarmStart` whose forces are on the device: the pairs are those of `contacts` (a step's
    :class:`colsim.engine.contacts.Contacts`: i, j and family read from them, their keys on the device
    from them), on_device (2, m, 3) the force and rolling force in the global frame. `force` and
    `rolling` (and a GPU detection's i, j and family) are copied to the host when first read (a
    checkpoint, a file, a match on the CPU); the GPU's matching reads them where they are."""

    def __init__(self, contacts, on_device):
        self.contacts, self.on_device = contacts, on_device
        self._on_host = None

    def _host(self) -> np.ndarray:
        if self._on_host is None:
            self._on_host = self.on_device.copy_to_host()
        return self._on_host

    m = property(lambda self: self.contacts.m)
    i = property(lambda self: self.contacts.i, doc="(m,) int particle (the contacts').")
    j = property(lambda self: self.contacts.j, doc="(m,) int other body (the contacts').")
    family = property(lambda self: self.contacts.family, doc="(m,) int family (the contacts').")
    force = property(lambda self: self._host()[0], doc="(m, 3) the force in the global frame (copied once).")
    rolling = property(lambda self: self._host()[1], doc="(m, 3) the rolling force in the global frame.")

    def keys_on_device(self):
        """(m,) int64 the pairs' keys on the device."""
        return contact_arrays_on_device(self.contacts, ("keys",), np.int64)[0]


def carried_on_device(contacts, forces) -> DeviceWarmStart:
    """:meth:`WarmStart.from_step` of m > 0 `contacts` and their forces (m, 5) on the GPU: the forces
    as they are when on the device (the solver's, when it solved there), else from their device copy,
    turned by the frames' (detection's) in the CPU's arithmetic (to rounding: a GPU fuses some
    multiply-adds)."""
    m = contacts.m
    frames = [contact_arrays_on_device(contacts, (name,))[0] for name in SHARED_FRAMES]
    on_device = cuda.device_array((2, m, 3), dtype=np.float64)
    if not hasattr(forces, "copy_to_host"):
        forces = device_copy_of(np.ascontiguousarray(forces, dtype=float))
    launch(_global_forces_kernel, blocks_for(m), THREADS, forces, *frames, on_device[0], on_device[1])
    return DeviceWarmStart(contacts, on_device)


def match_on_device(warm: WarmStart, contacts):
    """(m, 5) = :meth:`WarmStart.match` (the stored forces of the pairs in `contacts`, in their frames,
    projected onto their cones; zeros for new pairs), matched on the GPU: a device array. The new
    contacts' keys, frames and coefficients are a GPU detection's there, or go there once
    (:func:`colsim.engine.cuda_operator.contact_arrays_on_device`: the next step finds them); a
    :class:`DeviceWarmStart`'s keys and forces are there already, a host one's go in two copies."""
    out = full_on_device((contacts.m, ROWS_PER_CONTACT), 0.0)
    if warm.m == 0 or contacts.m == 0:
        return out
    keys, = contact_arrays_on_device(contacts, ("keys",), np.int64)
    if isinstance(warm, DeviceWarmStart):
        stored, forces = warm.keys_on_device(), warm.on_device
    else:
        stored = cuda.to_device(pair_keys(warm.i, warm.j, warm.family))
        forces = cuda.to_device(np.stack([warm.force, warm.rolling]).astype(float, copy=False))
    mu, mu_r = contact_arrays_on_device(contacts, ("mu", "mu_r"))
    size = 1 << int(2 * warm.m - 1).bit_length()       # a power of two >= 2 m
    table_key = full_on_device(size, EMPTY, np.int64)
    table_row = cuda.device_array(size, dtype=np.int64)   # read only where a key was stored
    launch(_insert_kernel, blocks_for(warm.m), THREADS, stored, table_key, table_row)
    frames = [contact_arrays_on_device(contacts, (name,))[0] for name in SHARED_FRAMES]
    launch(_match_kernel, blocks_for(contacts.m), THREADS, keys, table_key, table_row, forces[0], forces[1], *frames,
           mu, mu_r, out)
    return out


@cuda.jit
def _global_forces_kernel(forces, normal, tangent1, tangent2, force, rolling):
    """Contact k's force (m, 3) and rolling force (m, 3) in the global frame from its forces (m, 5)
    (:func:`colsim.engine.operator.global_forces`), one contact a thread."""
    k = cuda.grid(1)
    if k < force.shape[0]:
        _global_force_row(k, forces, normal, tangent1, tangent2, force, rolling)


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
