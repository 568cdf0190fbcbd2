"""Every CUDA kernel a GPU collapse launches, compiled for a card without one: the check numba's
simulator cannot make (it runs a kernel's Python; it never types or compiles it), and how many fused
multiply-adds each kernel holds (the card's rounding, docs/solvers.md).

    python -m benchmarks ptx                 # sm_90 (H100, H200): no card; numba-cuda and libNVVM
    python -m benchmarks ptx --cc 8.0        # another compute capability

First, two steps of `colsim collapse --device cuda` on numba's simulator, with each of APGD's
storages (`--gpu-storage`; a 27-sphere column poured on the CPU: a pour on the simulator takes many
minutes, and `colsim pack --device cuda` steps with the same stepper) record the types of every kernel
launch's arguments (colsim's kernels only). Then,
with the simulator off, each kernel is compiled with each of its argument types by
`numba.cuda.compile_ptx` (libNVVM; no driver, no card). The table: each kernel, its signatures, its
PTX's double-precision instructions, and how many of them are fused multiply-adds (fma.rn.f64); where CUDA's ptxas is at hand (CUDA_HOME/bin, or PATH), also the registers a thread and
the bytes spilled that ptxas gives the default PTX for the card, and for sm_90 how many threads an SM
then holds in blocks of 256 (of 2,048: the registers are what limits a large kernel's occupancy).
It needs numba-cuda, the compiler a card's run uses (`pip install -e .[gpu]`; numba's own deprecated
numba.cuda fails to type some of the kernels, e.g. `max` in a device function, which numba-cuda
compiles), and libNVVM (a CUDA toolkit, e.g. CUDA_HOME=/usr/local/cuda).
Exit 1 if a kernel does not compile.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import pickle
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import record

#: the column the launches are recorded on: a 27-sphere pour (r0 = 0.8), trimmed at a = 1
POUR = ["pack", "--r0", "0.8", "--height", "0.8", "--seed", "1"]
COLLAPSE = ["collapse", "--steps", "2", "--duration", "0.008", "--device", "cuda"]


def argument_type(value):
    """The numba type a launch on a card gives `value` (a simulator's array typed as its numpy array,
    never read-only: device arrays are not)."""
    import numba
    from numba import types
    from numba.cuda.simulator.cudadrv.devicearray import FakeCUDAArray

    if isinstance(value, FakeCUDAArray):
        value = value._ary
    found = numba.typeof(value)
    if isinstance(found, types.Array):
        return types.Array(found.dtype, found.ndim, found.layout)
    return found


def record_launches(folder: Path) -> dict[tuple[str, str], set]:
    """{(module, kernel name): {argument types, one tuple per distinct launch}} of colsim's kernels in
    a GPU collapse on numba's simulator (NUMBA_ENABLE_CUDASIM=1 in this process)."""
    from numba.cuda.simulator import kernel as simulated

    from colsim.cli.entry import main as colsim
    from colsim.solvers.defaults import GPU_STORAGES

    launches: dict[tuple[str, str], set] = {}
    call = simulated.FakeCUDAKernel.__call__

    def recorded(self, *args):
        if not self._device and self.fn.__module__.startswith("colsim."):
            launches.setdefault((self.fn.__module__, self.fn.__name__), set()).add(
                tuple(argument_type(a) for a in args))
        return call(self, *args)

    simulated.FakeCUDAKernel.__call__ = recorded
    try:
        for argv in ([*POUR, "--output", str(folder / "pack.nc")],
                     ["trim", "--input", str(folder / "pack.nc"), "--aspect-ratio", "1",
                      "--output", str(folder / "column.nc")],
                     *([*COLLAPSE, "--gpu-storage", storage, "--input", str(folder / "column.nc"),
                        "--output", str(folder / f"collapse-{storage}.nc")] for storage in GPU_STORAGES)):
            if colsim(["-q", *argv]):
                raise RuntimeError(f"colsim {' '.join(argv)} failed")
    finally:
        simulated.FakeCUDAKernel.__call__ = call
    return launches


