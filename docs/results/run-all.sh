#!/bin/sh
# Regenerates docs/results/<scene>/ (see docs/results.md): for each scene of
# the suite, a reference rendered by `prism converge` itself (kept out of the
# repository, in target/converge-refs/) and a run of 20 CPU-seconds per
# integrator at 128x128. About 12 minutes on a 2-core machine (11 min 47 s in
# session 25, 12 min 43 s in session 40).
# The references have 4x the samples of session 8's: at today's speed the
# integrators' 20 s runs reach errors the old references' own noise would
# have been up to ~70 % of (11-64 % of session 8's errors).
#
#   sh docs/results/run-all.sh            # builds target/release/prism first
#   PRISM=/path/to/prism sh docs/results/run-all.sh
set -eu
cd "$(dirname "$0")/../.."
if [ -z "${PRISM:-}" ]; then
    cargo build --release
    PRISM=target/release/prism
fi
REFS=target/converge-refs
COMMON="--width 128 --height 128 --seed 1 --time 20 --clock cpu"
ALL=path,light,bdpt,bdpt:uniform

run() { # scene integrators reference-integrator reference-spp
    "$PRISM" converge "scenes/$1.json" --integrators "$2" \
        --reference-integrator "$3" --reference-spp "$4" --reference-out "$REFS/$1.exr" \
        --out "docs/results/$1" $COMMON
}

run caustic          "$ALL"                 bdpt 4096
run veach-mis        "$ALL,simple_path"     path 16384
run gap-room         "$ALL"                 bdpt 4096
run cornell-box      "$ALL"                 path 16384
run cornell-glossy   "$ALL"                 bdpt 4096
run prism-dispersion "$ALL"                 bdpt 8192
