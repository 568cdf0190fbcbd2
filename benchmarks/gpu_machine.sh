#!/usr/bin/env bash
# The issue-46 measurements in one call on a lent GPU machine, the CPU baseline (the host's threads)
# in the same call. Prepared here first (benchmarks/README.md, "On a lent GPU"): .gpu/ holds the
# wheels the machine's image lacks (clarabel, netCDF4, cftime) and the column files to collapse.
#
#   bash benchmarks/gpu_machine.sh                      # the defaults below
#   bash benchmarks/gpu_machine.sh --spheres 100 --iterations 2   # any `benchmarks gpu` arguments
#
# Records go to $OUT (the device tool's folder that comes back), else results/benchmarks.
set -euo pipefail
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/colsim-site \
    .gpu/whl/*.whl
export PYTHONPATH="/tmp/colsim-site:$PWD/src:$PWD${PYTHONPATH:+:$PYTHONPATH}"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>/dev/null || echo "no nvidia-smi"
echo "CPUs: $(nproc); python: $(python3 --version); numpy: $(python3 -c 'import numpy; print(numpy.__version__)')"
if [ $# -eq 0 ]; then
    columns=(.gpu/*.nc)
    set -- --spheres 73000 704000 2000000 --iterations 60 --columns "${columns[@]}" --steps 20 \
        --profile "${OUT:-results/benchmarks}/profiles"
fi
python3 -m benchmarks --results "${OUT:-results/benchmarks}" gpu "$@"

# A whole collapse on the GPU (issue 46's r0 = 6 target): each .gpu/rest/NAME.nc column with its run's
# NAME.settings.yaml (the study's settings.yaml), `colsim collapse --device cuda` to rest, stopped
# after REST_LIMIT seconds (default 240) if not at rest; its checkpoint and log come back either way,
# and `colsim analyse` measures a finished run.
for column in .gpu/rest/*.nc; do
    [ -e "$column" ] || continue
    name=$(basename "$column" .nc); out="${OUT:-results/benchmarks}/rest"; mkdir -p "$out"
    start=$(date +%s)
    timeout "${REST_LIMIT:-240}" python3 -m colsim.cli collapse --settings ".gpu/rest/$name.settings.yaml" \
        --input "$column" --device cuda --threads "$(nproc)" --checkpoint-every 50 --output "$out/$name.nc" > "$out/$name.log" 2>&1 \
        && python3 -m colsim.cli analyse --input "$out/$name.nc" --output "$out/$name.analysis.nc" >> "$out/$name.log" 2>&1 \
        || echo "$name: stopped or failed (exit $?); see $out/$name.log"
    echo "$name: $(( $(date +%s) - start )) s of wall"; tail -n 3 "$out/$name.log"
done
