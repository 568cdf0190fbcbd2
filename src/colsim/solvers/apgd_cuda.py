"""APGD's iterations on one GPU (issue 46): the kernel set that APGD's one control flow
(:func:`colsim.solvers.apgd.apgd_iterations`) drives on the device, the residual check there, and
the iteration state that stays on the device between checks.

Each kernel is its CPU twin's arithmetic (colsim.solvers.apgd, colsim.engine.cones) for one contact
or one body a thread. Sums over contacts or bodies are taken per block by a fixed tree in shared
memory, then added on the host in block order: the same bits every run on one device (they differ
from the CPU's sums by rounding only). A trial step (projection, B' S z, the descent test's two sums)
costs one copy of its partial sums to the host, the only host round trip of an iteration; a residual
check costs one more. theta, beta and the Lipschitz estimate live on the host (scalars).

Without a GPU the kernels run on numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1), as in the tests.
"""
from __future__ import annotations

import math

import numpy as np

from ..engine.cuda_operator import (THREADS, CudaContactOperator, block_reduce, blocks_for, cuda,
                                    gradient_on_device, project_point_on_device,
                                    transpose_on_device)   # first: numba.cuda on numpy 2.5
from ..engine.cones import combine_residuals
from .apgd import apgd_iterations

@cuda.jit
def _project_kernel(x, x_prev, beta, g, x_new, step, mu_s, mu_r_s, parts):
    """x_new = Proj_K(y - step g) at y = x + beta (x - x_prev), one contact a thread; parts[0] and
    parts[1] (per block): ||x_new - y||^2 and g . (x_new - x) (colsim.solvers.apgd._project_step)."""
    moved = cuda.shared.array(THREADS, dtype=np.float64)
    uphill = cuda.shared.array(THREADS, dtype=np.float64)
    k = cuda.grid(1)
    t = cuda.threadIdx.x
    moved[t] = 0.0
    uphill[t] = 0.0
    if k < mu_s.shape[0]:
        o = 5 * k
        y0 = x[o] + beta * (x[o] - x_prev[o])
        y1 = x[o + 1] + beta * (x[o + 1] - x_prev[o + 1])
        y2 = x[o + 2] + beta * (x[o + 2] - x_prev[o + 2])
        y3 = x[o + 3] + beta * (x[o + 3] - x_prev[o + 3])
        y4 = x[o + 4] + beta * (x[o + 4] - x_prev[o + 4])
        p, q1, q2, r1, r2 = project_point_on_device(y0 - step * g[o], y1 - step * g[o + 1], y2 - step * g[o + 2],
                                                    y3 - step * g[o + 3], y4 - step * g[o + 4], mu_s[k], mu_r_s[k])
        x_new[o], x_new[o + 1], x_new[o + 2], x_new[o + 3], x_new[o + 4] = p, q1, q2, r1, r2
        moved[t] = ((p - y0) * (p - y0) + (q1 - y1) * (q1 - y1) + (q2 - y2) * (q2 - y2)
                    + (r1 - y3) * (r1 - y3) + (r2 - y4) * (r2 - y4))
        uphill[t] = (g[o] * (p - x[o]) + g[o + 1] * (q1 - x[o + 1]) + g[o + 2] * (q2 - x[o + 2])
                     + g[o + 3] * (r1 - x[o + 3]) + g[o + 4] * (r2 - x[o + 4]))
    block_reduce(moved, t, False)
    block_reduce(uphill, t, False)
    if t == 0:
        parts[0, cuda.blockIdx.x] = moved[0]
        parts[1, cuda.blockIdx.x] = uphill[0]


@cuda.jit
def _weighted_change_kernel(h_new, hy, inv_mass, parts):
    """parts[2] (per block): ||h_new - hy||^2 weighted by inv_mass (colsim.solvers.apgd._weighted_change)."""
    cache = cuda.shared.array(THREADS, dtype=np.float64)
    i = cuda.grid(1)
    t = cuda.threadIdx.x
    cache[t] = 0.0
    if i < h_new.shape[0]:
        dh = h_new[i] - hy[i]
        cache[t] = dh * dh * inv_mass[i]
    block_reduce(cache, t, False)
    if t == 0:
        parts[2, cuda.blockIdx.x] = cache[0]


@cuda.jit
def _extrapolate_kernel(hy, h_new, hx, beta):
    """hy = h_new + beta (h_new - hx), one entry a thread."""
    i = cuda.grid(1)
    if i < hy.shape[0]:
        hy[i] = h_new[i] + beta * (h_new[i] - hx[i])


