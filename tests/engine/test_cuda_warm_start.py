"""The warm start's matching on the GPU (colsim.engine.cuda_warm_start, issue 46.3) is the CPU's
(WarmStart.match): the same pairs found, the same forces in the new frames, projected onto the same
cones. On numba's CUDA simulator here (conftest sets NUMBA_ENABLE_CUDASIM=1 unless told otherwise).

Bound 1e-14 of the largest force: the same products, summed over three components in the same order,
and the same projection (the CPU's vectorised, the GPU's the scalar code it mirrors)."""
import dataclasses

import numpy as np
import pytest


from colsim.solvers import WarmStart

from solver_cases import collapse_program

pytest.importorskip("colsim.engine.cuda_warm_start", reason="numba.cuda is not importable")

from colsim.engine.backend import HOST  # noqa: E402
from colsim.engine.backends import make_backend  # noqa: E402

#: the GPU's back-end (numba's simulator here), and both by device
CUDA = make_backend("cuda")
BACKENDS = {"cuda": CUDA, "cpu": HOST}


def _both(warm: WarmStart, contacts, n: int):
    gpu, cpu = CUDA.matched(warm, contacts).copy_to_host(), warm.match(contacts)
    np.testing.assert_allclose(gpu, cpu, rtol=0, atol=1e-14 * max(np.abs(cpu).max(), 1.0))
    return gpu, cpu


def test_the_gpu_matches_the_cpu_s_pairs_and_forces(solver_pile):
    """The 90-sphere pile's contacts (particles, floor, cylinder) with forces partly outside their
    cones (so the projection acts), matched to the same contacts, then with a fifth of the stored
    pairs gone (those start from zero on both), then after a renumbering that drops a third of the
    particles (the trim's)."""
    _, found = collapse_program(solver_pile)
    rng = np.random.default_rng(46)
    forces = rng.uniform(0.0, 1.0, (found.m, 5)) * [1.0, 0.8, 0.8, 0.2, 0.2]
    warm = WarmStart.from_step(found, forces)
    gpu, cpu = _both(warm, found, solver_pile.n)
    assert not np.allclose(cpu, forces)                    # some were outside their cones
    keep = rng.uniform(size=warm.m) > 0.2
    fewer = WarmStart(warm.i[keep], warm.j[keep], warm.family[keep], warm.force[keep], warm.rolling[keep])
    gpu, _ = _both(fewer, found, solver_pile.n)
    assert np.all(gpu[~keep] == 0.0) and np.any(gpu[keep] != 0.0)
    particles = np.ones(solver_pile.n, dtype=bool)
    particles[::3] = False
    column = solver_pile.subset(particles)
    _, found_after = collapse_program(column)
    _both(warm.subset(particles), found_after, column.n)


def test_nothing_stored_or_no_contacts_give_zeros(solver_pile):
    _, found = collapse_program(solver_pile)
    empty = WarmStart(*(np.zeros(0, dtype=np.int64) for _ in range(3)), np.zeros((0, 3)), np.zeros((0, 3)))
    assert np.all(CUDA.matched(empty, found).copy_to_host() == 0.0)
    none = WarmStart.from_step(found, np.ones((found.m, 5)))
    nothing = dataclasses.replace(found, **{f.name: getattr(found, f.name)[:0] for f in dataclasses.fields(found)
                                            if isinstance(getattr(found, f.name), np.ndarray)})
    assert CUDA.matched(none, nothing).copy_to_host().shape == (0, 5)


def test_a_step_s_forces_stay_on_the_device_for_the_next_step(solver_pile, monkeypatch):
    """from_step on the GPU turns the forces into the global frame there (the CPU's sums; bound 4
    ulps of the largest force, for the multiply-adds a GPU fuses) and keeps them there: read on the
    host, they are the CPU's record; matched on the GPU, they give the CPU's match (1e-14, as
    above); and a match of contacts detected on the host copies to the device only their keys and
    coefficients, once (8 + 16 bytes a contact: the next match finds them there), where a host
    record's matching copies its stored keys and forces too (8 + 48 more)."""
    from numba import cuda

    from colsim.engine.cuda_warm_start import DeviceWarmStart

    _, found = collapse_program(solver_pile)
    forces = np.random.default_rng(47).uniform(0.0, 1.0, (found.m, 5)) * [1.0, 0.8, 0.8, 0.2, 0.2]
    host = WarmStart.from_step(found, forces)
    carried = CUDA.carried(found, forces)   # the forces and frames go to the device here
    assert isinstance(carried, DeviceWarmStart) and carried.m == host.m
    largest = 4 * np.finfo(float).eps * np.abs(forces).max()
    for name in ("force", "rolling"):
        np.testing.assert_allclose(getattr(carried, name), getattr(host, name), rtol=0, atol=largest)
    for name in ("i", "j", "family"):
        np.testing.assert_array_equal(getattr(carried, name), getattr(host, name))
    np.testing.assert_allclose(carried.match(found), host.match(found), rtol=0, atol=1e-14)   # on the CPU

    copied = _copies_to_device(monkeypatch, cuda)
    again = CUDA.carried(found, forces)      # the same arrays: nothing copied
    first, second = (CUDA.matched(again, found).copy_to_host() for _ in range(2))
    monkeypatch.undo()
    assert copied == [8 * found.m, 16 * found.m]
    expected = host.match(found)
    np.testing.assert_allclose(first, expected, rtol=0, atol=1e-14 * np.abs(expected).max())
    assert np.array_equal(first, second)


def test_contacts_detected_on_the_gpu_are_matched_with_no_copy_and_no_host_array(solver_pile, monkeypatch):
    """A GPU detection's contacts hold their keys, frames and coefficients on the device
    (DeviceContacts): a step's forces carried there and matched to the next contacts copy nothing to
    the device but the forces, and read none of the contacts' host arrays (none is copied back); the
    match is the CPU's on the same contacts (1e-14 of the largest force, as above)."""
    from numba import cuda

    from colsim.engine.contacts import DEVICE_ARRAYS
    from colsim.engine.cuda_contacts import DeviceContacts

    _, found = collapse_program(solver_pile, backend=CUDA)
    _, later = collapse_program(solver_pile, backend=CUDA)   # the next step's: a new set, the same pairs
    assert isinstance(found, DeviceContacts) and isinstance(later, DeviceContacts)
    forces = np.random.default_rng(48).uniform(0.0, 1.0, (found.m, 5)) * [1.0, 0.8, 0.8, 0.2, 0.2]
    copied = _copies_to_device(monkeypatch, cuda)
    matched = CUDA.matched(CUDA.carried(found, forces), later).copy_to_host()
    monkeypatch.undo()
    assert copied == [40 * found.m]   # the forces (m, 5): on a step's GPU solve, its own device copy
    for contacts in (found, later):
        assert not set(DEVICE_ARRAYS) & set(vars(contacts)), "a host array was copied back"
    expected = WarmStart.from_step(found, forces).match(later)
    np.testing.assert_allclose(matched, expected, rtol=0, atol=1e-14 * np.abs(expected).max())


def _copies_to_device(monkeypatch, cuda) -> list:
    """The sizes (bytes) of the arrays that cuda.to_device copies from now until monkeypatch.undo()."""
    copied = []
    to_device = cuda.to_device
    monkeypatch.setattr(cuda, "to_device", lambda array, *args, **kwargs: (
        copied.append(np.asarray(array).nbytes), to_device(array, *args, **kwargs))[1])
    return copied
