#!/usr/bin/env python3
"""Render a scene exported by `prism export-mitsuba` with Mitsuba 3 and time it.

Used by benches/peers/run.sh (see docs/performance.md). The integrator is
chosen here, not in the XML, so one export serves every variant:
  path     Mitsuba's `path` (NEE + BSDF sampling, MIS), max_depth -1
  ptracer  Mitsuba's `ptracer` (light / particle tracing), max_depth -1
Both use rr_depth 4: prism's roulette starts after 4 scattering events.

The scene is rendered --repeat times (seeds 0, 1, ...). The first call in a
process includes Dr.Jit's kernel compilation (or loading it from the kernel
cache in ~/.drjit) for the LLVM variants; later calls reuse the kernel.
With the LLVM variants, Dr.Jit's kernel history separates compile time
(codegen + backend) from kernel execution time. Prints one JSON object.
"""

import argparse
import json
import resource
import sys
import time

import drjit as dr
import mitsuba as mi


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


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
    ap.add_argument("--out", required=True, help="EXR of the last render (linear sRGB)")
    a = ap.parse_args()

    if a.variant not in mi.variants():
        sys.exit(f"error: Mitsuba {mi.__version__} has no variant {a.variant} (has: {', '.join(mi.variants())})")
    mi.set_variant(a.variant)
    dr.set_thread_count(a.threads)
    llvm = a.variant.startswith("llvm")
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
    for seed in range(a.repeat):
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
