"""A collapse's bookkeeping over a run, timed on the CPU: its checkpoints and the rest test's deposits.

    python -m benchmarks checkpoints COLUMN [--tile R0] [--steps 1200] [--every 100] [--frame-every 25]

Saves the checkpoints of a run of `--steps` steps as `colsim collapse` does (one every `--every`
steps, a frame every `--frame-every`; the column's state, its warm start and each step's
diagnostics), with nothing stepped: the column (`colsim trim`), or one of radius R0 tiled from it
(benchmarks/tiling.py), stands for every frame. Prints the seconds of each checkpoint and their sum,
and the seconds of one deposit measure (the main mass, h_inf, r_inf: what the rest test measures on
a frame it reads).
"""
from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import record
import tiling


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("column", help="a column file (colsim trim)")
    parser.add_argument("--tile", type=float, metavar="R0", help="a column of radius R0 tiled from it")
    parser.add_argument("--steps", type=int, default=1200, help="the run's steps")
    parser.add_argument("--every", type=int, default=100, help="a checkpoint every this many steps")
    parser.add_argument("--frame-every", type=int, default=25, help="a frame every this many steps")
    args = parser.parse_args(argv)

    from colsim import io
    from colsim.engine.records import Carry, StepDiagnostics
    from colsim.io.checkpoint import remove_checkpoint, save_checkpoint
    from colsim.stages.analyse import measure_deposit

    with tempfile.TemporaryDirectory() as scratch:
        state, dataset = io.read_state(tiling.column_or_tiled(args.column, args.tile, scratch))
        carry = Carry(io.contact_forces_of(dataset), 0.1)
        begin = time.perf_counter()
        measure_deposit(state)
        deposit_s = time.perf_counter() - begin
        blank = {f.name: 0 for f in dataclasses.fields(StepDiagnostics)}
        diagnostic = StepDiagnostics(**{**blank, "solver_status": "Solved", "solver_backend": "apgd"})
        path = Path(scratch) / "run.checkpoint"
        print(f"{state.n} spheres; one deposit measure {deposit_s:.3f} s")
        table = record.table(["step", "frames", "checkpoint s"])
        frames, total = [], 0.0
        for step in range(args.steps + 1):
            if step % args.frame_every == 0:
                frames.append((step, state))
            if step and step % args.every == 0:
                diagnostics = [dataclasses.replace(diagnostic, step=k) for k in range(1, step + 1)]
                begin = time.perf_counter()
                save_checkpoint(path, "benchmark", state, frames, diagnostics, carry, 1.0)
                spent = time.perf_counter() - begin
                total += spent
                table.row(step, len(frames), f"{spent:.3f}", data={"step": step, "frames": len(frames),
                                                                    "checkpoint_s": spent, "spheres": state.n})
        remove_checkpoint(path)
    summary = record.table(["spheres", "steps", "checkpoints", "all checkpoints s", "one deposit measure s"])
    summary.row(state.n, args.steps, args.steps // args.every, f"{total:.2f}", f"{deposit_s:.3f}",
                data={"spheres": state.n, "steps": args.steps, "every": args.every, "frame_every": args.frame_every,
                      "checkpoints_s": total, "deposit_s": deposit_s})


if __name__ == "__main__":
    record.run("checkpoints", main)
