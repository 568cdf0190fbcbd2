#!/usr/bin/env bash
# The GPU measurements in one command, on a machine with one NVIDIA GPU, with the CPU baseline (the
# host's threads) in the same command. Make .gpu/ first (benchmarks/gpu_prepare.sh): the wheels the
# machine's Python may lack (clarabel, netCDF4, cftime) and the column files to collapse.
#
#   bash benchmarks/gpu_machine.sh                      # the defaults below
#   bash benchmarks/gpu_machine.sh --spheres 100 --iterations 2   # any `benchmarks gpu` arguments
#
# Records go to $COLSIM_BENCHMARK_RESULTS, else results/benchmarks.
# STAGES (default "bench rest pour") picks what runs, in that order: the benchmark, "scatter" (not by
# default: the same-answer runs on both devices at once), the collapses of .gpu/rest/ to rest, the
# pours of .gpu/pour/ with their collapses; "big" (not by default, last) adds the first BIG_STEPS
# (100) steps of an r0 = BIG_R0 (13) column on the GPU, tiled from BIG_SOURCE (benchmarks/tiling.py:
# about 657,000 spheres from r0 = 6, a timing, not a pour): by default .gpu/rest/r0_6_a5_seed1.nc,
# else the column of a pour of r0 = 6 made on this machine (results/gpu-pour/r0_6_seed1/column.nc:
# `STAGES=pour` in the same command or an earlier one).
set -euo pipefail
if ls .gpu/whl/*.whl > /dev/null 2>&1; then   # none where the Python already has them
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/colsim-site \
        .gpu/whl/*.whl
fi
export PYTHONPATH="/tmp/colsim-site:$PWD/src:$PWD${PYTHONPATH:+:$PYTHONPATH}"
# On numba's simulator (NUMBA_ENABLE_CUDASIM=1, no card), every process sets the simulator up as the
# tests do (tests/simulator_site): numba's own swaps a device function's cuda module without a lock,
# and a kernel of many threads then fails ("module 'numba.cuda' has no attribute 'blockIdx'").
if [ "${NUMBA_ENABLE_CUDASIM:-0}" = 1 ]; then
    export PYTHONPATH="$PWD/tests/simulator_site:$PYTHONPATH"
fi
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>/dev/null || echo "no nvidia-smi"
echo "CPUs: $(nproc); python: $(python3 --version); numpy: $(python3 -c 'import numpy; print(numpy.__version__)')"
# With GPU_TESTS set (pytest arguments, e.g. "tests/engine/test_cuda_launch.py"), those tests first, on the
# GPU itself (NUMBA_ENABLE_CUDASIM=0), for at most 120 s: what CI checks on the simulator, on the card.
if [ -n "${GPU_TESTS:-}" ]; then
    NUMBA_ENABLE_CUDASIM=0 timeout 120 python3 -m pytest -q -p no:cacheprovider $GPU_TESTS 2>&1 | tail -n 15 \
        || echo "GPU tests: failed or stopped"
fi

stages=" ${STAGES:-bench rest pour} "
results=${COLSIM_BENCHMARK_RESULTS:-results/benchmarks}
mkdir -p "$results"

# busy COMMAND...: runs it, then prints the share of its wall time in which the GPU ran a kernel
# (the "kernels at least 80 % of a step"): the mean of nvidia-smi's utilisation, read every
# 200 ms in the background (each reading: the share of its last sample period with a kernel running),
# its start, imports and kernels' compilation included. Returns the command's exit status.
busy() {
    local samples status=0 sampler
    samples=$(mktemp)
    nvidia-smi --query-gpu=utilization.gpu --format=csv,noheader,nounits -lms 200 > "$samples" 2>/dev/null &
    sampler=$!
    "$@" || status=$?
    kill "$sampler" 2>/dev/null || true
    wait "$sampler" 2>/dev/null || true
    awk '$1 ~ /^[0-9]+$/ {s += $1; n++} END {if (n) printf "GPU busy: %.0f %% (nvidia-smi, %d readings, the start included)\n", s / n, n}' "$samples"
    rm -f "$samples"
    return "$status"
}
if [[ "$stages" == *" bench "* ]]; then
    if [ $# -eq 0 ]; then
        columns=(.gpu/*.nc)
        set -- --spheres 73000 704000 2000000 --iterations 60 --columns "${columns[@]}" --steps 20 \
            --profile "$results/profiles"
    fi
    python3 -m benchmarks --results "$results" gpu "$@" || echo "benchmarks gpu: failed (exit $?)"
fi

# The same answer : `python -m benchmarks scatter` on SCATTER_COLUMN (default r0_3_a2_seed1 of
# .gpu/rest/) with its settings, on both devices at once: the GPU's runs (the settings' own, each of
# SCATTER_TOLERANCES, default "9e-6 1.1e-5", and each draw of SCATTER_GPU_DRAWS, default "1-2": positions
# moved by 1e-12 d), SCATTER_GPU_JOBS (default 1) at once on the one card, and beside them the CPU's (the
# settings' own, the same tolerances and SCATTER_CPU_DRAWS, default "1-10"; "none": no CPU runs, e.g.
# when SCATTER_ALSO names a record of them made elsewhere) on the host's other cores, one thread each.
# Both scatters' tables (h_inf/r0 and run-out: range, mean, sd), then both together with each GPU run
# placed in the CPU's scatter (this call's CPU runs and SCATTER_ALSO's records), come back as
# scatter-*.json, and the runs' records as scatter-*.jsonl (resumable in results/ there; on a warm machine
# a later call goes on from them). SCATTER_LIMIT (seconds) stops the GPU's scatter, its finished runs
# kept, its tables then left to be made elsewhere (`scatter --also`). With SCATTER_GPU_STORAGE=float32 they store APGD's arrays in float32 (`--gpu-storage`; "cuda-float32").
if [[ "$stages" == *" scatter "* ]]; then
    column=.gpu/rest/${SCATTER_COLUMN:-r0_3_a2_seed1}
    common=("$column.nc" --settings "$column.settings.yaml" --tolerances ${SCATTER_TOLERANCES:-9e-6 1.1e-5})
    gpu=(--device cuda --gpu-storage "${SCATTER_GPU_STORAGE:-float64}")
    cpu_scatter=
    if [ "${SCATTER_CPU_DRAWS:-1-10}" != none ]; then
        python3 -m benchmarks --results "$results" scatter "${common[@]}" --device cpu \
            --draws "${SCATTER_CPU_DRAWS:-1-10}" --jobs "$(( $(nproc) - 2 * ${SCATTER_GPU_JOBS:-1} ))" \
            --record results/scatter-cpu.jsonl > /tmp/scatter-cpu.log 2>&1 &
        cpu_scatter=$!
    fi
    stopped=0
    timeout "${SCATTER_LIMIT:-86400}" python3 -m benchmarks --results "$results" scatter \
        "${common[@]}" "${gpu[@]}" --draws "${SCATTER_GPU_DRAWS:-1-2}" --threads 2 --jobs "${SCATTER_GPU_JOBS:-1}" \
        --record results/scatter-gpu.jsonl || { stopped=$?; echo "scatter on the GPU: stopped or failed (exit $stopped)"; }
    if [ -n "$cpu_scatter" ]; then
        wait "$cpu_scatter" || echo "scatter on the CPU: failed (exit $?)"
        cat /tmp/scatter-cpu.log
    fi
    # the tables of both would run the GPU's missing draws again: only after a whole scatter
    [ "$stopped" != 0 ] || python3 -m benchmarks --results "$results" scatter "${common[@]}" \
        "${gpu[@]}" --draws "${SCATTER_GPU_DRAWS:-1-2}" --record results/scatter-gpu.jsonl \
        --also results/scatter-cpu.jsonl ${SCATTER_ALSO:-} || echo "scatter: the tables of both failed (exit $?)"
    cp results/scatter-*.jsonl "$results/" 2> /dev/null || true   # every finished run's record
fi

# A whole collapse on the GPU (the r0 = 6 target): each .gpu/rest/NAME.nc column with its run's
# NAME.settings.yaml (the study's settings.yaml), `colsim collapse --device cuda` to rest, stopped
# after REST_LIMIT seconds (default 240) if not at rest, after the benchmarks; with REST_TOLERANCES
# (e.g. "1e-5 9e-6 1.1e-5") once for each APGD tolerance. The logs and `colsim analyse` of each
# finished run (h_inf/r0 and the run-out, in the log too) go into rest.tgz; the trajectories stay in results/gpu-rest (an r0 = 3 collapse's is 31 MB).
# REST_COLUMNS (names without .nc, e.g. "r0_6_a5_seed1") picks some of them; a run that finds its
# checkpoint in results/gpu-rest (git-ignored: kept on a warm machine between calls) goes on from it.
# Each finished run's steps are split by phase (`benchmarks gpu --trajectories`) in its log.
phases() {   # phases RUN LOG: RUN's steps (a collapse's or a pour's file) split by phase, appended to LOG
    python3 -m benchmarks --results "$(dirname "$2")" gpu --spheres --trajectories "$1" 2>&1 | grep "^|" >> "$2"
}
profile_top() {   # profile_top BASE: BASE.prof's 30 functions of most own time and BASE.kernels (the
                  # kernel trace's tables), appended to BASE.log
    [ -e "$1.kernels" ] && cat "$1.kernels" >> "$1.log"
    [ -e "$1.prof" ] || return 0
    python3 -c "import pstats, sys; pstats.Stats(sys.argv[1]).sort_stats('tottime').print_stats(30)" "$1.prof" \
        >> "$1.log" 2>&1 || true
}
rm -rf /tmp/rest-out /tmp/pour-out
for column in .gpu/rest/*.nc; do
    if [ -n "${REST_COLUMNS:-}" ] && [[ " $REST_COLUMNS " != *" $(basename "$column" .nc) "* ]]; then continue; fi
    [[ "$stages" == *" rest "* && -e "$column" ]] || continue
    for tolerance in ${REST_TOLERANCES:-settings}; do   # APGD's tolerance: the settings' own, or each given
        base=$(basename "$column" .nc); name=$base; flags=()
        [ "$tolerance" = settings ] || { name="$base-tol$tolerance"; flags=(--solver-tolerance "$tolerance"); }
        out=/tmp/rest-out; mkdir -p "$out" results/gpu-rest
        start=$(date +%s)
        busy timeout "${REST_LIMIT:-240}" python3 -m colsim.cli collapse --settings ".gpu/rest/$base.settings.yaml" \
            --input "$column" --device cuda --threads "$(nproc)" --checkpoint-every 50 "${flags[@]}" \
            --output "results/gpu-rest/$name.nc" > "$out/$name.log" 2>&1 \
            && python3 -m colsim.cli analyse --input "results/gpu-rest/$name.nc" --output "$out/$name.analysis.nc" >> "$out/$name.log" 2>&1 \
            && phases "results/gpu-rest/$name.nc" "$out/$name.log" \
            || echo "$name: stopped or failed (exit $?); see rest.tgz"
        echo "$name: $(( $(date +%s) - start )) s of wall"; grep "^GPU busy" "$out/$name.log" || true
        tail -n 3 "$out/$name.log"
        tar czf "$results/rest.tgz" -C /tmp rest-out   # each run's log and analysis, one file
    done
done


# A pour, its trim and its collapse on the GPU (the "pour and collapse of r0 = 6 in 10
# minutes"): each .gpu/pour/NAME.pack.yaml (a study's packing settings.yaml) with NAME.collapse.yaml
# (its run's settings.yaml), `colsim pack --device cuda` stopped after POUR_LIMIT seconds (default
# 300), `colsim trim --aspect-ratio ${POUR_ASPECT:-5}`, then the collapse to rest as above. The logs
# and the analysis come back in pour.tgz; the files stay in results/gpu-pour/NAME there (git-ignored:
# kept on a warm machine between calls; a packing already there is not poured again). The trimmed
# column comes back too, as NAME.aA.column.nc (A the aspect ratio; benchmarks/travelling_column.py:
# its particles without the contact forces, 81 bytes a sphere, 13 MB at r0 = 8, a = 5), and one for
# each aspect ratio of TRAVEL_ASPECTS (e.g. "2"): put in .gpu/pour/, a later call on another machine
# collapses it (POUR_ASPECT=A) instead of pouring.
# With POUR_PROFILE=1 the pour and the collapse run under cProfile and PyTorch's CUDA profiler
# (`benchmarks kernel_trace`: slower, so not the target's timing; a command stopped by its limit
# still writes both): their statistics (NAME.pack.prof, NAME.collapse.prof) and, in the logs, the 30
# functions of most own time, the card's busy share between its first and last kernel, its idle gaps
# by length and the kernels of most GPU time come back in pour.tgz: where a GPU step's wall goes
# outside the kernels, and which kernels take it (the collapse's busy share at r0 = 6 was 28 %).
# POUR_PROFILE=collapse: the collapse alone so (the pour at its own speed). POUR_NAMES picks the
# pours (default "r0_6_seed1"; "r0_8_seed1" is the r0 = 8, a = 5 pour and collapse, about
# 166,000 spheres: its pour may take one call and its collapse the next, on the same warm machine).
for settings in .gpu/pour/*.pack.yaml; do
    name=$(basename "$settings" .pack.yaml); out=/tmp/pour-out; work=results/gpu-pour/$name
    [[ " ${POUR_NAMES:-r0_6_seed1} " == *" $name "* ]] || continue
    [[ "$stages" == *" pour "* && -e "$settings" ]] || continue
    mkdir -p "$out" "$work"
    pack_run=(-m colsim.cli); collapse_run=(-m colsim.cli)
    if [ "${POUR_PROFILE:-0}" = 1 ]; then
        pack_run=(-m benchmarks --results "$out" kernel_trace --cprofile "$out/$name.pack.prof"
                  --summary "$out/$name.pack.kernels" colsim.cli)
    fi
    if [ "${POUR_PROFILE:-0}" = 1 ] || [ "${POUR_PROFILE:-0}" = collapse ]; then
        collapse_run=(-m benchmarks --results "$out" kernel_trace --cprofile "$out/$name.collapse.prof"
                      --summary "$out/$name.collapse.kernels" colsim.cli)
    fi
    start=$(date +%s)
    aspect=${POUR_ASPECT:-5}
    travelled=.gpu/pour/$name.a$aspect.column.nc   # a column an earlier call returned: poured and trimmed there
    if [ -e "$travelled" ]; then
        cp "$travelled" "$work/column.nc"; poured=$start
        echo "$name: the column of an earlier call ($travelled)" | tee "$out/$name.collapse.log"
    else
        [ -e "$work/packing.nc" ] && echo "$name: poured in an earlier call ($work/packing.nc)" || \
        busy timeout "${POUR_LIMIT:-300}" python3 "${pack_run[@]}" pack --settings "$settings" --max-spheres 1000000 \
            --device cuda --threads "$(nproc)" --output "$work/packing.nc" > "$out/$name.pack.log" 2>&1 \
            || echo "$name: the pour stopped or failed (exit $?); see pour.tgz"
        poured=$(date +%s); echo "$name: pour $(( poured - start )) s of wall"
        grep "^GPU busy" "$out/$name.pack.log" 2>/dev/null || true; tail -n 2 "$out/$name.pack.log" 2>/dev/null || true
        [ -e "$work/packing.nc" ] && phases "$work/packing.nc" "$out/$name.pack.log" || true
        profile_top "$out/$name.pack"
        tar czf "$results/pour.tgz" -C /tmp pour-out
        [ -e "$work/packing.nc" ] || continue
        python3 -m colsim.cli trim --input "$work/packing.nc" --aspect-ratio "$aspect" \
            --output "$work/column.nc" > "$out/$name.collapse.log" 2>&1 || { echo "$name: the trim failed"; continue; }
        # the columns without their contact forces come back, for later calls on other machines: this
        # one, and one trimmed at each of TRAVEL_ASPECTS
        python3 benchmarks/travelling_column.py "$work/column.nc" "$results/$name.a$aspect.column.nc" \
            || echo "$name: the travelling column failed (exit $?)"
        for other in ${TRAVEL_ASPECTS:-}; do
            python3 -m colsim.cli trim --input "$work/packing.nc" --aspect-ratio "$other" --output "$work/column-a$other.nc" \
                >> "$out/$name.collapse.log" 2>&1 \
                && python3 benchmarks/travelling_column.py "$work/column-a$other.nc" "$results/$name.a$other.column.nc" \
                || echo "$name: the travelling column at a = $other failed (exit $?)"
        done
    fi
    busy timeout "${REST_LIMIT:-240}" python3 "${collapse_run[@]}" collapse \
        --settings ".gpu/pour/$name.collapse.yaml" \
        --input "$work/column.nc" --device cuda --threads "$(nproc)" --checkpoint-every 50 \
        --output "$work/collapse.nc" >> "$out/$name.collapse.log" 2>&1 \
        && python3 -m colsim.cli analyse --input "$work/collapse.nc" --output "$out/$name.analysis.nc" \
            >> "$out/$name.collapse.log" 2>&1 \
        && phases "$work/collapse.nc" "$out/$name.collapse.log" \
        || echo "$name: the collapse stopped or failed (exit $?); see pour.tgz"
    echo "$name: trim and collapse $(( $(date +%s) - poured )) s of wall, $(( $(date +%s) - start )) s in all"
    grep "^GPU busy" "$out/$name.collapse.log" || true; tail -n 4 "$out/$name.collapse.log"   # h_inf, phases
    profile_top "$out/$name.collapse"
    tar czf "$results/pour.tgz" -C /tmp pour-out
done

# The r0 = 13 steps (the "at most 1 s a step over the first 100 steps"): no 700,000-sphere
# pour fits one call, so the column is tiled from the r0 = 6 one; the GPU's steps only (the host's 16
# threads took 3.3 s a step over r0 = 6's first steps, with ten times fewer spheres). BIG_TRACE=K
# then runs its first K steps again with their kernels traced (`benchmarks gpu --kernel-trace`): the
# tables come back as COLUMN.kernels (which kernels take APGD's three quarters of a step).
# BIG_STORED (e.g. "float32 float32-geometry") then runs the same steps again with APGD's arrays stored
# as each of those `benchmarks gpu` STORAGE_VARIANTS has them (`--stored`: whether narrower storage
# brings a step under the target).
if [[ "$stages" == *" big "* ]]; then
    tiled_from=.gpu/rest/r0_6_a5_seed1.nc
    [ -e "$tiled_from" ] || tiled_from=results/gpu-pour/r0_6_seed1/column.nc
    echo "big: tiled from ${BIG_SOURCE:-$tiled_from}"
    python3 -m benchmarks --results "$results" gpu --spheres \
        --columns "${BIG_SOURCE:-$tiled_from}" --tile "${BIG_R0:-13}" \
        --steps "${BIG_STEPS:-100}" --cpu-steps 0 \
        ${BIG_TRACE:+--kernel-trace "$results" --trace-steps "$BIG_TRACE"} \
        ${BIG_STORED:+--stored $BIG_STORED} \
        || echo "benchmarks gpu (big): failed (exit $?)"
fi
