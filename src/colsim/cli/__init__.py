"""The `colsim` command (:mod:`colsim.cli.entry`) and what each subcommand does (:mod:`colsim.cli.commands`)."""
from .entry import build_parser, main

__all__ = ["build_parser", "main"]
