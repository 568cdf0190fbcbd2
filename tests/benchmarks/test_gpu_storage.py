"""benchmarks/gpu.py's narrower storage of APGD's iteration (--storage-variants, --stored): the bytes
it counts, and the arrays it narrows on the device (numba's simulator here): each the nearest float32
or the same int32 of its float64 or int64, the iteration then run on them."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import gpu  # noqa: E402


def test_the_bytes_as_compiled_are_the_kernels_words():
    """8 bytes an element: a trial step 59m + 43n + 1 + entries words, a check 31m + 12n (the counts of
    iteration_bytes' docstring)."""
    m, n, entries = 1000, 330, 1950
    assert gpu.iteration_bytes(m, n, entries, 7, 6, 2) == 8 * (7 * (59 * m + 43 * n + 1 + entries)
                                                               + 2 * (31 * m + 12 * n))


def test_narrower_groups_count_their_elements_at_four_bytes():
    """Each group's elements by hand. A trial step: the iterate 15m, the bodies' slots 30n, the wrenches
    18m, the geometry 17m, the indices 2m + n + 1 + entries. A check reads float64 under any storage,
    and under float32 storage (the iterate narrowed) first widens the iterate (5m at 4 bytes, 5m at 8)
    and makes its T x in float64 (31m, then n + 1 + entries + 9m + 6n, at 8)."""
    m, n, entries = 1000, 330, 1950
    full = gpu.iteration_bytes(m, n, entries, 1, 1, 1)
    saved = {"bodies": 30 * n, "work": 18 * m, "geometry": 17 * m, "indices": 2 * m + n + 1 + entries}
    for group, elements in saved.items():
        assert full - gpu.iteration_bytes(m, n, entries, 1, 1, 1, {group: 4}) == 4 * elements, group
    widening = 4 * 5 * m + 8 * (5 * m + 31 * m + n + 1 + entries + 9 * m + 6 * n)
    assert full - gpu.iteration_bytes(m, n, entries, 1, 1, 1, {"iterate": 4}) == 4 * 15 * m - widening
    everything = {group: 4 for group in gpu.STORED_GROUPS}
    assert (full - gpu.iteration_bytes(m, n, entries, 1, 1, 1, everything)
            == 4 * (sum(saved.values()) + 15 * m) - widening)


@pytest.mark.slow   # the CUDA simulator's longer runs, or studies end to end: `pytest -m slow`
def test_the_narrowed_iteration_holds_the_nearest_float32_and_the_same_int32():
    """On a 40-sphere lattice: every group narrowed ("all") holds, for its trial steps, the float64
    arrays' nearest float32 and the int64 arrays' values, and keeps the float64 contact arrays for its
    checks; three iterations from there end within float32's rounding of the float64 iterate's largest
    entry. The bound is the storage's: an iteration is a gradient step of length 1/L and a projection,
    which do not enlarge a difference, so three iterations' roundings of what they store (6e-8 each)
    stay within 3e-6, fifty of them."""
    from colsim.engine.cuda_apgd import CudaIteration

    start, operator, mu, mu_r = gpu.start_of(40)
    wide = CudaIteration.like(start, operator, mu, mu_r)
    narrow = gpu.stored_as(CudaIteration.like(start, operator, mu, mu_r), gpu.STORAGE_VARIANTS["all"][1])
    for name in ("s", "normal", "lever", "i", "entry", "work"):
        before, after = getattr(wide.geometry, name).copy_to_host(), getattr(narrow.trial_geometry, name).copy_to_host()
        kind = np.int32 if name in ("i", "entry") else np.float32
        assert after.dtype == kind and after.shape == before.shape, name
        assert getattr(narrow.geometry, name).dtype == before.dtype, name
        if name != "work":   # room for the wrenches, written before read
            assert np.array_equal(after, before.astype(kind)), name
    assert np.array_equal(narrow.x_slots[0].copy_to_host(), wide.x.copy_to_host().astype(np.float32))
    assert np.array_equal(narrow.h_slots[0].copy_to_host(), wide.hx.copy_to_host().astype(np.float32))
    narrow.iterate(3)
    wide.iterate(3)
    x = wide.host_x()
    assert np.max(np.abs(narrow.host_x() - x)) <= 3e-6 * np.max(np.abs(x))
