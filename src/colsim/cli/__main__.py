"""`python -m colsim.cli`: the `colsim` command."""
import sys

from .main import main

sys.exit(main())
