"""The contact operator's products on a GPU against the CPU kernels: B' S z then S B Mbar^-1 h, the
pair of products an APGD iteration makes, per call.

    python -m benchmarks cuda_operator --spheres 73000 704000 2000000 --repeat 20

The column is synthetic, as in `benchmarks gpu`'s lattices: a jittered cubic lattice of spheres (diameter
0.375, spacing 0.376) in a box of aspect ratio 5, each sphere in contact with its lattice neighbours
along +x, +y and +z (about 3 contacts a sphere), frames and radii as colsim's detection makes them.
CPU: colsim.engine.operator on the process's numba threads (NUMBA_NUM_THREADS, all cores by default),
best of --repeat calls, wall time. GPU: colsim.engine.cuda_operator with every vector on the device,
best of --repeat calls between two synchronisations. Beside the times, the largest difference of the
two B' S z over its largest entry. Without a GPU the CUDA kernels run on numba's simulator (set
NUMBA_ENABLE_CUDASIM=1): only to check the script, at a few hundred spheres; its times mean nothing.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import record
from colsim.engine.contacts import Contacts, tangent_basis
from colsim.engine.operator import ContactOperator, apply_gradient
from colsim.engine.threads import threads

DIAMETER = 0.375
SPACING = 0.376


def lattice_positions(spheres: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(positions (n, 3), the lattice's shape (3,)): a jittered cubic lattice of spacing SPACING,
    about `spheres` sites, aspect ratio 5."""
    side = max(2, round((spheres / 5) ** (1 / 3)))
    shape = np.array([side, side, 5 * side])
    n = int(np.prod(shape))
    lattice = np.stack(np.meshgrid(*(np.arange(k) for k in shape), indexing="ij"), axis=-1).reshape(n, 3)
    return lattice * SPACING + np.random.default_rng(seed).uniform(-0.002, 0.002, (n, 3)), shape


def lattice_contacts(spheres: int, seed: int = 0) -> tuple[Contacts, int]:
    """(contacts, n): the column of :func:`lattice_positions`, contacts with the +x, +y, +z lattice
    neighbours."""
    position, shape = lattice_positions(spheres, seed)
    n = len(position)
    index = np.arange(n).reshape(shape)
    first, second = [], []
    for axis in range(3):
        lead = [slice(None)] * 3
        lag = [slice(None)] * 3
        lead[axis], lag[axis] = slice(0, -1), slice(1, None)
        first.append(index[tuple(lead)].ravel())
        second.append(index[tuple(lag)].ravel())
    i, j = np.concatenate(first), np.concatenate(second)
    d = position[j] - position[i]
    normal = d / np.linalg.norm(d, axis=1)[:, None]
    t1, t2 = tangent_basis(normal)
    m = len(i)
    radius = np.full(m, DIAMETER / 2)
    contacts = Contacts(i=i, j=j, family=np.zeros(m, dtype=np.int64), normal=normal, tangent1=t1, tangent2=t2,
                        gap=np.linalg.norm(d, axis=1) - DIAMETER, radius_i=radius, radius_j=radius,
                        lever=radius.copy(), mu=np.full(m, 0.577), mu_r=np.full(m, 0.12))
    return contacts, n


def best_of(repeat: int, call) -> float:
    """The shortest of `repeat` wall times of call() (seconds), after one call to warm up."""
    call()
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        best = min(best, time.perf_counter() - start)
    return best


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spheres", type=int, nargs="+", default=[73_000, 704_000, 2_000_000])
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args(argv)
    from numba import cuda
    from numba.core import config as numba_config

    from colsim.engine.cuda_operator import CudaContactOperator

    table = record.table(["spheres", "contacts", f"CPU ms ({threads()} threads)", "GPU ms", "GPU vs CPU",
                          "B' S z difference / largest"])
    for spheres in args.spheres:
        contacts, n = lattice_contacts(spheres)
        rng = np.random.default_rng(1)
        z, s = rng.standard_normal(5 * contacts.m), rng.uniform(0.5, 2.0, 5 * contacts.m)
        inv_mass, c = rng.uniform(0.5, 2.0, 6 * n), rng.standard_normal(5 * contacts.m)
        cpu, gpu = ContactOperator(contacts, n), CudaContactOperator(contacts, n)
        h_cpu, g_cpu = np.empty(6 * n), np.empty(5 * contacts.m)

        def on_cpu():
            h_cpu[:] = cpu.transpose(z, s)
            apply_gradient(h_cpu, inv_mass, s, *cpu.frames(), c, g_cpu)

        device = {name: cuda.to_device(value) for name, value in
                  (("z", z), ("s", s), ("inv_mass", inv_mass), ("c", c))}
        h_gpu, g_gpu = cuda.device_array(6 * n), cuda.device_array(5 * contacts.m)

        def on_gpu():
            gpu.transpose_on_device(device["z"], device["s"], h_gpu)
            gpu.apply_on_device(h_gpu, g_gpu, device["inv_mass"], device["s"], device["c"])
            cuda.synchronize()

        cpu_s, gpu_s = best_of(args.repeat, on_cpu), best_of(args.repeat, on_gpu)
        difference = float(np.max(np.abs(h_gpu.copy_to_host() - h_cpu)) / np.max(np.abs(h_cpu)))
        table.row(n, contacts.m, f"{1e3 * cpu_s:.2f}", f"{1e3 * gpu_s:.2f}", f"{cpu_s / gpu_s:.1f}",
                  f"{difference:.1e}",
                  data={"spheres": n, "contacts": contacts.m, "cpu_ms": 1e3 * cpu_s, "gpu_ms": 1e3 * gpu_s,
                        "cpu_threads": threads(), "simulator": bool(numba_config.ENABLE_CUDASIM),
                        "relative_difference": difference})


if __name__ == "__main__":
    record.run("cuda_operator", main)
