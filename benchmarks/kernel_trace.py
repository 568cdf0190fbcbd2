"""Where a command's GPU time goes, kernel by kernel, and where the card waits between kernels.

    python -m benchmarks kernel_trace [--cprofile FILE] [--summary FILE] MODULE [ARGS...]
    python -m benchmarks kernel_trace colsim.cli collapse --device cuda --input column.nc ...

Runs the module as `python -m MODULE ARGS...` would, in this process, under PyTorch's profiler with
its CUDA activity alone: the card's own record of every kernel and copy (CUPTI), whoever launched
it, numba-cuda's kernels included. Then prints, over the window from the first kernel's start to
the last one's end (the imports before it left out):

- the window's wall, the share of it in which a kernel ran (the union of the kernels' intervals; on
  one stream they do not overlap) and in which a copy ran: the share "kernels at least 80 % of a
  step" asks for, read on the card rather than sampled by NVML;
- the card's idle gaps by length: many short ones mean launch-bound steps (the host's launches
  pace the card), a few long ones the host's own work or a wait (a compilation, a file written);
- the kernels with the most GPU time: launches, total ms, mean us, share of the window.

With --cprofile FILE the command also runs under cProfile (statistics to FILE), so the host's side
of the same run is at hand. A SIGTERM (`timeout`) ends the command as Ctrl-C would, and both are
still written. Needs torch with CUDA, and a GPU (the GPU machines' image has both); elsewhere the
command runs as it would and the summary says why there is no trace. The summary's tables go to
stdout, or to --summary FILE, so that a command's log ends with the command's own lines.
"""
from __future__ import annotations

import argparse
import contextlib
import cProfile
import json
import os
import runpy
import signal
import sys
import tempfile

import numpy as np

import record

#: the idle gaps' classes (upper bounds, us): launch latency, a launch's marshalling, host work, waits
GAP_BOUNDS_US = (10.0, 100.0, 1_000.0, 10_000.0, 100_000.0, float("inf"))
#: a gap at least this long (us) is not a step's own wait but a kernel's compilation, a file written,
#: a frame: the "steady" busy share leaves such gaps out of the window
LONG_GAP_US = 100_000.0


def union_us(intervals: np.ndarray) -> float:
    """Total length (us) of the union of intervals (k, 2) = (start, end): their span less the idle gaps."""
    if len(intervals) == 0:
        return 0.0
    return float(intervals[:, 1].max() - intervals[:, 0].min() - idle_gaps_us(intervals).sum())


def idle_gaps_us(intervals: np.ndarray) -> np.ndarray:
    """The idle gaps (us) between the union's pieces of intervals (k, 2), in time order."""
    if len(intervals) < 2:
        return np.zeros(0)
    order = np.argsort(intervals[:, 0], kind="stable")
    start, end = intervals[order, 0], np.maximum.accumulate(intervals[order, 1])
    gaps = start[1:] - end[:-1]
    return gaps[gaps > 0.0]


def summarise(kernels: list, copies: list, top: int = 25) -> dict:
    """The card's busy shares, idle gaps and top kernels from the kernels' and copies' (name, start
    us, duration us) lists: window_us (first start to last end of either), kernel_busy and copy_busy
    (shares of the window), kernel_busy_steady (the share of the window less its gaps of at least
    :data:`LONG_GAP_US`), gaps (per class of :data:`GAP_BOUNDS_US`: count, total us), and by_kernel
    (name, launches, total us), the `top` largest totals first."""
    everything = kernels + copies
    if not everything:
        return {"window_us": 0.0, "kernels": 0, "copies": 0}

    def intervals(events):
        return np.array([(s, s + d) for _, s, d in events], dtype=float).reshape(-1, 2)

    both = intervals(everything)
    window = float(both[:, 1].max() - both[:, 0].min())
    gaps = idle_gaps_us(both)
    classes, lower = [], 0.0
    for bound in GAP_BOUNDS_US:
        chosen = gaps[(gaps >= lower) & (gaps < bound)]
        classes.append({"from_us": lower, "to_us": bound, "count": int(len(chosen)), "total_us": float(chosen.sum())})
        lower = bound
    totals: dict = {}
    for name, _, duration in kernels:
        launches, total = totals.get(name, (0, 0.0))
        totals[name] = (launches + 1, total + duration)
    by_kernel = sorted(((name, n, total) for name, (n, total) in totals.items()), key=lambda row: -row[2])
    steady = window - float(gaps[gaps >= LONG_GAP_US].sum())
    kernel_time = union_us(intervals(kernels))
    return {"window_us": window, "kernels": len(kernels), "copies": len(copies),
            "kernel_busy": kernel_time / window if window else float("nan"),
            "kernel_busy_steady": kernel_time / steady if steady else float("nan"),
            "copy_busy": union_us(intervals(copies)) / window if window else float("nan"),
            "any_busy": union_us(both) / window if window else float("nan"),
            "gaps": classes, "by_kernel": by_kernel[:top], "kernel_names": len(totals)}


