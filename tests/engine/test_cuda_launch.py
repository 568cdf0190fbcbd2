"""Launches with the arrays' words made once (colsim.engine.cuda_launch, issue 46): the kernel gets
the same arguments as through numba's dispatcher, so it writes the same bits; what the launcher
cannot take (a host array, an argument of another type) goes the plain way. On numba's simulator
every launch goes the plain way, so there the test checks that; on a GPU, that the launcher ran."""
import numpy as np
import pytest
from numba.core import config as numba_config

cuda_operator = pytest.importorskip("colsim.engine.cuda_operator", reason="numba.cuda is not importable")
from colsim.engine import cuda_launch  # noqa: E402

cuda = cuda_operator.cuda


@cuda.jit
def _axpy_kernel(a, x, y, count, out):
    i = cuda.grid(1)
    if i < count:
        out[i] = a * x[i] + y[i]


def test_a_launch_writes_what_the_plain_launch_writes():
    rng = np.random.default_rng(7)
    x, y = (cuda.to_device(rng.standard_normal(300)) for _ in range(2))
    ours, plain = cuda.device_array(300), cuda.device_array(300)
    with cuda_launch.plain_launches():
        _axpy_kernel[3, 128](0.5, x, y, 300, plain)   # compiles: the launcher takes the one overload
    for a in (0.5, 2.0, 3):   # a scalar anew at each launch, an int too (the kernel's float64)
        cuda_launch.launch(_axpy_kernel, 3, 128, a, x, y, 300, ours)
        with cuda_launch.plain_launches():
            cuda_launch.launch(_axpy_kernel, 3, 128, a, x, y, 300, plain)
        assert np.array_equal(ours.copy_to_host(), plain.copy_to_host())
        np.testing.assert_allclose(ours.copy_to_host(), a * x.copy_to_host() + y.copy_to_host(), rtol=1e-15)
    host_out = np.zeros(300)   # a host array: the plain way, which copies it back
    cuda_launch.launch(_axpy_kernel, 3, 128, 1.0, x, y, 300, host_out)
    np.testing.assert_allclose(host_out, x.copy_to_host() + y.copy_to_host(), rtol=1e-15)
    launcher = cuda_launch._launchers.get(_axpy_kernel)
    if numba_config.ENABLE_CUDASIM:
        assert not launcher   # the simulator: the plain way only
    else:
        assert launcher, "on a GPU the launcher should have taken the kernel"


def test_packed_parameters_point_at_each_word_s_value():
    """The driver reads parameter i from the address at pointers[i]: every int word there as a
    64-bit value (a pointer above 2^63 with the same bits), a ctypes scalar from its own storage."""
    import ctypes
    scalar, count = ctypes.c_double(2.5), ctypes.c_int64(-3)
    words = [0, 0, 300, 8, 0x7F00_0000_1234, 300, 8, scalar, count, (1 << 63) + 5]
    kept, pointers = cuda_launch.packed_parameters(words)
    assert len(pointers) == len(words)
    for pointer, word in zip(pointers, words):
        if isinstance(word, int):
            assert ctypes.c_uint64.from_address(pointer).value == word
        else:
            assert ctypes.addressof(word) == pointer and type(word).from_address(pointer).value == word.value
    with pytest.raises(TypeError, match="bool"):
        cuda_launch.packed_parameters([True])


@pytest.mark.parametrize("direct", [False, True])
def test_a_prepared_launch_writes_what_the_plain_launch_writes(direct, monkeypatch):
    """A Prepared launch, called again and again, writes the plain launch's bits: on a GPU through the
    driver itself where asked (direct), on the simulator the plain way either way."""
    monkeypatch.setattr(cuda_launch, "direct_enabled", direct)
    rng = np.random.default_rng(8)
    x, y = (cuda.to_device(rng.standard_normal(300)) for _ in range(2))
    ours, plain = cuda.device_array(300), cuda.device_array(300)
    prepared = cuda_launch.Prepared(_axpy_kernel, 3, 128, 0.5, x, y, 300, ours)
    with cuda_launch.plain_launches():
        _axpy_kernel[3, 128](0.5, x, y, 300, plain)
    for _ in range(3):
        ours.copy_to_device(np.zeros(300))
        prepared()
        assert np.array_equal(ours.copy_to_host(), plain.copy_to_host())
    if numba_config.ENABLE_CUDASIM or not direct:
        assert prepared._direct is None   # never tried
    else:
        assert prepared._direct, "on a GPU the direct launch should have been made"
