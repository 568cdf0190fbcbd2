"""Python's start-up hook for the processes the tests start (the `colsim` command, the benchmarks):
where numba's CUDA simulator is on (NUMBA_ENABLE_CUDASIM=1), set it up as the tests' own process is
(tests/cuda_simulator.py) once numba loads it. conftest.py puts this folder on PYTHONPATH. A process
that never loads the simulator loads nothing more than this file."""
import importlib.abc
import importlib.util
import os
import sys

#: the simulator's module whose loading sets it up, and the set-up
TRIGGER = "numba.cuda.simulator.kernel"
SET_UP = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "cuda_simulator.py")


class _SetUpSimulator(importlib.abc.MetaPathFinder):
    """Finds nothing itself: hands the trigger's spec on with its loading followed by the set-up."""

    def find_spec(self, name, path, target=None):
        if name != TRIGGER:
            return None
        others = [finder for finder in sys.meta_path if finder is not self and hasattr(finder, "find_spec")]
        spec = next((found for found in (f.find_spec(name, path, target) for f in others) if found), None)
        if spec is None:
            return None
        load = spec.loader.exec_module

        def exec_module(module):
            load(module)
            sys.meta_path.remove(self)
            setup = importlib.util.spec_from_file_location("cuda_simulator", SET_UP)
            cuda_simulator = importlib.util.module_from_spec(setup)
            setup.loader.exec_module(cuda_simulator)
            cuda_simulator.use()

        spec.loader.exec_module = exec_module
        return spec


if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
    sys.meta_path.insert(0, _SetUpSimulator())
