#!/usr/bin/env bash
# A profile-guided build of prism (rustc's PGO, LLVM's instrumentation
# profiles): the same code and flags as `cargo build --release`, laid out and
# inlined by where a render spends its time (docs/performance-log.md, "A
# profile-guided build").
#
#   scripts/pgo-build.sh          # from the repository root: target/pgo/prism
#
# 1. an instrumented build (target/pgo/gen), which writes counters as it runs;
# 2. training renders: every integrator on the scenes below at 96x96, 4 spp.
#    The Cornell box, the benchmark's scene, is left out of the training so
#    the benchmark measures a profile it did not see;
# 3. llvm-profdata (rustup's llvm-tools component, the one that matches
#    rustc's LLVM) merges the counters; the final build (target/pgo/use)
#    reads them;
# 4. a check: the PGO binary and `cargo build --release`'s render the Cornell
#    box and the dispersive prism bit for bit alike with every integrator (PGO
#    changes code layout and inlining, never floating-point semantics), else
#    the script fails.
# The whole script is one block, which bash reads before it runs any of it:
# a file edited during a run (a checkout, a pull) cannot break the run.
{
set -euo pipefail
cd "$(dirname "$0")/.."

OUT=target/pgo
TRAINING="cornell-glossy caustic veach-mis gap-room"

sysroot=$(rustc --print sysroot)
host=$(rustc -vV | sed -n 's/^host: //p')
PROFDATA="$sysroot/lib/rustlib/$host/bin/llvm-profdata"
if [[ ! -x $PROFDATA ]]; then
    echo "== installing rustup's llvm-tools (llvm-profdata)"
    rustup component add llvm-tools
fi

# Appended to .cargo/config.toml's flags (cargo joins the rustflags of every
# matching target table; RUSTFLAGS would replace them).
build() { # TARGET_DIR FLAG
    cargo build --release --quiet --target-dir "$1" --config "target.'cfg(all())'.rustflags = [\"$2\"]"
}

rm -rf "$OUT/profiles"
mkdir -p "$OUT/profiles"
echo "== 1. instrumented build"
build "$OUT/gen" "-Cprofile-generate=$PWD/$OUT/profiles"

echo "== 2. training renders: $TRAINING; path, light, bdpt"
for scene in $TRAINING; do
    for integrator in path light bdpt; do
        "$OUT/gen/release/prism" render "scenes/$scene.json" --integrator "$integrator" --spp 4 \
            --width 96 --height 96 --threads 2 --quiet --out "$OUT/training.exr" 2>/dev/null
    done
done

echo "== 3. merged profile, optimised build"
"$PROFDATA" merge -o "$OUT/prism.profdata" "$OUT/profiles"
build "$OUT/use" "-Cprofile-use=$PWD/$OUT/prism.profdata"
cp "$OUT/use/release/prism" "$OUT/prism"

echo "== 4. same pixels as the plain release build"
cargo build --release --quiet
for scene in cornell-box prism-dispersion; do
    for integrator in path light bdpt; do
        for bin in target/release/prism "$OUT/prism"; do
            "$bin" render "scenes/$scene.json" --integrator "$integrator" --spp 4 --width 64 --height 64 \
                --threads 2 --quiet --out "$OUT/check-$(basename "$(dirname "$bin")").exr" >/dev/null 2>&1
        done
        diff=$(target/release/prism compare "$OUT/check-release.exr" "$OUT/check-pgo.exr")
        if [[ $diff != *" MSE 0.000000e0  MAE 0.000000e0"* ]]; then
            echo "error: $scene, $integrator: the PGO build's pixels differ from the release build's: $diff" >&2
            exit 1
        fi
    done
done
echo "$OUT/prism"
exit
}
