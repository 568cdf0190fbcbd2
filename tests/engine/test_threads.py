"""APGD on several threads (colsim.engine.threads): the same answer as on one, to the solver's tolerance.

The kernels run in a child process started with NUMBA_NUM_THREADS=3, so three threads exist on
any machine (on one core they take turns; only the arithmetic is tested, never the speed)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from colsim.engine.threads import pins_threads, use_threads

TESTS = Path(__file__).resolve().parents[1]   # tests/, where solver_cases.py is

SOLVE_ON_THREADS = """
import json, sys
import numpy as np
sys.path.insert(0, {tests!r})
from colsim.solvers.apgd import ApgdSolver
from colsim.solvers import ClarabelSolver
from colsim.engine.threads import threads, use_threads
from solver_cases import collapse_program, mid_collapse, small_pile

program, _ = collapse_program(mid_collapse(small_pile()))
reference = ClarabelSolver(tolerance=1e-10).solve(program).increments
out = {{}}
for count in (1, 2, 3, 3):
    use_threads(count)
    assert threads() == count
    solution = ApgdSolver().solve(program)
    out.setdefault(str(count), []).append({{
        "increments": solution.increments.tolist(), "primal": solution.info["primal"],
        "complementarity": solution.info["complementarity"],
        "error": float(np.linalg.norm(solution.increments - reference) / np.linalg.norm(reference))}})
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def solved():
    """{thread count: [solutions]} of one mid-collapse program, three threads twice."""
    env = {**os.environ, "NUMBA_NUM_THREADS": "3"}
    done = subprocess.run([sys.executable, "-c", SOLVE_ON_THREADS.format(tests=str(TESTS))], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_every_thread_count_solves_to_the_tolerance(solved):
    """On 1, 2 and 3 threads APGD meets its tolerance (1e-5) and its increments are within the
    bound of test_apgd.test_agrees_with_clarabel (1e-3 relative) of Clarabel's at 1e-10."""
    for count, solutions in solved.items():
        for solution in solutions:
            assert solution["primal"] <= 1e-5 and solution["complementarity"] <= 1e-5, count
            assert solution["error"] <= 1e-3, (count, solution["error"])


def test_a_thread_count_gives_the_same_bits_every_time(solved):
    """The sums run in fixed blocks, so the threads' timing never changes a result."""
    first, second = solved["3"]
    assert first["increments"] == second["increments"]


def test_thread_counts_are_checked():
    with pytest.raises(ValueError, match="whole number >= 1"):
        use_threads(0)
    assert use_threads(1) == 1


def test_the_collapse_command_runs_on_threads_and_records_them(tmp_path):
    """`colsim collapse --threads 2` on a tiny column: it runs, and its file records the count."""
    import xarray as xr

    def cli(*args):
        env = {**os.environ, "NUMBA_NUM_THREADS": "2"}
        done = subprocess.run([sys.executable, "-m", "colsim.cli", *args], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]

    cli("pack", "--r0", "1", "--height", "1", "--seed", "3", "--threads", "2", "--output", "pack.nc")
    cli("trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "column.nc")
    cli("collapse", "--input", "column.nc", "--steps", "10", "--duration", "0.1", "--threads", "2",
        "--output", "collapse.nc")
    config = json.loads(xr.load_dataset(tmp_path / "collapse.nc").attrs["config"])
    assert config["threads"] == 2 and config["input_config"]["input_config"]["threads"] == 2


def test_threads_are_pinned_only_when_they_fill_the_jobs_cpus():
    """Pinned one to a CPU when the threads are as many as the CPUs the job may use; never one
    thread (two one-thread jobs would both sit on the first CPU), never fewer threads than CPUs
    (another job may need the rest), never over the user's own OpenMP binding."""
    assert pins_threads(2, 2, {}) and pins_threads(16, 16, {})
    assert not pins_threads(1, 1, {})
    assert not pins_threads(2, 4, {})
    assert not pins_threads(2, 2, {"OMP_PROC_BIND": "false"})
    assert not pins_threads(2, 2, {"OMP_PLACES": "cores"})


PIN_CHILD = """
import os
import numpy as np
os.sched_setaffinity(0, {cpus!r})
from colsim.engine.threads import use_threads
from colsim.engine.compiled import numba, prange

@numba.njit(parallel=True)
def double(x):
    out = np.empty_like(x)
    for k in prange(len(x)):
        out[k] = 2.0 * x[k]
    return out

use_threads(2)
double(np.ones(1000))   # a parallel call: the threads have surely started
single = set()
for task in os.listdir("/proc/self/task"):
    with open(f"/proc/self/task/{{task}}/status") as status:
        allowed = next(line.split()[1] for line in status if line.startswith("Cpus_allowed_list"))
    if allowed.isdigit():
        single.add(int(allowed))
print(os.environ.get("OMP_PROC_BIND"), ",".join(map(str, sorted(single))))
"""


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2
                    or not Path("/proc/self/task").exists(), reason="needs Linux and 2 CPUs")
def test_two_threads_on_two_cpus_are_pinned_one_to_each():
    """A process allowed 2 CPUs that asks for 2 threads runs them on one CPU each: the threads
    pinned to a single CPU (their affinity in /proc) cover both CPUs."""
    cpus = sorted(os.sched_getaffinity(0))[:2]
    child = PIN_CHILD.format(cpus=set(cpus))
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_PROC_BIND", "OMP_PLACES")}
    env["NUMBA_NUM_THREADS"] = "2"
    done = subprocess.run([sys.executable, "-c", child], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    bound, pinned = done.stdout.split()[-2:]
    assert bound == "true"
    assert sorted(int(cpu) for cpu in pinned.split(",")) == cpus


def _environment_with_tbb() -> dict:
    """os.environ with the lock's tbb wheel (its libtbb in the interpreter's lib/) on the loader's path
    and no layer chosen by the user; a skip naming why when numba still cannot load TBB."""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY")}
    env["LD_LIBRARY_PATH"] = os.pathsep.join(filter(None, [str(Path(sys.prefix) / "lib"), env.get("LD_LIBRARY_PATH")]))
    env["NUMBA_NUM_THREADS"] = "2"
    probe = subprocess.run([sys.executable, "-c", "import numba.np.ufunc.tbbpool"], env=env, capture_output=True,
                           text=True, timeout=120)
    if probe.returncode != 0:
        pytest.skip("numba cannot load Intel TBB here (install the lock's tbb wheel, environment.txt): "
                    + probe.stderr.strip().splitlines()[-1])
    return env


def test_an_installed_tbb_does_not_take_the_threads(tmp_path):
    """Issue 50: with Intel TBB loadable, numba's own order would run the kernels on it (two threads
    on two cores then took turns, 10-30x slower); colsim chooses OpenMP (or numba's workqueue where
    there is no OpenMP), logs the layer and records it, and the 2-thread collapse equals the 1-thread
    one to the solver's tolerance."""
    import numpy as np
    import xarray as xr

    from colsim.engine.compiled import LAYER_PRIORITY

    env = _environment_with_tbb()

    def cli(*args):
        done = subprocess.run([sys.executable, "-m", "colsim.cli", *args], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        return done.stderr

    cli("pack", "--r0", "1", "--height", "1", "--seed", "3", "--output", "pack.nc")
    cli("trim", "--input", "pack.nc", "--aspect-ratio", "1", "--output", "column.nc")
    logs, finals = {}, {}
    for count in (1, 2):
        logs[count] = cli("collapse", "--input", "column.nc", "--steps", "10", "--duration", "0.1",
                          "--threads", str(count), "--output", f"collapse{count}.nc")
        result = xr.load_dataset(tmp_path / f"collapse{count}.nc")
        layer = result.attrs["threading_layer"]
        assert layer in LAYER_PRIORITY[:2], layer            # never TBB unless asked
        assert f"--threads {count} on numba's {layer} threading layer" in logs[count]
        finals[count] = result.position.values[-1]
        diameter = 2 * float(result.radius.mean())
    # auto's APGD stops each step with its gaps right to 1e-6 d (tolerance 1e-5 x length floor 0.1 d);
    # the thread count changes only the order of its sums: ten steps, at most 1e-5 d apart
    np.testing.assert_allclose(finals[2], finals[1], rtol=0, atol=1e-5 * diameter)
