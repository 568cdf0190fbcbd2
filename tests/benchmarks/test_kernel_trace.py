"""benchmarks/kernel_trace.py: the card's busy share and idle gaps are exact interval arithmetic on
the trace's kernels, and a command runs as `python -m` would (its exit status kept) with or without
a trace to take."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import kernel_trace  # noqa: E402
from kernel_trace import idle_gaps_us, read_chrome_trace, short_name, summarise, union_us  # noqa: E402


def test_the_union_counts_overlaps_once_and_gaps_not_at_all():
    """[0, 10] and [5, 20] overlap (20 us), [30, 35] stands apart (5 us), [31, 32] lies inside it:
    25 us busy, one idle gap of 10 us."""
    intervals = np.array([[30.0, 35.0], [0.0, 10.0], [31.0, 32.0], [5.0, 20.0]])
    assert union_us(intervals) == 25.0
    assert idle_gaps_us(intervals).tolist() == [10.0]
    assert union_us(np.zeros((0, 2))) == 0.0


def test_the_summary_splits_the_window_into_kernels_copies_and_gaps():
    """Kernels a (2 x 10 us), b (30 us) and a copy (5 us) over a window of 100 us: the kernels busy
    50 %, the copy 5 %, the gaps 5 (one of 5 us) and 40 us (one), each in its class; b first."""
    kernels = [("a", 0.0, 10.0), ("b", 15.0, 30.0), ("a", 90.0, 10.0)]
    copies = [("copy", 45.0, 5.0)]
    summary = summarise(kernels, copies)
    assert summary["window_us"] == 100.0
    assert summary["kernel_busy"] == pytest.approx(0.5)
    assert summary["copy_busy"] == pytest.approx(0.05)
    assert summary["any_busy"] == pytest.approx(0.55)
    counts = {(g["from_us"], g["to_us"]): (g["count"], g["total_us"]) for g in summary["gaps"]}
    assert counts[(0.0, 10.0)] == (1, 5.0) and counts[(10.0, 100.0)] == (1, 40.0)
    assert sum(c for c, _ in counts.values()) == 2
    assert summary["by_kernel"] == [("b", 1, 30.0), ("a", 2, 20.0)]
    assert summary["kernel_busy_steady"] == summary["kernel_busy"]   # no gap of 0.1 s


def test_the_steady_share_leaves_out_gaps_of_a_tenth_of_a_second():
    """Three kernels of 1 ms, the second after a 0.5 s gap (a compilation), the third 1 ms after it:
    busy 3 ms of a 504 ms window, and 3 ms of the 4 ms left without the long gap (75 %)."""
    kernels = [("a", 0.0, 1_000.0), ("b", 501_000.0, 1_000.0), ("c", 503_000.0, 1_000.0)]
    summary = summarise(kernels, [])
    assert summary["kernel_busy"] == pytest.approx(3 / 504)
    assert summary["kernel_busy_steady"] == pytest.approx(0.75)
    assert [g["count"] for g in summary["gaps"]] == [0, 0, 0, 1, 0, 1]


def test_a_chrome_trace_gives_its_kernels_and_copies(tmp_path):
    """PyTorch's export: complete events ("ph": "X") of category kernel, gpu_memcpy, gpu_memset;
    others (the host's, instants) left out."""
    trace = {"traceEvents": [
        {"ph": "X", "cat": "kernel", "name": "k", "ts": 1.5, "dur": 2.0},
        {"ph": "X", "cat": "gpu_memcpy", "name": "Memcpy DtoH", "ts": 4.0, "dur": 1.0},
        {"ph": "X", "cat": "gpu_memset", "name": "Memset", "ts": 6.0, "dur": 0.5},
        {"ph": "X", "cat": "cuda_runtime", "name": "cudaLaunchKernel", "ts": 1.0, "dur": 3.0},
        {"ph": "i", "cat": "kernel", "name": "instant", "ts": 9.0}]}
    path = tmp_path / "trace.json"
    path.write_text(json.dumps(trace))
    kernels, copies = read_chrome_trace(str(path))
    assert kernels == [("k", 1.5, 2.0)]
    assert copies == [("Memcpy DtoH", 4.0, 1.0), ("Memset", 6.0, 0.5)]


def test_a_numba_kernel_s_mangled_name_is_made_readable():
    """The PTX entry numba-cuda made for colsim.engine.cuda_state._inverse_kernel (libNVVM, cc 9.0)."""
    mangled = ("_ZN6colsim6engine10cuda_state15_inverse_kernelB2v1B92cw51cXTLSUwv1sDUaKthqaNgoKmjgOR3W3CwAkMX"
               "LaJtQYkOIgxJU0gCqOkEJoHkbttqdVhoqlspQGNFHSgJ5BnXagIAE5ArrayIdLi1E1C7mutable7alignedE")
    assert short_name(mangled) == "cuda_state._inverse_kernel"
    assert short_name("void cub::DeviceReduce") == "void cub::DeviceReduce"


def test_a_command_runs_as_python_m_and_keeps_its_exit_status(tmp_path, monkeypatch):
    """A module that writes a file and exits 3: it runs with its arguments, the summary (here: no
    trace, as on any machine without torch's CUDA and a GPU, or with one) is written to its file,
    the cProfile statistics too, and the exit status is 3."""
    module = tmp_path / "exits_three.py"
    module.write_text("import sys\nopen(sys.argv[1], 'w').write('ran')\nsys.exit(3)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(kernel_trace, "_profiler", lambda: (None, "no GPU in this test"))
    summary, profile, marker = tmp_path / "summary.md", tmp_path / "host.prof", tmp_path / "marker"
    with pytest.raises(SystemExit) as exited:
        kernel_trace.main(["--summary", str(summary), "--cprofile", str(profile), "exits_three", str(marker)])
    assert exited.value.code == 3
    assert marker.read_text() == "ran"
    assert "no kernel trace: no GPU in this test" in summary.read_text()
    assert profile.stat().st_size > 0


def test_a_profiler_that_fails_leaves_the_block_to_run_untraced(monkeypatch):
    """A profiler whose start raises (CUPTI refused, say): the block runs and the result says why;
    one whose export raises: the block's work stands and the trace is reported lost."""
    class Refusing:
        def start(self):
            raise RuntimeError("CUPTI_ERROR_NOT_INITIALIZED")

    class Losing:
        def start(self):
            pass

        def stop(self):
            pass

        def export_chrome_trace(self, path):
            raise OSError("disk full")

    ran = []
    for profiler, why in ((Refusing(), "did not start"), (Losing(), "the trace failed")):
        monkeypatch.setattr(kernel_trace, "_profiler", lambda p=profiler: (p, ""))
        with kernel_trace.kernels_traced() as trace:
            ran.append(True)
        assert trace["found"] is None and why in trace["why"]
    assert ran == [True, True]
