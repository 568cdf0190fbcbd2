"""The contact operator's CUDA kernels (colsim.engine.cuda_operator, issue 46): B u, B' S z,
diag(B Mbar^-1 B') and the dot product equal the CPU kernels' (colsim.engine.operator) on a pile with
particle, floor, cylinder and fixed-sphere contacts. They run on numba's CUDA simulator here
(conftest sets NUMBA_ENABLE_CUDASIM=1 unless told otherwise), on a GPU where there is one.

Bound 1e-14 relative: the same arithmetic in the same order, each body's sums in contact order on
both; only a fused multiply-add that one compiler makes and the other does not can change a last bit."""
import gc

import numpy as np
import pytest

from colsim.engine.operator import ContactOperator

cuda_operator = pytest.importorskip("colsim.engine.cuda_operator", reason="numba.cuda is not importable")


def test_the_kernels_equal_the_cpu_operator(pile_with_every_contact):
    state, found, program = pile_with_every_contact
    n = state.n
    cpu, gpu = ContactOperator(found, n), cuda_operator.CudaContactOperator(found, n)
    rng = np.random.default_rng(46)
    u, z, s = rng.standard_normal(6 * n), rng.standard_normal(5 * found.m), rng.uniform(0.5, 2.0, 5 * found.m)
    for ours, theirs in ((gpu.apply(u), cpu.apply(u)), (gpu.transpose(z, s), cpu.transpose(z, s)),
                         (gpu.transpose(z), cpu.transpose(z)),
                         (gpu.diagonal(1.0 / program.mass), cpu.diagonal(1.0 / program.mass))):
        np.testing.assert_allclose(ours, theirs, rtol=1e-14, atol=1e-14 * np.abs(theirs).max())


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_the_dot_product_sums_in_a_fixed_order():
    """Over several blocks (1,000 values, blocks of THREADS: 128 on a GPU, 32 on the simulator):
    numpy's dot to rounding, and the same bits on every call."""
    rng = np.random.default_rng(7)
    a, b = rng.standard_normal(1000), rng.standard_normal(1000)
    first = cuda_operator.dot(a, b)
    assert first == pytest.approx(float(np.dot(a, b)), rel=1e-13)
    assert all(cuda_operator.dot(a, b) == first for _ in range(3))


def test_no_contacts_give_zero_forces():
    from colsim.engine.contacts import Contacts

    empty = Contacts(**{name: np.zeros((0, 3)) if name in ("normal", "tangent1", "tangent2") else np.zeros(0)
                        for name in Contacts.__dataclass_fields__})
    gpu = cuda_operator.CudaContactOperator(empty, 4)
    np.testing.assert_array_equal(gpu.transpose(np.zeros(0)), np.zeros(24))
    assert gpu.apply(np.ones(24)).shape == (0,) and gpu.diagonal(np.ones(24)).shape == (0, 5)


def test_an_array_goes_to_the_device_once_and_goes_with_its_array():
    """The warm start's matching and the solver's operator share one device copy of each frame of
    an attempt's contacts (and of its pair keys, int64, kept as they are): the same host array gives
    the same device array, another array its own, and the copy is dropped with the host array."""
    normal = np.random.default_rng(6).normal(size=(40, 3))
    first = cuda_operator.device_copy_of(normal)
    assert cuda_operator.device_copy_of(normal) is first and np.array_equal(first.copy_to_host(), normal)
    assert cuda_operator.kept_device_copy(normal) is first
    other = normal.copy()
    assert cuda_operator.kept_device_copy(other) is None
    assert cuda_operator.device_copy_of(other) is not first
    keys = np.arange(-3, 37, dtype=np.int64) << 32
    assert cuda_operator.device_copy_of(keys).dtype == np.int64
    np.testing.assert_array_equal(cuda_operator.device_copy_of(keys).copy_to_host(), keys)
    key = id(normal)
    del normal
    gc.collect()
    assert key not in cuda_operator._device_copies


@pytest.mark.parametrize("shape, value, dtype", [(300, 0.0, np.float64), ((7, 5), 2.5, np.float64),
                                                 (129, -1, np.int64), (0, 0, np.int64)])
