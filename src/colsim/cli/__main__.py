"""`python -m colsim.cli`: the `colsim` command."""
import sys

from .entry import main

sys.exit(main())
