#!/usr/bin/env bash
# prism vs Mitsuba 3 on the same scene, back to back (docs/performance.md).
#
#   benches/peers/run.sh            # from the repository root
#
# 1. a virtual environment target/peers-venv with Mitsuba (pinned) from PyPI;
# 2. a libLLVM >= 19 for Mitsuba's LLVM variants (Dr.Jit loads it at run
#    time; Debian 12's libLLVM 15 aborts with "Cannot select: fminimum");
#    installed with apt if root, else the apt command is printed;
# 3. `prism export-mitsuba` writes scenes/cornell-box.json as Mitsuba XML + PLY;
# 4. renders, back to back, SPP spp at RESxRES on THREADS threads:
#    prism path, light, bdpt; Mitsuba scalar_spectral path,
#    llvm_ad_spectral path, llvm_ad_spectral ptracer;
# 5. the rays alone: `examples/peer_rays.rs` writes 2^22 incoherent rays
#    and times prism's ray queries on them, benches/peers/mitsuba_rays.py
#    Mitsuba's (Embree's) on the same rays, at 1 and THREADS threads;
# 6. a high-spp prism reference (cached: delete target/peers/reference.exr
#    to remake it), then compare.py prints the table (relMSE, equal-time
#    efficiency, ratios, the rays alone).
# Environment: SPP (64), RES (256), THREADS (2), REF_SPP (2048), ROUNDS (1:
# with more, every renderer runs ROUNDS times, interleaved, and the fastest
# round counts; compare.py also gives each round's own prism / Mitsuba
# ratio, which a load that changes between rounds does not skew), SCENE
# (scenes/cornell-box.json), OUT (target/peers), VENV (target/peers-venv),
# PGO (0: with 1, scripts/pgo-build.sh makes a profile-guided build too, and
# its path, light and bdpt run beside the plain build's in every round; ~5
# minutes more).
# AVX2 (0: with 1, Mitsuba's LLVM path and ptracer also run with their
# kernels compiled for x86-64-v3 with 8 float lanes, in every round: on an
# AVX-512 host, Mitsuba at an AVX2 host's width; ~1 minute more).
# Even rounds run the renderers in reverse order (ABBA), so that the paired
# ratios compare.py reports are not biased towards the first of a pair.
# ONLY (all renderers; e.g. "prism-path mitsuba-llvm-path"): run just these
# in each round (the keys of run() below), e.g. many cheap rounds of one
# pair for its paired ratio on a noisy host. RAYS (1: with 0, step 5, the
# rays alone, is skipped).
# The whole script is one block, which bash reads before it runs any of it:
# a file edited during a run (a checkout, a pull) cannot break the run.
{
set -euo pipefail
cd "$(dirname "$0")/../.."

SPP=${SPP:-64}
RES=${RES:-256}
THREADS=${THREADS:-2}
REF_SPP=${REF_SPP:-2048}
ROUNDS=${ROUNDS:-1}
SCENE=${SCENE:-scenes/cornell-box.json}
OUT=${OUT:-target/peers}
VENV=${VENV:-target/peers-venv}
MITSUBA_VERSION=3.9.1
DRJIT_VERSION=1.5.0
NUMPY_VERSION=2.1.3
REF_PASSES=8

for v in SPP RES THREADS REF_SPP ROUNDS; do
    if ! [[ ${!v} =~ ^[1-9][0-9]*$ ]]; then
        echo "error: $v must be a positive integer (is '${!v}')" >&2
        exit 1
    fi
done
PGO=${PGO:-0}
AVX2=${AVX2:-0}
RAYS=${RAYS:-1}
# The renderers of a round (the keys of run() below), or ONLY's.
KEYS=(prism-path mitsuba-llvm-path mitsuba-scalar-path prism-light mitsuba-llvm-ptracer)
[[ $AVX2 == 1 ]] && KEYS+=(mitsuba-avx2-path mitsuba-avx2-ptracer)
KEYS+=(prism-bdpt)
[[ $PGO == 1 ]] && KEYS+=(prism-pgo-path prism-pgo-light prism-pgo-bdpt)
if [[ -n ${ONLY:-} ]]; then
    read -rd '' -a KEYS <<<"$ONLY" || true
    if (( ${#KEYS[@]} == 0 )); then
        echo "error: ONLY names no renderer" >&2
        exit 1
    fi
    for key in "${KEYS[@]}"; do
        case $key in
            prism-path | prism-light | prism-bdpt | mitsuba-llvm-path | mitsuba-scalar-path | mitsuba-llvm-ptracer | \
                mitsuba-avx2-path | mitsuba-avx2-ptracer) ;;
            prism-pgo-path | prism-pgo-light | prism-pgo-bdpt)
                [[ $PGO == 1 ]] || { echo "error: ONLY names $key, which needs PGO=1" >&2; exit 1; } ;;
            *) echo "error: ONLY names '$key', not a renderer (prism-path, mitsuba-llvm-path, ...: run.sh's run())" >&2
                exit 1 ;;
        esac
    done
fi
if [[ $RAYS != [01] ]]; then
    echo "error: RAYS must be 0 or 1 (is '$RAYS')" >&2
    exit 1
fi
if (( REF_SPP % REF_PASSES != 0 )); then
    echo "error: REF_SPP ($REF_SPP) must be a multiple of $REF_PASSES" >&2
    exit 1
fi

# Debian packages the script needs: installed when it runs as root, else
# it names them and stops.
apt_install() { # PACKAGE... (WHY)
    local why=${*: -1} packages=("${@:1:$#-1}")
    if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null; then
        echo "== installing ${packages[*]} (apt-get install -y ${packages[*]}): $why"
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y "${packages[@]}" >/dev/null ||
            { apt-get update >/dev/null && apt-get install -y "${packages[@]}" >/dev/null; }
    else
        echo "error: $why; run: sudo apt-get install ${packages[*]}" >&2
        exit 1
    fi
}
# GNU time reads the renders' CPU seconds (step 4).
[[ -x /usr/bin/time ]] || apt_install time "the CPU seconds of each render are read by /usr/bin/time"

# --- 1. Mitsuba in a venv
if ! "$VENV/bin/python" -c "import mitsuba, sys; sys.exit(mitsuba.__version__ != '$MITSUBA_VERSION')" 2>/dev/null; then
    echo "== installing mitsuba==$MITSUBA_VERSION into $VENV"
    python3 -c 'import ensurepip' 2>/dev/null || apt_install python3-venv "python3 -m venv needs ensurepip"
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install --quiet "mitsuba==$MITSUBA_VERSION" "drjit==$DRJIT_VERSION" "numpy==$NUMPY_VERSION"
fi
PY="$VENV/bin/python"

# --- 2. libLLVM >= 19
find_llvm() {
    local f
    for f in /usr/lib/x86_64-linux-gnu/libLLVM.so.{21,20,19}* /usr/lib/x86_64-linux-gnu/libLLVM-{21,20,19}.so \
        /usr/lib/llvm-{21,20,19}/lib/libLLVM.so*; do
        [[ -e $f ]] && { echo "$f"; return 0; }
    done
    return 1
}
if [[ -z ${DRJIT_LIBLLVM_PATH:-} ]]; then
    if ! DRJIT_LIBLLVM_PATH=$(find_llvm); then
        apt_install libllvm19 "Mitsuba's LLVM variants need libLLVM >= 19"
        DRJIT_LIBLLVM_PATH=$(find_llvm)
    fi
fi
export DRJIT_LIBLLVM_PATH

# --- 3. prism and the exported scene
CARGO_BUILD_JOBS=${CARGO_BUILD_JOBS:-1} cargo build --release --quiet --bins --example peer_rays
PRISM=target/release/prism
# (Only when a round runs the PGO binary: ONLY may name none of its keys.)
if [[ " ${KEYS[*]} " == *" prism-pgo-"* ]]; then
    echo "== profile-guided build (scripts/pgo-build.sh)"
    scripts/pgo-build.sh >/dev/null
fi
mkdir -p "$OUT/runs" "$OUT/rounds" "$OUT/images"
rm -f "$OUT"/runs/*.json "$OUT"/rounds/*.json
"$PRISM" export-mitsuba "$SCENE" "$OUT/mitsuba-scene" --width "$RES" --height "$RES" --spp "$SPP"

# The machine, and the vector width each renderer compiles for: Dr.Jit JITs
# Mitsuba's LLVM kernels for the host (16 float lanes where it has
# AVX-512), prism is built for a fixed level (.cargo/config.toml), so the
# ratios depend on the host's vector ISA (docs/performance-log.md, "Session 16").
cpu_field() { sed -n "s/^$1[[:space:]]*: *//p" /proc/cpuinfo | head -1; }
# Where the host has more CPUs than THREADS, every timed run is pinned to
# as many CPUs as it has threads (the first of those this process may
# use), so that neither renderer can use more CPUs than it is given (an
# audit, session 50). Dr.Jit's pool of THREADS counts the thread that
# waits on a task, which helps with its work (nanothread.h: THREADS - 1
# workers), so Mitsuba runs THREADS threads either way (session 55). On a
# host of THREADS CPUs nothing is pinned.
PINNED=$( (( $(nproc) > THREADS )) && command -v taskset >/dev/null && echo true || echo false)
pinned() { # N COMMAND...: COMMAND on N CPUs if PINNED
    local n=$1
    shift
    if [[ $PINNED == true ]]; then
        taskset -c "$("$PY" -c 'import os, sys; print(",".join(map(str, sorted(os.sched_getaffinity(0))[:int(sys.argv[1])])))' "$n")" "$@"
    else
        "$@"
    fi
}
DRJIT_IR=$("$PY" -c 'import drjit as dr; dr.set_log_level(dr.LogLevel.Trace); dr.eval(dr.llvm.Float(1, 2) + 1)' 2>&1 || true)
"$PY" - "$OUT/machine.json" <<PYEOF
import json, sys
flags = set("$(cpu_field flags)".split())
json.dump({
    "cpu": "$(cpu_field 'model name')", "cpu_family": "$(cpu_field 'cpu family')", "cpu_model": "$(cpu_field model)",
    "cpus": $(nproc), "pinned": $( [[ $PINNED == true ]] && echo True || echo False), "load_at_start": "$(cut -d' ' -f1-3 /proc/loadavg)",
    "isa": [f for f in ("avx2", "fma", "avx512f", "avx512vl") if f in flags],
    "drjit_target_cpu": "$(grep -o '"target-cpu"="[^"]*"' <<<"$DRJIT_IR" | head -1 | cut -d'"' -f4)",
    "drjit_float_lanes": "$(grep -o '<[0-9]* x float>' <<<"$DRJIT_IR" | head -1 | tr -dc 0-9)",
}, open(sys.argv[1], "w"), indent=2)
PYEOF
echo "== machine: $(cpu_field 'model name') (family $(cpu_field 'cpu family'), model $(cpu_field model)), $(nproc) CPUs, load $(cut -d' ' -f1-3 /proc/loadavg)$( [[ $PINNED == true ]] && echo "; timed runs pinned to as many CPUs as they have threads")"
echo "== vector ISA: $("$PY" -c 'import json, sys; m = json.load(open(sys.argv[1])); print(" ".join(m["isa"]) + "; Dr.Jit compiles for", m["drjit_target_cpu"], "with", m["drjit_float_lanes"], "float lanes")' "$OUT/machine.json")"
echo "== $("$PY" -c 'import mitsuba, drjit; print("mitsuba", mitsuba.__version__, "drjit", drjit.__version__, "libLLVM", ".".join(map(str, drjit.detail.llvm_version())))')"

# --- 4. renders, back to back; each writes $OUT/runs/<key>.json for compare.py
# keep_best KEY ROUND JSON: keeps this round's run in rounds/, and in runs/
# the faster of it and an earlier round's run.
keep_best() {
    echo "$3" >"$OUT/rounds/$1-r$2.json"
    "$PY" - "$OUT/runs/$1.json" "$3" <<'PYEOF'
import json, sys
path, new = sys.argv[1], json.loads(sys.argv[2])
try:
    old = json.load(open(path))
    if old["wall_seconds"] <= new["wall_seconds"]:
        new = old
except FileNotFoundError:
    pass
json.dump(new, open(path, "w"))
PYEOF
}

summary() { # KEY JSON: one progress line
    "$PY" - "$1" "$2" <<'PYEOF'
import json, sys
key, r = sys.argv[1], json.loads(sys.argv[2])
first = f" (first call {r['first_seconds']:.2f} s)" if r.get("first_seconds") else ""
print(f"   {key}: {r['wall_seconds']:.2f} s{first}, CPU {r['cpu_seconds']:.2f} s, "
      f"{r['samples'] / r['wall_seconds'] / 1e6:.3f} Msamples/s")
PYEOF
}

prism_run() { # KEY INTEGRATOR ROUND [BINARY]
    local exr="$OUT/images/$1-r$3.exr" t bin=${4:-$PRISM}
    t=$(mktemp)
    pinned "$THREADS" /usr/bin/time -f '%U %S' -o "$t" "$bin" render "$SCENE" --integrator "$2" --spp "$SPP" --width "$RES" \
        --height "$RES" --threads "$THREADS" --seed "$3" --quiet --out "$exr"
    local json
    json=$("$PY" - "$exr" "$t" "$1" "$2" <<'PYEOF'
import json, sys
exr, t, key, integrator = sys.argv[1:]
side = json.load(open(exr.replace(".exr", ".json")))
user, sys_ = map(float, open(t).read().split()[-2:])
label = f"prism {integrator}" + (" (PGO build)" if key.startswith("prism-pgo") else "")
print(json.dumps({"key": key, "label": label, "out": exr, "samples": side["spp"] * side["width"] * side["height"],
                  "build_target": side.get("build_target"), "wall_seconds": side["wall_seconds"], "cpu_seconds": user + sys_, "first_seconds": None,
                  "note": "CPU s: whole process (scene load and BVH build included, a few ms)"}))
PYEOF
)
    rm -f "$t"
    summary "$1" "$json"
    keep_best "$1" "$3" "$json"
}

mitsuba_run() { # KEY VARIANT INTEGRATOR ROUND [--avx2]
    local exr="$OUT/images/$1-r$4.exr" raw
    local repeat=2
    [[ $2 == scalar_* ]] && repeat=1 # no JIT: one render is the measurement
    # Kernels compiled for another target are cached apart from the host's.
    local cache=()
    [[ -n ${5:-} ]] && cache=("DRJIT_CACHE_DIR=$OUT/drjit-cache-avx2")
    raw=$(pinned "$THREADS" env "${cache[@]}" "$PY" benches/peers/mitsuba_render.py "$OUT/mitsuba-scene/scene.xml" \
        --variant "$2" --integrator "$3" --spp "$SPP" --width "$RES" --height "$RES" --threads "$THREADS" \
        --repeat "$repeat" --seed $(( ($4 - 1) * repeat )) --out "$exr" ${5:-})
    local json
    json=$("$PY" - "$raw" "$1" <<'PYEOF'
import json, sys
r, key = json.loads(sys.argv[1]), sys.argv[2]
last = r["runs"][-1]
lanes = " (AVX2, 8 lanes)" if r["lanes"] != "host" else ""
r.update(key=key, label=f"Mitsuba {r['variant']} {r['integrator']}{lanes}", wall_seconds=last["wall_seconds"],
         cpu_seconds=last["cpu_seconds"])
print(json.dumps(r))
PYEOF
)
    summary "$1" "$json"
    keep_best "$1" "$4" "$json"
}

# run KEY ROUND: one renderer's render in a round.
run() {
    case $1 in
        prism-path) prism_run "$1" path "$2" ;;
        prism-light) prism_run "$1" light "$2" ;;
        prism-bdpt) prism_run "$1" bdpt "$2" ;;
        prism-pgo-*) prism_run "$1" "${1#prism-pgo-}" "$2" target/pgo/prism ;;
        mitsuba-llvm-path) mitsuba_run "$1" llvm_ad_spectral path "$2" ;;
        mitsuba-scalar-path) mitsuba_run "$1" scalar_spectral path "$2" ;;
        mitsuba-llvm-ptracer) mitsuba_run "$1" llvm_ad_spectral ptracer "$2" ;;
        mitsuba-avx2-path) mitsuba_run "$1" llvm_ad_spectral path "$2" --avx2 ;;
        mitsuba-avx2-ptracer) mitsuba_run "$1" llvm_ad_spectral ptracer "$2" --avx2 ;;
    esac
}

