"""benchmarks/gpu.py's narrower storage of APGD's iteration (--storage-variants, --stored): the bytes
it counts, and the arrays it narrows on the device (numba's simulator here): each the nearest float32
or the same int32 of its float64 or int64, the iteration then run on them."""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import gpu  # noqa: E402


def test_the_bytes_as_compiled_are_the_kernels_words():
    """8 bytes an element: a trial step 59m + 43n + 1 + entries words, a check 31m + 12n (the counts of
    iteration_bytes' docstring)."""
    m, n, entries = 1000, 330, 1950
    assert gpu.iteration_bytes(m, n, entries, 7, 6, 2) == 8 * (7 * (59 * m + 43 * n + 1 + entries)
                                                               + 2 * (31 * m + 12 * n))


def test_narrower_groups_count_their_elements_at_four_bytes():
    """Each group's elements by hand: the iterate 15m a trial step and 5m a check, the bodies' slots 30n
    and 6n, the wrenches 18m, the geometry 17m and 17m, the indices 2m + n + 1 + entries and 2m."""
    m, n, entries = 1000, 330, 1950
    full = gpu.iteration_bytes(m, n, entries, 1, 1, 1)
    saved = {"iterate": 15 * m + 5 * m, "bodies": 30 * n + 6 * n, "work": 18 * m, "geometry": 34 * m,
             "indices": 2 * m + n + 1 + entries + 2 * m}
    for group, elements in saved.items():
        assert full - gpu.iteration_bytes(m, n, entries, 1, 1, 1, {group: 4}) == 4 * elements, group
    everything = {group: 4 for group in gpu.STORED_GROUPS}
    assert full - gpu.iteration_bytes(m, n, entries, 1, 1, 1, everything) == 4 * sum(saved.values())


def test_the_narrowed_iteration_holds_the_nearest_float32_and_the_same_int32():
    """On a 40-sphere lattice: every group narrowed ("all") holds the float64 arrays' nearest float32
    and the int64 arrays' values; three iterations from there end within float32's rounding of the
    float64 iterate's largest entry. The bound is the storage's: an iteration is a gradient step of
    length 1/L and a projection, which do not enlarge a difference, so three iterations' roundings of
    what they store (6e-8 each) stay within 3e-6, fifty of them."""
    from colsim.solvers.apgd_cuda import CudaIteration

    start, operator, mu, mu_r = gpu.start_of(40)
    wide = CudaIteration.like(start, operator, mu, mu_r)
    with gpu.fresh_iteration_kernels():
        narrow = gpu.stored_as(CudaIteration.like(start, operator, mu, mu_r), gpu.STORAGE_VARIANTS["all"][1])
        for name in ("s", "normal", "lever", "i", "entry", "work"):
            before, after = getattr(wide.geometry, name).copy_to_host(), getattr(narrow.geometry, name).copy_to_host()
            kind = np.int32 if name in ("i", "entry") else np.float32
            assert after.dtype == kind and after.shape == before.shape, name
            if name != "work":   # room for the wrenches, written before read
                assert np.array_equal(after, before.astype(kind)), name
        assert np.array_equal(narrow.x.copy_to_host(), wide.x.copy_to_host().astype(np.float32))
        assert np.array_equal(narrow.hx.copy_to_host(), wide.hx.copy_to_host().astype(np.float32))
        narrow.iterate(3)
    wide.iterate(3)
    x = wide.host_x()
    assert np.max(np.abs(narrow.host_x().astype(np.float64) - x)) <= 3e-6 * np.max(np.abs(x))
