"""Where a stage's steps run: its `device` setting, with 'auto' decided here once, before the stage
builds its back-end (:func:`colsim.engine.backends.make_backend`)."""
from __future__ import annotations

import logging

from ..solvers import defaults

log = logging.getLogger(__name__)


def device_for(device: str, spheres: float, solver: str = "auto") -> str:
    """'cpu' or 'cuda' for a pour or collapse of about `spheres` spheres solved by `solver`: `device`
    itself, or for 'auto' the GPU where APGD solves (auto, apgd), a GPU is visible (numba's
    simulator is none) and spheres >= GPU_FROM_SPHERES, else the CPU; auto's choice is logged."""
    if device != "auto":
        return device
    if solver not in ("auto", "apgd") or spheres < defaults.GPU_FROM_SPHERES:
        chosen = "cpu"
    else:
        from ..engine.backends import gpu_visible

        chosen = "cuda" if gpu_visible() else "cpu"
    log.info("device auto: %s (about %d spheres, solver %s; the GPU from %d spheres under APGD, when one is "
             "visible)", chosen, round(spheres), solver, defaults.GPU_FROM_SPHERES)
    return chosen
