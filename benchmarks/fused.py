"""`colsim` with the CPU's compiled kernels allowed to fuse a * b + c into one rounding (an FMA), as a
GPU's compiler does: the same algorithm on the same processor, rounded another way (issue 46, the
run-out at r0 = 3, a = 2; `benchmarks scatter --fused`).

    python benchmarks/fused.py collapse --settings S --input COLUMN --output OUT ...

Every kernel colsim compiles with `numba.njit` gets LLVM's `contract` flag and no other fast-math
liberty (no reassociation: a sum's order, the parallel reductions' included, stays as written), so a
product and the sum that reads it may become one fused multiply-add where the processor has one
(this project's AMD EPYC has). numba.cuda's kernels on a card contract the same way by default; the
numpy work on the host, and numba's simulator, do not. The kernels compile into their own cache
folder (numba's cache keys do not hold the flags), so a fused run never loads a plain one's code.
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

#: the fused kernels' numba cache, apart from the plain ones' (__pycache__ beside the sources)
CACHE = Path(tempfile.gettempdir()) / "colsim-numba-fused"


def contracting(njit):
    """numba.njit with fastmath={"contract"} added to what the caller asks (fastmath=True kept)."""

    def fused(*args, **options):
        if options.get("fastmath") is not True:
            options["fastmath"] = set(options.get("fastmath") or ()) | {"contract"}
        return njit(*args, **options)

    return fused


def main(argv=None) -> int:
    os.environ["NUMBA_CACHE_DIR"] = str(CACHE)   # before numba reads its configuration
    import numba

    numba.njit = contracting(numba.njit)          # before colsim compiles (on import) anything
    from colsim.cli.entry import main as colsim

    return colsim(argv)


if __name__ == "__main__":
    sys.exit(main())