def read_chrome_trace(path: str) -> tuple[list, list]:
    """(kernels, copies), each a list of (name, start us, duration us), from a Chrome trace that
    PyTorch's profiler exported: its events of category "kernel", and "gpu_memcpy" or "gpu_memset"."""
    with open(path) as f:
        events = json.load(f)
    events = events.get("traceEvents", []) if isinstance(events, dict) else events
    kernels, copies = [], []
    for event in events:
        if event.get("ph") != "X":
            continue
        row = (str(event.get("name", "")), float(event.get("ts", 0.0)), float(event.get("dur", 0.0)))
        category = str(event.get("cat", "")).lower()
        if category == "kernel":
            kernels.append(row)
        elif category in ("gpu_memcpy", "gpu_memset"):
            copies.append(row)
    return kernels, copies


def short_name(name: str) -> str:
    """A numba-cuda kernel's readable name: `cuda_state._inverse_kernel` from its mangled
    `_ZN6colsim6engine10cuda_state15_inverse_kernelB2v1...E5ArrayIdLi1E...` (the module's last part
    and the function); other names as they are."""
    if not name.startswith("_ZN"):
        return name
    parts, rest = [], name[3:]
    while rest[:1].isdigit():
        digits = len(rest) - len(rest.lstrip("0123456789"))
        size = int(rest[:digits])
        parts.append(rest[digits:digits + size])
        rest = rest[digits + size:]
    return ".".join(parts[-2:]) if parts else name


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """A SIGTERM inside the block raises KeyboardInterrupt, so that what wraps the command still
    writes what it gathered (`timeout` sends SIGTERM)."""
    def interrupt(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    before = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)


def _run_module(module: str, args: list) -> int:
    """`python -m module args...` in this process; its exit status (a KeyboardInterrupt: 130)."""
    saved = sys.argv
    sys.argv = [module, *args]
    try:
        runpy.run_module(module, run_name="__main__", alter_sys=True)
        return 0
    except SystemExit as done:
        code = done.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    except KeyboardInterrupt:
        return 130
    finally:
        sys.argv = saved


def _profiler():
    """PyTorch's profiler of CUDA activity, or (None, why) where torch, CUDA or a GPU is missing."""
    try:
        import torch
        from torch.profiler import ProfilerActivity, profile
    except ImportError as error:
        return None, f"no torch ({error})"
    if not torch.cuda.is_available():
        return None, "torch sees no GPU"
    return profile(activities=[ProfilerActivity.CUDA]), ""


@contextlib.contextmanager
def kernels_traced():
    """Trace the block's kernels and copies (PyTorch's CUDA profiler); yields a dict that holds,
    after the block, "found": (kernels, copies) as :func:`read_chrome_trace` gives them, or None,
    and "why" None ("" when found)."""
    result = {"found": None, "why": ""}
    profiler, result["why"] = _profiler()
    if profiler is not None:
        try:
            profiler.start()
        except Exception as error:   # CUPTI refused, say: the block still runs, untraced
            profiler, result["why"] = None, f"the profiler did not start ({type(error).__name__}: {error})"
    try:
        yield result
    finally:
        if profiler is not None:
            try:
                profiler.stop()
                with tempfile.TemporaryDirectory() as scratch:
                    path = os.path.join(scratch, "trace.json")
                    profiler.export_chrome_trace(path)
                    result["found"] = read_chrome_trace(path)
            except Exception as error:   # the block's own outcome stands; the trace is lost
                result["found"], result["why"] = None, f"the trace failed ({type(error).__name__}: {error})"
            if result["found"] is not None and not (result["found"][0] or result["found"][1]):
                result["found"], result["why"] = None, "the trace holds no kernel (CUPTI saw none)"


