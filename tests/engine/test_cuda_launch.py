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
    # a scalar anew at each launch: an int where the kernel took a float64, and an integral float where
    # it took an int64 (ctypes' int64 takes no float: the launcher gives it the int)
    for a, count in ((0.5, 300), (2.0, 300), (3, 300.0)):
        cuda_launch.launch(_axpy_kernel, 3, 128, a, x, y, count, ours)
        with cuda_launch.plain_launches():
            cuda_launch.launch(_axpy_kernel, 3, 128, a, x, y, count, plain)
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


def test_numba_cudas_low_occupancy_warnings_are_off_unless_asked_for():
    """colsim's one-block launches would each print numba-cuda's warning once a grid size (hundreds of
    them in an r0 = 6 pour's log); a user who sets the variable gets them."""
    import os
    import subprocess
    import sys

    read = ("import colsim.engine.cuda_operator; from numba.core import config; "
            "print(config.CUDA_LOW_OCCUPANCY_WARNINGS)")
    environment = {k: v for k, v in os.environ.items() if k != "NUMBA_CUDA_LOW_OCCUPANCY_WARNINGS"}
    for asked, expected in ((None, "0"), ("1", "1"), ("0", "0")):
        if asked is not None:
            environment["NUMBA_CUDA_LOW_OCCUPANCY_WARNINGS"] = asked
        out = subprocess.run([sys.executable, "-c", read], env=environment, capture_output=True, text=True, check=True)
        assert out.stdout.strip() == expected


def test_the_launcher_gives_a_scalar_what_its_parameter_takes():
    """The launcher marshals a scalar with numba-cuda's own code (`_Kernel._prepare_args`), whose int64
    is a ctypes c_int64, which refuses a float, even 3.0: an integral float goes as the int, any other
    value for an integer parameter the plain way (which compiles a float overload); a boolean or a
    tuple whose value types otherwise than the parameter goes the plain way too. Checked on numba's
    real marshalling without a GPU: a subprocess with the simulator off."""
    import os
    import subprocess
    import sys

    script = """
import weakref
from numba.core import types
from numba.core.typing.typeof import Purpose, typeof
from numba.cuda.dispatcher import _Kernel
from colsim.engine.cuda_launch import _Launcher

class Kernel:
    extensions = []
    def _prepare_args(self, *args):
        return _Kernel._prepare_args(self, *args)

launcher = object.__new__(_Launcher)
launcher._kernel, launcher._types = Kernel(), (types.float64, types.int64, types.boolean, types.UniTuple(types.int64, 2))
launcher._arrays, launcher._integers = (False,) * 4, (False, True, False, False)
launcher._exact = (False, False, True, True)
launcher._device_array, launcher._words = type(None), weakref.WeakKeyDictionary()
launcher._typeof = lambda value: typeof(value, Purpose.argument)
values = [getattr(w, "value", w) for w in launcher.words((3, 3.0, True, (4, 5)))]
print(values == [3.0, 3, True, 4, 5], [type(v).__name__ for v in values[:2]])
print(launcher.words((0.5, 2.5, True, (4, 5))), launcher.words((0.5, 2, 1, (4, 5))),
      launcher.words((0.5, 2, False, (4.0, 5.0))))
"""
    environment = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0"}
    done = subprocess.run([sys.executable, "-c", script], env=environment, capture_output=True, text=True)
    if done.returncode and "cannot import name" in done.stderr:
        pytest.skip(f"this numba.cuda has no _Kernel._prepare_args: {done.stderr.strip().splitlines()[-1]}")
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.splitlines() == ["True ['float', 'int']", "None None None"]
