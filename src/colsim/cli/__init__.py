"""The `colsim` command (:mod:`colsim.cli.main`) and what each subcommand does (:mod:`colsim.cli.commands`)."""
from .main import build_parser, main

__all__ = ["build_parser", "main"]
