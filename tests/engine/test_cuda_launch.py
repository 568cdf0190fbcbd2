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


def test_a_prepared_launch_writes_what_the_plain_launch_writes():
    """A Prepared launch, called again and again, writes the plain launch's bits."""
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
