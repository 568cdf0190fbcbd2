"""colsim's files: netCDF (states, trajectories, analyses, summaries), the collapse's checkpoint and
the ParaView export, each written to a temporary name and renamed when complete. Imports no numerics
(no numba, solver or contact detection): reading a file is cheap.

One concern a module: files.py (atomic writing, InputError), provenance.py (what a file records of
how it was made), cf.py (CF units, encodings and labels, the writer), netcdf.py (the kinds of file
and reading one back, older files included), state_file.py (a packing's or column's particles and
contact forces), trajectory.py, steps.py, checks.py, checkpoint.py, vtk.py. The names of the first
five are also colsim.io's."""
from .files import *  # noqa: F401,F403
from .cf import *  # noqa: F401,F403
from .provenance import *  # noqa: F401,F403
from .netcdf import *  # noqa: F401,F403
from .state_file import *  # noqa: F401,F403
from .files import InputError  # noqa: F401
from .netcdf import AT_REST_FLAGS  # noqa: F401
