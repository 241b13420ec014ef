# Scratch script of session 22 (docs/performance-log.md, "Session 22"), kept as a record: run with the
# peers venv and DRJIT_LIBLLVM_PATH set; its argument is the ray log that ray-log.patch makes prism write.
# Mitsuba (Embree) on the rays a prism `path` render traced: kind 0 bounce, 1 shadow, 2 camera.
import sys, time, numpy as np, drjit as dr, mitsuba as mi
mi.set_variant("llvm_ad_spectral"); dr.set_thread_count(1)
scene = mi.load_file("/work/main/target/peers/mitsuba-scene/scene.xml")
raw = np.fromfile(sys.argv[1], dtype="<f4").reshape(-1, 10)
def rays(kind):
    r = raw[raw[:, 0] == kind]
    d = r[:, 4:7].astype(np.float64); n = np.linalg.norm(d, axis=1)
    dn = (d / n[:, None]).astype(np.float32); tmax = (r[:, 7].astype(np.float64) * n).astype(np.float32)
    ray = mi.Ray3f(mi.Point3f(*(mi.Float(r[:, i]) for i in (1, 2, 3))), mi.Vector3f(*(mi.Float(dn[:, i]) for i in range(3))))
    ray = mi.Ray3f(ray, mi.Float(tmax)); dr.eval(ray)
    return ray, len(r)
def best(f):
    b = 1e9
    for _ in range(7):
        dr.sync_thread(); t = time.perf_counter(); out = f(); dr.eval(out); dr.sync_thread(); b = min(b, time.perf_counter() - t)
    return b, out
for kind, name in ((0, "bounce"), (2, "camera")):
    r, n = rays(kind)
    tc, pc = best(lambda: (lambda p: (p.t, p.prim_index, p.prim_uv))(scene.ray_intersect_preliminary(r)))
    tsi, _ = best(lambda: (lambda s: (s.t, s.p, s.n, s.sh_frame.s, s.sh_frame.t, s.sh_frame.n, s.uv, s.wi))(scene.ray_intersect(r)))
    t = np.array(pc[0], dtype=np.float64); h = np.isfinite(t)
    print(f"{name}: {n} rays, hit {h.mean():.4f}, mean hit t {t[h].mean():.4f}, {tc/n*1e9:.1f} ns/ray, with surface interaction {tsi/n*1e9:.1f} ns")
r, n = rays(1)
ts, ps = best(lambda: scene.ray_test(r))
print(f"shadow: {n} rays, occluded {np.array(ps).mean():.4f}, {ts/n*1e9:.1f} ns/ray")
