"""`colsim` with the CPU's compiled kernels allowed to fuse a * b + c into one rounding (an FMA), as a
GPU's compiler does: the same algorithm on the same processor, rounded another way (issue 46, the
run-out at r0 = 3, a = 2; `benchmarks scatter --fused`).

    python benchmarks/fused.py collapse --settings S --input COLUMN --output OUT ...
    COLSIM_FUSED_MODULES=colsim.solvers python benchmarks/fused.py collapse ...   # those kernels only

Every kernel colsim compiles with `numba.njit` (or, with $COLSIM_FUSED_MODULES, a comma-separated
list of module prefixes, each kernel defined there) gets LLVM's `contract` flag and no other fast-math
liberty (no reassociation: a sum's order, the parallel reductions' included, stays as written), so a
product and the sum that reads it may become one fused multiply-add where the processor has one
(this project's AMD EPYC has). numba.cuda's kernels on a card contract the same way by default; the
numpy work on the host, and numba's simulator, do not. The kernels compile into their own cache
folder (numba's cache keys do not hold the flags), so a fused run never loads a plain one's code. A
kernel inlined into another (`inline="always"`, the cone's projection in APGD's step) is compiled
with its caller's flags.
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

#: the environment variable naming the modules whose kernels fuse (unset or empty: every module)
MODULES = "COLSIM_FUSED_MODULES"


def cache_folder(modules: tuple[str, ...]) -> Path:
    """The fused kernels' numba cache, apart from the plain ones' (__pycache__ beside the sources) and
    from another module list's."""
    return Path(tempfile.gettempdir()) / "-".join(["colsim-numba-fused", *modules])


def contracting(njit, modules: tuple[str, ...] = ()):
    """numba.njit with fastmath={"contract"} added to what the caller asks (fastmath=True kept), for
    the kernels defined in a module whose name starts with one of `modules` (empty: every kernel)."""

    def options_for(function, options: dict) -> dict:
        chosen = not modules or function.__module__.startswith(modules)
        if chosen and options.get("fastmath") is not True:
            options = {**options, "fastmath": set(options.get("fastmath") or ()) | {"contract"}}
        return options

    def fused(*args, **options):
        if args and callable(args[0]):             # njit(function, **options)
            return njit(args[0], *args[1:], **options_for(args[0], options))
        return lambda function: njit(*args, **options_for(function, options))(function)

    return fused


def main(argv=None) -> int:
    modules = tuple(name for name in os.environ.get(MODULES, "").split(",") if name)
    os.environ["NUMBA_CACHE_DIR"] = str(cache_folder(modules))   # before numba reads its configuration
    import numba

    numba.njit = contracting(numba.njit, modules)   # before colsim compiles (on import) anything
    from colsim.cli.entry import main as colsim

    return colsim(argv)


if __name__ == "__main__":
    sys.exit(main())