def test_an_array_filled_on_the_device_holds_its_value_everywhere(shape, value, dtype):
    """full_on_device makes the array there; every entry is the value (none left as allocated)."""
    garbage = cuda_operator.cuda.to_device(np.full(shape, 99, dtype=dtype))   # a freed block to reuse
    del garbage
    ours = cuda_operator.full_on_device(shape, value, dtype).copy_to_host()
    assert ours.dtype == dtype and ours.shape == np.full(shape, value, dtype=dtype).shape
    assert np.array_equal(ours, np.full(shape, value, dtype=dtype))


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_a_vector_normalised_on_the_device_has_unit_length_and_the_same_bits_every_run():
    """normalise_on_device: v / ||v|| to rounding (the norm's sum in another order than numpy's), and
    the same bits on a second run (a fixed order)."""
    cuda = cuda_operator.cuda
    v = np.random.default_rng(12).standard_normal(1000) * 1e3
    runs = []
    for _ in range(2):
        d_v = cuda.to_device(v)
        partial = cuda.device_array(cuda_operator.blocks_for(len(v)))
        square = cuda.device_array(1)
        cuda_operator.normalise_on_device(d_v, partial, square)
        runs.append(d_v.copy_to_host())
    np.testing.assert_allclose(runs[0], v / np.linalg.norm(v), rtol=1e-14, atol=0)
    assert np.array_equal(runs[0], runs[1])


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_each_bodys_contacts_are_listed_on_the_device_as_on_the_cpu(pile_with_every_contact):
    """body_contacts_on_device: the CPU's lists (colsim.engine.operator.body_contacts) exactly, on a
    pile with walls and fixed spheres (no second body) and on random pairs among bodies some of which
    have none, over several blocks of bodies; integer sums and a sort, so equal, not close."""
    from colsim.engine.operator import body_contacts

    state, found, _ = pile_with_every_contact
    rng = np.random.default_rng(5)
    first = rng.integers(0, 300, 2000)
    second = np.where(rng.random(2000) < 0.2, -1, (first + rng.integers(1, 300, 2000)) % 300)
    for i, j, n in ((found.i, found.j, state.n), (first, second, 310), (np.zeros(0, int), np.zeros(0, int), 5)):
        i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
        start, entry = cuda_operator.body_contacts_on_device(
            cuda_operator.cuda.to_device(i), cuda_operator.cuda.to_device(j), n, len(i) + int(np.sum(j >= 0)))
        expected_start, expected_entry = body_contacts(i, j, n)
        np.testing.assert_array_equal(start.copy_to_host(), expected_start)
        np.testing.assert_array_equal(entry.copy_to_host(), expected_entry)


@pytest.mark.parametrize("n", sorted({0, 1, 127, 128, 129, 1000, cuda_operator.THREADS - 1, cuda_operator.THREADS,
                                       cuda_operator.THREADS + 1}))
def test_prefix_sums_on_the_device_are_numpys(n):
    """prefix_sums_on_device: 0 then numpy's cumsum, exactly (integers), across block edges."""
    count = np.random.default_rng(n).integers(0, 9, n).astype(np.int64)
    ours = cuda_operator.prefix_sums_on_device(cuda_operator.cuda.to_device(count)).copy_to_host()
    np.testing.assert_array_equal(ours, np.concatenate([[0], np.cumsum(count)]))


@pytest.mark.parametrize("blocks", [5, 300])
def test_the_blocks_totals_are_scanned_by_one_block(blocks):
    """The blocks' totals' exclusive running sums, by one block of THREADS threads: more totals than
    threads (300: each thread sums a stretch of several) as well as fewer."""
    totals = np.random.default_rng(blocks).integers(0, 1000, blocks).astype(np.int64)
    on_device = cuda_operator.cuda.to_device(totals)
    cuda_operator._exclusive_scan_kernel[1, cuda_operator.THREADS](on_device)
    np.testing.assert_array_equal(on_device.copy_to_host(), np.concatenate([[0], np.cumsum(totals)[:-1]]))
