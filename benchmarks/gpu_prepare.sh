#!/usr/bin/env bash
# Make .gpu/, the inputs of benchmarks/gpu_machine.sh, from this repository alone, on this machine's
# CPU (git-ignored; copy it with the repository to the machine with the GPU):
#
#   bash benchmarks/gpu_prepare.sh           # about 15 minutes on one core: the r0 = 3 pour
#
# - .gpu/whl/: the wheels that machine's image lacks (clarabel, netCDF4, cftime; Python 3.12);
# - .gpu/rest/r0_3_a2_seed1 and r0_3_a5_seed1 (.nc, .settings.yaml): the default study's r0 = 3,
#   seed-1 packing trimmed at a = 2 and 5, with the mu_r = 0.12 run's settings (`STAGES=rest` and
#   `scatter`; the a = 5 column also as .gpu/r0_3_a5.nc, the benchmark's), and under results/r0_3/
#   that run's CPU collapse and analysis (`snakemake`, the study's rules);
# - .gpu/pour/r0_6_seed1 (.pack.yaml, .collapse.yaml): the settings of an r0 = 6, a = 5 pour and its
#   collapse (`STAGES=pour`), which the GPU makes itself; `STAGES=big` tiles the r0 = 13 column from
#   that pour's column, on the same warm machine (BIG_SOURCE);
# - .gpu/pour/r0_8_seed1, r0_8_seed2, r0_8_seed3 and r0_10_seed1: likewise for r0 = 8, a = 5 (about
#   166,000 spheres; `POUR_NAMES=r0_8_seed1`), its seeds 2 and 3, and r0 = 10, a = 5 (about 310,000).
#
# A machine's earlier .gpu/ is kept where its files are already there. The columns are this commit's
# pour: a CPU scatter to compare the GPU's collapses with is `python -m benchmarks scatter` on them.
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p .gpu/whl .gpu/rest .gpu/pour
if ! ls .gpu/whl/clarabel-*.whl > /dev/null 2>&1; then
    python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
        --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
        -d .gpu/whl clarabel==0.11.1 netCDF4==1.7.5.1.post1 cftime==1.6.6.1
fi

study() {   # the config of a one-seed study at mu_r = 0.12: study() NAME R0 "ASPECT RATIOS" [SEED, default 1]
    printf 'study: %s\nr0: %s\naspect_ratios: [%s]\nmu_r: [0.12]\nseeds: [%s]\n' "$1" "$2" "${3// /, }" "${4:-1}" \
        > ".gpu/$1.yaml"
    echo ".gpu/$1.yaml"
}

planned() {   # the study's planned files matching a pattern: planned() CONFIG PATTERN
    snakemake --configfile "$1" --summary 2> /dev/null | cut -f 1 | grep -E "$2"
}

# r0 = 3, a = 2 and 5: the pour, the trims, and the CPU's collapses with the study's settings
config=$(study gpu-inputs 3 "2 5")
snakemake -j "${JOBS:-2}" --configfile "$config" --until analyse > .gpu/gpu-inputs.log 2>&1 \
    || { echo "the r0 = 3 study failed: see .gpu/gpu-inputs.log"; exit 1; }
for a in 2 5; do
    run=$(dirname "$(planned "$config" "/a_$a/mu_r_0.12/run_[^/]*/settings.yaml$")")
    cp "$run/../../column.nc" ".gpu/rest/r0_3_a${a}_seed1.nc"
    cp "$run/settings.yaml" ".gpu/rest/r0_3_a${a}_seed1.settings.yaml"
    echo "r0 = 3, a = $a: $run (the CPU's collapse and analysis)"
done
cp .gpu/rest/r0_3_a5_seed1.nc .gpu/r0_3_a5.nc   # the benchmark's 20 first steps on both devices

# r0 = 6, a = 5: the settings only (the GPU pours it)
config=$(study gpu-pour 6 "5")
snakemake -j 1 --configfile "$config" --until packing_settings run_settings > .gpu/gpu-pour.log 2>&1 \
    || { echo "the r0 = 6 settings failed: see .gpu/gpu-pour.log"; exit 1; }
cp "$(planned "$config" "/pack_[^/]*/settings.yaml$")" .gpu/pour/r0_6_seed1.pack.yaml
cp "$(planned "$config" "/run_[^/]*/settings.yaml$")" .gpu/pour/r0_6_seed1.collapse.yaml
# r0 = 8, a = 5, seeds 1-3, and r0 = 10, a = 5, seed 1: likewise
for column in "8 1" "8 2" "8 3" "10 1"; do
    read -r r0 seed <<< "$column"
    config=$(study "gpu-pour-$r0-seed$seed" "$r0" "5" "$seed")
    snakemake -j 1 --configfile "$config" --until packing_settings run_settings > ".gpu/gpu-pour-$r0-seed$seed.log" 2>&1 \
        || { echo "the r0 = $r0, seed $seed settings failed: see .gpu/gpu-pour-$r0-seed$seed.log"; exit 1; }
    cp "$(planned "$config" "/pack_[^/]*/settings.yaml$")" ".gpu/pour/r0_${r0}_seed$seed.pack.yaml"
    cp "$(planned "$config" "/run_[^/]*/settings.yaml$")" ".gpu/pour/r0_${r0}_seed$seed.collapse.yaml"
done
du -sh .gpu
