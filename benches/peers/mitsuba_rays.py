#!/usr/bin/env python3
"""Mitsuba's half of the ray-throughput comparison (benches/peers/run.sh, step 5).

  mitsuba_rays.py SCENE_XML RAYS THREADS

Traces the rays that `cargo run --release --example peer_rays` wrote (f32
ox, oy, oz, dx, dy, dz per ray) in the exported scene with the
llvm_ad_spectral variant, whose ray queries are Embree's (MI_ENABLE_EMBREE
in the PyPI build): one kernel over all rays per query, its results written
to memory (in a render, Dr.Jit compiles the whole path loop into one kernel
instead, and the results stay in registers). The fastest of PASSES passes
of each query counts; the first pass also compiles the kernel. Prints one
JSON object, in the form of peer_rays's:
  closest  ray_intersect_preliminary: t, primitive, barycentrics
  shadow   ray_test (any hit, t_max infinite)
  surface  ray_intersect, with t, p, n, the shading frame, uv and wi
           evaluated (Dr.Jit computes only what is evaluated)
"""

import json
import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np

PASSES = 7


def main():
    scene_xml, rays_path, threads = sys.argv[1], sys.argv[2], int(sys.argv[3])
    mi.set_variant("llvm_ad_spectral")
    dr.set_thread_count(threads)
    scene = mi.load_file(scene_xml)
    raw = np.fromfile(rays_path, dtype="<f4").reshape(-1, 6)
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(raw[:, i]) for i in range(3))),
                   mi.Vector3f(*(mi.Float(raw[:, 3 + i]) for i in range(3))))
    dr.eval(ray)
    queries = [
        ("closest", lambda: (lambda p: (p.t, p.prim_index, p.prim_uv))(scene.ray_intersect_preliminary(ray)),
         lambda out: dr.isfinite(out[0])),
        ("shadow", lambda: scene.ray_test(ray), lambda out: out),
        ("surface", lambda: (lambda s: (s.t, s.p, s.n, s.sh_frame.s, s.sh_frame.t, s.sh_frame.n, s.uv, s.wi))(
            scene.ray_intersect(ray)), lambda out: dr.isfinite(out[0])),
    ]
    ops = []
    for name, query, hit in queries:
        best = float("inf")
        for _ in range(PASSES):
            dr.sync_thread()
            start = time.perf_counter()
            out = query()
            dr.eval(out)
            dr.sync_thread()
            best = min(best, time.perf_counter() - start)
        fraction = dr.mean(mi.Float(hit(out)))
        ops.append({"op": name, "seconds": best, "hit_fraction": float(np.array(fraction).ravel()[0])})
    t = np.array(scene.ray_intersect_preliminary(ray).t, dtype=np.float64)
    mean_hit_t = float(t[np.isfinite(t)].mean())
    triangles = sum(shape.face_count() for shape in scene.shapes())
    print(json.dumps({"renderer": f"mitsuba {mi.__version__} llvm_ad_spectral (Embree)", "threads": threads,
                      "rays": len(raw), "passes": PASSES, "triangles": triangles, "mean_hit_t": mean_hit_t,
                      "ops": ops}))


if __name__ == "__main__":
    main()