def ptx_of(function, signature, cc: tuple[int, int], **options) -> str:
    """`function` compiled to PTX for `cc` with argument types `signature` (numba-cuda's compile_ptx:
    libNVVM, no driver, no card)."""
    from numba import cuda

    return cuda.compile_ptx(function, signature, cc=cc, **options)[0]


def f64_of(ptx: str) -> list[str]:
    """The double-precision instructions of a PTX text, in order."""
    return [line.split()[0] for line in ptx.splitlines() if line.split() and line.split()[0].endswith(".f64")]


#: an SM of compute capability 9.0 (H100, H200): its registers, the most warps it holds, and a warp's
#: registers are allotted in units of this many (CUDA's occupancy calculator)
SM_REGISTERS, SM_WARPS, REGISTER_UNIT = 65_536, 64, 256


def ptxas() -> str | None:
    """CUDA's PTX assembler: CUDA_HOME's, else the one on PATH, else None."""
    home = os.environ.get("CUDA_HOME") or os.environ.get("CUDA_PATH") or "/usr/local/cuda"
    found = Path(home) / "bin" / "ptxas"
    return str(found) if found.exists() else shutil.which("ptxas")


def resources(ptx: str, cc: tuple[int, int]) -> dict | None:
    """What ptxas makes of a kernel's PTX for sm_<cc>: {registers (a thread), spill_stores,
    spill_loads (bytes a thread)}; None without ptxas. A PTX newer than this ptxas (libNVVM's wheel
    can be) is assembled with its .version line set to the newest this ptxas names (numba's kernels
    use nothing newer)."""
    assembler = ptxas()
    if assembler is None:
        return None
    with tempfile.TemporaryDirectory(prefix="ptxas-") as scratch:
        path = Path(scratch) / "kernel.ptx"
        for _ in range(2):
            path.write_text(ptx)
            done = subprocess.run([assembler, f"-arch=sm_{cc[0]}{cc[1]}", "-v", str(path), "-o", os.devnull],
                                  capture_output=True, text=True)
            newest = re.search(r"Unsupported \.version \S+; current version is '([\d.]+)'", done.stderr)
            if done.returncode == 0 or newest is None:
                break
            ptx = re.sub(r"^\.version \S+", f".version {newest.group(1)}", ptx, count=1, flags=re.M)
    registers = re.search(r"Used (\d+) registers", done.stderr)
    spills = re.search(r"(\d+) bytes spill stores, (\d+) bytes spill loads", done.stderr)
    if done.returncode or registers is None:
        raise RuntimeError(f"ptxas: {done.stderr.strip()[-300:]}")
    return {"registers": int(registers.group(1)), "spill_stores": int(spills.group(1)) if spills else 0,
            "spill_loads": int(spills.group(2)) if spills else 0}


