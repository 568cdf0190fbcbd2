"""colsim's benchmarks: `python -m benchmarks list` names them, `python -m benchmarks NAME` runs one
(benchmarks/README.md). The scripts import each other as plain modules (`packings`, `record`), with
this folder on sys.path, so each also runs as `python benchmarks/NAME.py`."""
