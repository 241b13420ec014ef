#!/usr/bin/env python3
"""Render a scene exported by `prism export-mitsuba` with Mitsuba 3 and time it.

Used by benches/peers/run.sh (see docs/performance.md). The integrator is
chosen here, not in the XML, so one export serves every variant:
  path     Mitsuba's `path` (NEE + BSDF sampling, MIS), max_depth -1
  ptracer  Mitsuba's `ptracer` (light / particle tracing), max_depth -1
Both use rr_depth 4: prism's roulette starts after 4 scattering events.

With --avx2, the LLVM kernels are compiled for x86-64-v3 with 8 float
lanes whatever the host has (Dr.Jit's `jit_llvm_set_target`), so that on
an AVX-512 host Mitsuba runs at an AVX2 host's width (docs/performance.md).

The scene is rendered --repeat times (seeds --seed, --seed + 1, ...; run.sh
gives each round seeds of its own, so that the rounds' images are
independent and their relMSE can be averaged). The first call in a
process includes Dr.Jit's kernel compilation (or loading it from the kernel
cache in ~/.drjit) for the LLVM variants; later calls reuse the kernel.
With the LLVM variants, Dr.Jit's kernel history separates compile time
(codegen + backend) from kernel execution time. Prints one JSON object.
"""

import argparse
import ctypes
import json
import os
import resource
import sys
import time

import drjit as dr
import mitsuba as mi


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def hold_to_avx2():
    """Has Dr.Jit compile the current LLVM variant's kernels for x86-64-v3
    (AVX2, FMA) with 8 float lanes. The C API function is not in the Python
    bindings: it is called in libdrjit-core.so by its C++ symbol,
    jit_llvm_set_target(const char *cpu, const char *features, uint32_t width).
    Exits if Dr.Jit does not then report 8 lanes."""
    lib = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
    set_target = lib["_Z19jit_llvm_set_targetPKcS0_j"]
    set_target.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
    features = b"+avx,+avx2,+fma,+f16c,+bmi,+bmi2,+lzcnt,+popcnt,+sse4.1,+sse4.2,+ssse3"
    set_target(b"x86-64-v3", features, 8)
    width = lib["_Z21jit_llvm_vector_widthv"]
    width.restype = ctypes.c_uint32
    if width() != 8:
        sys.exit(f"error: Dr.Jit reports {width()} float lanes after jit_llvm_set_target(x86-64-v3, AVX2, 8)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "scene",
        help="scene.xml written by prism export-mitsuba, or 'builtin' for Mitsuba's own mi.cornell_box() "
        "(a control: is the exported scene slower for Mitsuba than its own?)",
    )
    ap.add_argument("--variant", required=True, help="e.g. llvm_ad_spectral, scalar_spectral")
    ap.add_argument("--integrator", choices=["path", "ptracer"], default="path")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--width", type=int, default=256)
    ap.add_argument("--height", type=int, default=256)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=2, help="renders in this process (the first includes the JIT)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the first render; the others follow it")
    ap.add_argument("--out", required=True, help="EXR of the last render (linear sRGB)")
    ap.add_argument("--avx2", action="store_true", help="LLVM kernels for x86-64-v3, 8 float lanes (see above)")
    a = ap.parse_args()

    if a.variant not in mi.variants():
        sys.exit(f"error: Mitsuba {mi.__version__} has no variant {a.variant} (has: {', '.join(mi.variants())})")
    mi.set_variant(a.variant)
    dr.set_thread_count(a.threads)
    llvm = a.variant.startswith("llvm")
    if a.avx2:
        if not llvm:
            sys.exit(f"error: --avx2 needs an LLVM variant (not {a.variant})")
        hold_to_avx2()
    if llvm:
        dr.set_flag(dr.JitFlag.KernelHistory, True)

    t = time.perf_counter()
    if a.scene == "builtin":
        box = mi.cornell_box()
        box["sensor"]["film"].update(width=a.width, height=a.height)
        scene = mi.load_dict(box)
    else:
        scene = mi.load_file(a.scene, spp=a.spp, width=a.width, height=a.height)
    load_seconds = time.perf_counter() - t
    integrator = mi.load_dict({"type": a.integrator, "max_depth": -1, "rr_depth": 4})

    runs = []
    image = None
    for seed in range(a.seed, a.seed + a.repeat):
        if llvm:
            dr.kernel_history()  # clear
        c0, t0 = cpu_seconds(), time.perf_counter()
        image = mi.render(scene, integrator=integrator, spp=a.spp, seed=seed)
        dr.eval(image)
        dr.sync_thread()
        wall = time.perf_counter() - t0
        run = {"seed": seed, "wall_seconds": wall, "cpu_seconds": cpu_seconds() - c0}
        if llvm:
            hist = dr.kernel_history()
            ms = lambda key: sum(k.get(key, 0.0) for k in hist) / 1e3  # noqa: E731
            run.update(
                kernels=len(hist),
                cache_hits=sum(1 for k in hist if k.get("cache_hit")),
                compile_seconds=ms("codegen_time") + ms("backend_time"),
                execution_seconds=ms("execution_time"),
            )
        runs.append(run)

    mi.Bitmap(image).write(a.out)
    samples = a.spp * a.width * a.height
    best = min(r["wall_seconds"] for r in runs[1:]) if len(runs) > 1 else runs[0]["wall_seconds"]
    print(
        json.dumps(
            {
                "renderer": f"mitsuba {mi.__version__} {a.variant} {a.integrator}",
                "variant": a.variant,
                "lanes": "avx2 (8)" if a.avx2 else "host",
                "integrator": a.integrator,
                "spp": a.spp,
                "width": a.width,
                "height": a.height,
                "threads": a.threads,
                "load_seconds": load_seconds,
                "runs": runs,
                "first_seconds": runs[0]["wall_seconds"],
                "warm_seconds": best,
                "samples": samples,
                "samples_per_second": samples / best,
                "out": a.out,
            }
        )
    )


if __name__ == "__main__":
    main()
