"""Where a stage's steps run (colsim.stages.devices): the device setting, auto decided once."""


def test_device_auto_takes_a_visible_gpu_for_large_columns_only(monkeypatch):
    """device_for: cpu and cuda stay as given; auto takes the GPU only where APGD solves,
    one is visible and the column holds GPU_FROM_SPHERES spheres or more. numba's simulator (conftest)
    is no GPU."""
    from numba.core import config as numba_config

    from colsim.engine import backends
    from colsim.stages import devices
    from colsim.solvers.defaults import GPU_FROM_SPHERES

    assert devices.device_for("cpu", 10**7) == "cpu" and devices.device_for("cuda", 10) == "cuda"
    if numba_config.ENABLE_CUDASIM:
        assert not backends.gpu_visible()
    monkeypatch.setattr(backends, "gpu_visible", lambda: False)   # a machine without a GPU
    assert devices.device_for("auto", 10**7) == "cpu"
    monkeypatch.setattr(backends, "gpu_visible", lambda: True)   # a machine with a GPU
    assert devices.device_for("auto", GPU_FROM_SPHERES) == "cuda"
    assert devices.device_for("auto", GPU_FROM_SPHERES, "apgd") == "cuda"
    assert devices.device_for("auto", GPU_FROM_SPHERES - 1) == "cpu"
    assert devices.device_for("auto", 10**7, "clarabel") == "cpu"   # APGD's device only
