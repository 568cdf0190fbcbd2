"""colsim's files: netCDF (states, trajectories, analyses, summaries), the collapse's checkpoint and
the ParaView export, each written to a temporary name and renamed when complete. Imports no numerics
(no numba, solver or contact detection): reading a file is cheap."""
from .netcdf import *  # noqa: F401,F403
from .netcdf import AT_REST_FLAGS, InputError  # noqa: F401