@cuda.jit
def _residual_kernel(g, x, s, mu, mu_r, parts):
    """parts[0..3] (per block): the largest cone violation of the gaps y = g / s and of the forces
    lam = s x, the sum of the positive normal forces and sum_k |lam_k . y_k|
    (colsim.engine.cones._residual_parts)."""
    primal = cuda.shared.array(THREADS, dtype=np.float64)
    dual = cuda.shared.array(THREADS, dtype=np.float64)
    total = cuda.shared.array(THREADS, dtype=np.float64)
    comp = cuda.shared.array(THREADS, dtype=np.float64)
    k = cuda.grid(1)
    t = cuda.threadIdx.x
    primal[t] = -math.inf
    dual[t] = -math.inf
    total[t] = 0.0
    comp[t] = 0.0
    if k < mu.shape[0]:
        o = 5 * k
        y0, y1, y2 = g[o] / s[o], g[o + 1] / s[o + 1], g[o + 2] / s[o + 2]
        y3, y4 = g[o + 3] / s[o + 3], g[o + 4] / s[o + 4]
        p, q1, q2 = s[o] * x[o], s[o + 1] * x[o + 1], s[o + 2] * x[o + 2]
        r1, r2 = s[o + 3] * x[o + 3], s[o + 4] * x[o + 4]
        primal[t] = mu[k] * math.sqrt(y1 * y1 + y2 * y2) + mu_r[k] * math.sqrt(y3 * y3 + y4 * y4) - y0
        dual[t] = max(math.sqrt(q1 * q1 + q2 * q2) - mu[k] * p, math.sqrt(r1 * r1 + r2 * r2) - mu_r[k] * p, -p)
        total[t] = max(p, 0.0)
        comp[t] = abs(p * y0 + q1 * y1 + q2 * y2 + r1 * y3 + r2 * y4)
    block_reduce(primal, t, True)
    block_reduce(dual, t, True)
    block_reduce(total, t, False)
    block_reduce(comp, t, False)
    if t == 0:
        b = cuda.blockIdx.x
        parts[0, b], parts[1, b], parts[2, b], parts[3, b] = primal[0], dual[0], total[0], comp[0]


# -- the kernel set APGD's control flow drives (colsim.solvers.apgd.apgd_iterations) ------------

def trial_step(x, x_prev, beta, g, x_new, step, h_new, hy, geometry, mu_s, mu_r_s, inv_mass, parts):
    """The projection, h_new = T x_new and the descent test's sums, on the device; returns
    (||x_new - y||^2, g . (x_new - x), ||h_new - hy||^2_{Mbar^-1}), summed in block order on the host."""
    _project_kernel[blocks_for(mu_s.shape[0]), THREADS](x, x_prev, beta, g, x_new, step, mu_s, mu_r_s, parts)
    transpose_on_device(geometry, x_new, h_new)
    _weighted_change_kernel[blocks_for(h_new.shape[0]), THREADS](h_new, hy, inv_mass, parts)
    sums = parts.copy_to_host().sum(axis=1)   # entries past a kernel's blocks stay zero
    return float(sums[0]), float(sums[1]), float(sums[2])


def extrapolate(hy, h_new, hx, beta):
    _extrapolate_kernel[blocks_for(hy.shape[0]), THREADS](hy, h_new, hx, beta)


def gradient(hy, inv_mass, geometry, c, g):
    gradient_on_device(geometry, hy, inv_mass, c, g)


#: APGD's iterations on the device: the one control flow, driving this module's kernels
iterate = apgd_iterations(trial_step, extrapolate, gradient)


class CudaIteration:
    """The APGD state on the device, from its start on the host (a :class:`colsim.solvers.apgd._Iteration`
    built on the program's CPU operator: the scaling, the first iterate and the Lipschitz estimate):
    the same fields, as device arrays, and the same methods the solver calls."""

    def __init__(self, start, operator, mu, mu_r):
        self.scaling = start.scaling
        self.m = len(start.mu_s)
        device = CudaContactOperator.from_operator(operator)
        self.geometry = device.geometry(cuda.to_device(np.ascontiguousarray(start.scaling.ravel())))
        for name in ("x", "x_prev", "hx", "hy", "g", "x_new", "h_new", "c", "mu_s", "mu_r_s", "inv_mass"):
            setattr(self, name, cuda.to_device(np.ascontiguousarray(getattr(start, name), dtype=float)))
        self.mu = cuda.to_device(np.ascontiguousarray(mu, dtype=float))
        self.mu_r = cuda.to_device(np.ascontiguousarray(mu_r, dtype=float))
        self.beta, self.theta, self.lip, self.lip_decay = start.beta, start.theta, start.lip, start.lip_decay
        self.backtracks = self.restarts = 0
        # the trial step's blocks' sums: its kernels write their own blocks, the rest stay zero
        self.parts = cuda.to_device(np.zeros((3, max(blocks_for(self.m), blocks_for(len(start.hx))))))
        self.residual_parts = cuda.device_array((4, blocks_for(self.m)), dtype=np.float64)
        self.gap = cuda.device_array(5 * self.m, dtype=np.float64)

    def iterate(self, n: int):
        (self.x, self.x_prev, self.x_new, self.hx, self.h_new, self.theta, self.beta, self.lip, bt,
         rs) = iterate(n, self.x, self.x_prev, self.beta, self.hx, self.hy, self.g, self.x_new, self.h_new,
                             self.theta, self.lip, self.geometry, self.c, self.mu_s, self.mu_r_s, self.inv_mass,
                             self.lip_decay, self.parts)
        self.backtracks += bt
        self.restarts += rs

    def residuals(self, mu, mu_r, scale: float, floor: float) -> dict[str, float]:
        """The relative residuals at the iterate (colsim.engine.cones.relative_residuals), on the
        device; mu, mu_r: the program's (those given at construction are used)."""
        gradient_on_device(self.geometry, self.hx, self.inv_mass, self.c, self.gap)
        _residual_kernel[blocks_for(self.m), THREADS](self.gap, self.x, self.geometry.s, self.mu, self.mu_r,
                                                      self.residual_parts)
        parts = self.residual_parts.copy_to_host()
        return combine_residuals(max(0.0, float(parts[0].max())), max(0.0, float(parts[1].max())),
                                 float(parts[2].sum()), float(parts[3].sum()), self.m, scale, floor)

    def host_x(self) -> np.ndarray:
        """(5m,) the scaled iterate z on the host."""
        return self.x.copy_to_host()