def traced(module: str, args: list, cprofile: str | None = None) -> tuple[int, tuple | None, str]:
    """Run the module (:func:`_run_module`) with its kernels traced (:func:`kernels_traced`) and
    under cProfile into `cprofile` (None: not); returns (exit status, (kernels, copies) or None,
    why None). A SIGTERM ends it as Ctrl-C would."""
    host = cProfile.Profile() if cprofile else None
    with _sigterm_as_interrupt(), kernels_traced() as trace:
        if host is not None:
            host.enable()
        try:
            status = _run_module(module, args)
        finally:
            if host is not None:
                host.disable()
                host.dump_stats(cprofile)
    return status, trace["found"], trace["why"]


def write_summary(found: tuple | None, why: str, heading: str, path: str | None = None, top: int = 25) -> None:
    """The heading, then the trace's tables (:func:`print_summary`) or why there is none, to stdout
    or to the file `path`."""
    with open(path, "w") if path else contextlib.nullcontext(sys.stdout) as out, contextlib.redirect_stdout(out):
        print(heading)
        if found is None:
            print(f"no kernel trace: {why}")
            record.note("no_trace", why)
        else:
            print_summary(summarise(*found, top=top))


def print_summary(summary: dict) -> None:
    """The summary's three tables (record.table: printed and kept)."""
    window_ms = summary["window_us"] / 1e3
    busy = record.table(["window (first kernel to last) s", "kernels", "copies", "card busy with kernels",
                         "the same without gaps of 0.1 s or more", "with copies", "with either", "kernel names"],
                        "the card over the command's window")
    busy.row(f"{window_ms / 1e3:.2f}", summary["kernels"], summary["copies"], f"{summary['kernel_busy']:.1%}",
             f"{summary['kernel_busy_steady']:.1%}", f"{summary['copy_busy']:.1%}", f"{summary['any_busy']:.1%}",
             summary["kernel_names"],
             data={k: v for k, v in summary.items() if k not in ("gaps", "by_kernel")})
    gaps = record.table(["idle gap", "gaps", "total ms", "share of the window"], "the card's idle gaps")
    for gap in summary["gaps"]:
        label = f"{gap['from_us']:g}-{gap['to_us']:g} us" if np.isfinite(gap["to_us"]) else f">= {gap['from_us']:g} us"
        gaps.row(label, gap["count"], f"{gap['total_us'] / 1e3:.1f}", f"{gap['total_us'] / summary['window_us']:.1%}",
                 data=gap)
    kernels = record.table(["kernel", "launches", "GPU ms", "mean us", "share of the window"], "the kernels")
    for name, launches, total in summary["by_kernel"]:
        kernels.row(short_name(name), launches, f"{total / 1e3:.1f}", f"{total / launches:.1f}",
                    f"{total / summary['window_us']:.1%}", data={"kernel": name, "launches": launches, "total_us": total})


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cprofile", metavar="FILE", help="also run under cProfile, statistics to FILE")
    parser.add_argument("--summary", metavar="FILE", help="the tables to FILE instead of stdout")
    parser.add_argument("--top", type=int, default=25, help="kernels listed (most GPU time first)")
    parser.add_argument("module", help="the module to run, as python -m MODULE")
    parser.add_argument("args", nargs=argparse.REMAINDER, help="its arguments")
    args = parser.parse_args(argv)
    status, found, why = traced(args.module, args.args, args.cprofile)
    write_summary(found, why, f"kernel trace of `python -m {args.module} {' '.join(args.args)}` (exit {status}):",
                  args.summary, args.top)
    if status:
        raise SystemExit(status)


if __name__ == "__main__":
    record.run("kernel_trace", main)
