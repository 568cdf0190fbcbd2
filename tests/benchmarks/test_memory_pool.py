"""benchmarks/memory_pool.py's bookkeeping (the plugin itself needs a GPU: numba's simulator has no
memory managers): a request gets a block of its size class, never smaller and at most 1/8 larger,
and a block given back serves the next request of its class instead of a new one."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from memory_pool import SMALLEST, FreeLists, size_class  # noqa: E402


def test_a_request_s_class_holds_it_with_at_most_an_eighth_to_spare():
    for size in [0, 1, SMALLEST, SMALLEST + 1, 4095, 4096, 4097, 10**6, 74 * 10**6 + 8, 2**31 + 3]:
        block = size_class(size)
        assert block >= max(size, 1)
        assert block == SMALLEST or block <= size + size / 8, (size, block)
    assert size_class(513) == 576 and size_class(1000) == 1024 and size_class(1025) == 1152


def test_a_block_given_back_serves_the_next_request_of_its_class():
    """Three requests of one class made three blocks; two given back serve the next two requests
    (last given, first taken), a third request of that class makes a fourth, another class its own."""
    made = []
    pool = FreeLists(lambda nbytes: made.append(nbytes) or len(made))
    first = [pool.take(10_000) for _ in range(3)]
    assert [block for block, _ in first] == [1, 2, 3] and {b for _, b in first} == {size_class(10_000)}
    pool.give(*first[0])
    pool.give(*first[2])
    assert pool.take(10_100)[0] == 3 and pool.take(9_900)[0] == 1   # the same class: 10,240 bytes
    assert pool.take(10_000)[0] == 4 and pool.take(100)[0] == 5
    assert [nbytes for _, nbytes in pool.clear()] == [10_240] * 4 + [SMALLEST]
    assert pool.take(10_000)[0] == 6
