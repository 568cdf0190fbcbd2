"""`colsim` with numba.cuda's kernels compiled without fused multiply-adds (libNVVM's `-fma=0`): the
GPU rounding as the plain CPU does, fused.py's converse (issue 46, the run-out at r0 = 3, a = 2;
`benchmarks scatter --device cuda --unfused`).

    python benchmarks/unfused.py collapse --settings S --input COLUMN --output OUT --device cuda ...
    python benchmarks/unfused.py --check    # on a card: one kernel's a * b + c, default and unfused

libNVVM fuses a product and the sum that reads it into one FMA (one rounding instead of two) unless
given `-fma=0`, and numba-cuda passes no such option (its fastmath turns fma on). Here every kernel's
NVVM options get fma=False, except a kernel's that asks for fastmath (colsim's ask for none). The
kernels compile into their own numba cache folder, so an unfused run never loads a default one's code.
On numba's simulator there is no NVVM and nothing changes.
"""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path


def cache_folder() -> Path:
    """The unfused kernels' numba cache, apart from the default ones' (__pycache__ beside the sources)."""
    return Path(tempfile.gettempdir()) / "colsim-numba-unfused"


def without_fma(compile_ir):
    """numba.cuda's `nvvm.compile_ir(llvmir, **options)` with `fma=False` added to the options of every
    compilation that does not ask for fastmath."""

    def compile_unfused(llvmir, **options):
        if not options.get("fastmath"):
            options = {**options, "fma": False}
        return compile_ir(llvmir, **options)

    return compile_unfused


def unfuse() -> None:
    """Make every numba.cuda kernel compiled from now on unfused (before colsim launches any)."""
    from numba.cuda.cudadrv import nvvm   # numba.cuda's codegen calls nvvm.compile_ir through the module

    nvvm.compile_ir = without_fma(nvvm.compile_ir)


@contextlib.contextmanager
def unfused_compilation():
    """Every numba.cuda compilation inside the block unfused (:func:`unfuse`), the default after it."""
    from numba.cuda.cudadrv import nvvm

    default = nvvm.compile_ir
    unfuse()
    try:
        yield
    finally:
        nvvm.compile_ir = default


def check() -> int:
    """On a card: a * b + c with a * b = 1 - 2**-60 exactly and c = -1, from a kernel compiled by default
    and one compiled unfused. Fused it is -2**-60, rounded first 0. Prints both; exit 1 if the unfused
    kernel fused."""
    import numpy as np
    from numba import cuda

    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1" or not cuda.is_available():
        print("unfused check: no card (or numba's simulator): nothing to compile")
        return 0

    def multiply_add(a, b, c, out):
        out[0] = a[0] * b[0] + c[0]

    values = [np.array([v]) for v in (1.0 + 2.0 ** -30, 1.0 - 2.0 ** -30, -1.0)]
    results = {}
    for name in ("default", "unfused"):
        if name == "unfused":
            unfuse()
        kernel = cuda.jit(multiply_add)     # a new dispatcher: compiled at its first launch, after unfuse()
        out = cuda.to_device(np.zeros(1))
        kernel[1, 1](*(cuda.to_device(v) for v in values), out)
        results[name] = float(out.copy_to_host()[0])
    print(f"unfused check: a * b + c = {results['default']!r} by default (fused: {-(2.0 ** -60)!r}), "
          f"{results['unfused']!r} with -fma=0 (rounded first: 0.0)")
    return 0 if results["unfused"] == 0.0 else 1


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    os.environ["NUMBA_CACHE_DIR"] = str(cache_folder())   # before numba reads its configuration
    if argv == ["--check"]:
        return check()
    unfuse()
    from colsim.cli.entry import main as colsim

    return colsim(argv)


if __name__ == "__main__":
    sys.exit(main())