def threads_an_sm(registers: int, block: int = 256) -> int:
    """The threads an SM of compute capability 9.0 holds of a kernel with `registers` a thread in blocks
    of `block` threads, as its registers allow (whole blocks; shared memory not counted)."""
    per_warp = -(-registers * 32 // REGISTER_UNIT) * REGISTER_UNIT
    warps = min(SM_WARPS, SM_REGISTERS // per_warp)
    return (warps // (block // 32)) * block


def compiled(launches: dict, cc: tuple[int, int]) -> list[dict]:
    """Each kernel compiled to PTX with each of its argument types (with the simulator off in this
    process): {module, kernel, signatures, f64 instructions, fma, registers, spills, error}."""
    from types import SimpleNamespace

    from numba.cuda import dispatcher

    # a device function a kernel calls compiles for the current device's compute capability: with no
    # driver, for `cc`
    dispatcher.get_current_device = lambda: SimpleNamespace(compute_capability=cc)
    rows = []
    for (module, name), signatures in sorted(launches.items()):
        row = {"module": module, "kernel": name, "signatures": len(signatures), "f64": 0, "fma": 0,
               "registers": None, "spill_stores": None, "spill_loads": None, "error": ""}
        try:
            function = getattr(importlib.import_module(module), name).py_func
            for signature in signatures:
                ptx = ptx_of(function, signature, cc)
                fused = f64_of(ptx)
                used = resources(ptx, cc)
                for key, value in (used or {}).items():   # the most over the kernel's signatures
                    row[key] = max(row[key] or 0, value)
                row["f64"] += len(fused)
                row["fma"] += fused.count("fma.rn.f64")
        except Exception as error:   # a kernel that does not compile is this check's finding
            row["error"] = f"{type(error).__name__}: {str(error).splitlines()[0][:200]}"
        rows.append(row)
    return rows


def nvvm_missing() -> str:
    """Why libNVVM cannot be loaded here, or "" (it can)."""
    try:
        from numba.cuda.cudadrv import nvvm

        nvvm.NVVM()
    except Exception as error:   # numba's NvvmSupportError, or ctypes' OSError
        return f"no libNVVM here ({str(error).strip()[:200]}): a CUDA toolkit, e.g. CUDA_HOME=/usr/local/cuda"
    return ""


def compiler_missing() -> str:
    """Why a card's kernels cannot be compiled here, or "" (numba-cuda and libNVVM are installed)."""
    try:
        import numba_cuda  # noqa: F401   numba-cuda, not numba's own deprecated numba.cuda
    except ImportError:
        return "no numba-cuda here: `pip install -e .[gpu]` (numba-cuda, the compiler of a card's runs)"
    return nvvm_missing()


def child(phase: str, folder: Path, cc: str) -> None:
    """Run this file's `phase` in a child process: "record" on the simulator, "compile" without."""
    environment = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1" if phase == "record" else "0"}
    done = subprocess.run([sys.executable, __file__, "--phase", phase, "--folder", str(folder), "--cc", cc],
                          capture_output=True, text=True, env=environment)
    if done.returncode:
        raise RuntimeError(f"the {phase} phase failed:\n{done.stderr[-3000:]}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cc", default="9.0", help="the compute capability compiled for (H100, H200: 9.0)")
    parser.add_argument("--phase", choices=("record", "compile"), help=argparse.SUPPRESS)
    parser.add_argument("--folder", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    cc = tuple(int(part) for part in args.cc.split("."))
    if args.phase == "record":
        launches = record_launches(args.folder)
        (args.folder / "launches.pickle").write_bytes(pickle.dumps(launches))
        return 0
    if args.phase == "compile":
        missing = compiler_missing()
        if missing:
            sys.exit(missing)
        launches = pickle.loads((args.folder / "launches.pickle").read_bytes())
        (args.folder / "compiled.json").write_text(json.dumps(compiled(launches, cc)))
        return 0
    with tempfile.TemporaryDirectory(prefix="ptx-") as scratch:
        folder = Path(scratch)
        child("record", folder, args.cc)
        child("compile", folder, args.cc)
        rows = json.loads((folder / "compiled.json").read_text())
    table = record.table(["kernel", "signatures", "f64 instructions", "fma.rn.f64",
                          f"registers a thread (ptxas, sm_{cc[0]}{cc[1]})", "spilled bytes stored, loaded",
                          "threads an SM by registers (blocks of 256)", "error"],
                         title=f"colsim's CUDA kernels compiled to PTX for sm_{cc[0]}{cc[1]}")
    for row in rows:
        known = row.get("registers") is not None
        table.row(f"{row['module'].rsplit('.', 1)[-1]}.{row['kernel']}", row["signatures"], row["f64"], row["fma"],
                  row["registers"] if known else "-",
                  f"{row['spill_stores']}, {row['spill_loads']}" if known else "-",
                  threads_an_sm(row["registers"]) if known and cc == (9, 0) else "-", row["error"], data=row)
    failed = [row["kernel"] for row in rows if row["error"]]
    print(f"{len(rows)} kernels, {sum(row['signatures'] for row in rows)} signatures; "
          f"{sum(row['fma'] for row in rows)} FMAs")
    if failed:
        raise SystemExit(f"{len(failed)} kernels failed: {', '.join(failed)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