# Odd rounds run the renderers in KEYS' order, even rounds in reverse
# (ABBA), so a load that drifts within a round does not favour whichever
# renderer of a pair comes first.
for round in $(seq 1 "$ROUNDS"); do
    echo "== round $round of $ROUNDS: ${RES}x${RES}, $SPP spp, $THREADS threads"
    order=("${KEYS[@]}")
    if (( round % 2 == 0 )); then
        for ((i = ${#KEYS[@]} - 1, j = 0; i >= 0; i--, j++)); do order[j]=${KEYS[i]}; done
    fi
    for key in "${order[@]}"; do
        run "$key" "$round"
    done
done

# --- 5. rays alone: prism's traversal and Mitsuba's (Embree) on the same
# incoherent rays in the same scene, at 1 and THREADS threads; compare.py
# tabulates them beside the renders.
# Each result is written under a temporary name and moved into place, so a
# failed run leaves no partial JSON; the 100 MB ray file is removed either way.
mkdir -p "$OUT/rays"
rm -f "$OUT"/rays/*.json
trap 'rm -f "$OUT/rays/rays.f32" "$OUT"/rays/*.tmp' EXIT
thread_counts=$(printf '%s\n' 1 "$THREADS" | sort -un)
[[ $RAYS == 1 ]] || thread_counts=
for t in $thread_counts; do
    echo "== rays alone, $t thread(s)"
    pinned "$t" target/release/examples/peer_rays "$SCENE" "$OUT/rays/rays.f32" "$t" >"$OUT/rays/prism-$t.tmp"
    pinned "$t" "$PY" benches/peers/mitsuba_rays.py "$OUT/mitsuba-scene/scene.xml" "$OUT/rays/rays.f32" "$t" \
        >"$OUT/rays/mitsuba-$t.tmp"
    mv "$OUT/rays/prism-$t.tmp" "$OUT/rays/prism-$t.json"
    mv "$OUT/rays/mitsuba-$t.tmp" "$OUT/rays/mitsuba-$t.json"
done

# --- 6. reference and table
REF="$OUT/reference.exr"
# Reused only if it matches the run and is newer than the scene file and
# the prism binary (an edited scene or a changed engine needs a new one).
if ! [ "$OUT/reference.json" -nt "$SCENE" ] || ! [ "$OUT/reference.json" -nt "$PRISM" ] ||
    ! "$PY" -c "import json,sys; m=json.load(open('$OUT/reference.json')); sys.exit(not (m['spp']*m['passes']==$REF_SPP and m['width']==$RES and m['scene']=='$SCENE'))" 2>/dev/null; then
    echo "== reference: prism path, $REF_SPP spp ($REF_PASSES passes, seeds 1000.., independent of the runs' seeds)"
    "$PRISM" reference "$SCENE" --integrator path --spp $((REF_SPP / REF_PASSES)) --passes $REF_PASSES \
        --width "$RES" --height "$RES" --threads "$THREADS" --out "$REF"
fi
"$PY" benches/peers/compare.py "$OUT" | tee "$OUT/table.md"
exit
}
