#!/usr/bin/env python3
"""Render time, load + BVH build time and peak memory vs triangle count.

The Cornell box (scenes/cornell-box.json) with a flat icosphere of
20 x 4^k triangles (k = 3..8: 1,280 to 1,310,720) resting on the short
block; each is rendered by `prism render` (path, --spp, --res, --threads)
under /usr/bin/time -v. Per scene it records:
  render_s     the render's wall seconds (from the sidecar)
  setup_s      process wall minus render: JSON parse, tessellation, BVH
               build, EXR write (the criterion bench benches/bvh.rs times
               the BVH build alone)
  peak_rss_mb  maximum resident set size of the process
  bytes_per_tri  (peak RSS - peak RSS of the empty box) / triangles
Writes OUT/scaling.csv and OUT/render-time-vs-triangles.svg (log-x: a
BVH's log n growth is a straight line there) and prints a Markdown table.
Standard library only; run from the repository root:
  python3 benches/peers/scaling.py [--spp 16] [--res 128] [--threads 2] [--out target/peers/scaling]
"""

import argparse
import json
import math
import re
import subprocess
import sys
import time
from pathlib import Path


def run_prism(prism, scene, out_exr, a):
    cmd = ["/usr/bin/time", "-v", prism, "render", str(scene), "--integrator", "path", "--spp", str(a.spp),
           "--width", str(a.res), "--height", str(a.res), "--threads", str(a.threads), "--quiet", "--out", str(out_exr)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        sys.exit(f"error: {' '.join(cmd)} failed:\n{p.stderr}")
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr).group(1))
    side = json.loads(out_exr.with_suffix(".json").read_text())
    return {"process_s": wall, "render_s": side["wall_seconds"], "peak_rss_mb": rss_kb / 1024,
            "msamples_per_s": side["samples_per_second"] / 1e6, "mrays_per_s": side["mrays_per_second"]}


def svg_chart(rows, path):
    w, h, m = 640, 400, 60
    xs = [math.log10(r["triangles"]) for r in rows]
    ys = [r["render_s"] for r in rows]
    x0, x1 = math.floor(min(xs)), math.ceil(max(xs))
    y1 = max(ys) * 1.15
    px = lambda x: m + (x - x0) / (x1 - x0) * (w - 2 * m)  # noqa: E731
    py = lambda y: h - m - y / y1 * (h - 2 * m)  # noqa: E731
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<line x1="{m}" y1="{h - m}" x2="{w - m}" y2="{h - m}" stroke="black"/>',
           f'<line x1="{m}" y1="{m}" x2="{m}" y2="{h - m}" stroke="black"/>',
           f'<text x="{w / 2}" y="{h - 15}" text-anchor="middle">triangles (log scale)</text>',
           f'<text x="15" y="{h / 2}" transform="rotate(-90 15 {h / 2})" text-anchor="middle">render seconds</text>',
           f'<text x="{w / 2}" y="25" text-anchor="middle">prism path: Cornell box + icosphere, render time vs triangles</text>']
    for e in range(x0, x1 + 1):
        out.append(f'<text x="{px(e)}" y="{h - m + 18}" text-anchor="middle">1e{e}</text>')
        out.append(f'<line x1="{px(e)}" y1="{h - m}" x2="{px(e)}" y2="{h - m + 5}" stroke="black"/>')
    for k in range(5):
        y = y1 * k / 4
        out.append(f'<text x="{m - 8}" y="{py(y) + 4}" text-anchor="end">{y:.2f}</text>')
    pts = " ".join(f"{px(x):.1f},{py(y):.1f}" for x, y in zip(xs, ys))
    out.append(f'<polyline points="{pts}" fill="none" stroke="#1f77b4" stroke-width="2"/>')
    for x, y in zip(xs, ys):
        out.append(f'<circle cx="{px(x):.1f}" cy="{py(y):.1f}" r="4" fill="#1f77b4"/>')
    out.append("</svg>")
    path.write_text("\n".join(out) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--levels", default="3,4,5,6,7,8", help="icosphere subdivision levels")
    ap.add_argument("--prism", default="target/release/prism")
    ap.add_argument("--out", default="target/peers/scaling")
    a = ap.parse_args()
    if not Path("/usr/bin/time").exists():
        sys.exit("error: the peak memory is read by GNU time, /usr/bin/time; run: sudo apt-get install time")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    base = json.loads(Path("scenes/cornell-box.json").read_text())
    base.pop("comment", None)
    rows = []
    for level in [None] + [int(k) for k in a.levels.split(",")]:
        scene = json.loads(json.dumps(base))
        tris = 32
        if level is not None:
            scene["objects"].append({"name": "icosphere", "material": "white", "shape": {
                "type": "sphere", "center": [186.0, 265.0, 168.0], "radius": 100.0, "subdivisions": level}})
            tris += 20 * 4**level
        path = out / f"scene-{tris}.json"
        path.write_text(json.dumps(scene))
        r = run_prism(a.prism, path, out / f"render-{tris}.exr", a)
        r["triangles"] = tris
        rows.append(r)
        print(f"  {tris:>9} triangles: render {r['render_s']:.2f} s, setup {r['process_s'] - r['render_s']:.2f} s, "
              f"peak RSS {r['peak_rss_mb']:.1f} MB", file=sys.stderr)
    empty = rows[0]["peak_rss_mb"]
    for r in rows:
        r["setup_s"] = r["process_s"] - r["render_s"]
        extra = r["triangles"] - rows[0]["triangles"]
        r["bytes_per_tri"] = (r["peak_rss_mb"] - empty) * 2**20 / extra if extra > 0 else None
    with open(out / "scaling.csv", "w") as f:
        keys = ["triangles", "render_s", "setup_s", "process_s", "peak_rss_mb", "bytes_per_tri", "msamples_per_s",
                "mrays_per_s"]
        f.write(",".join(keys) + "\n")
        for r in rows:
            f.write(",".join("" if r[k] is None else str(r[k]) if isinstance(r[k], int) else f"{r[k]:.6g}" for k in keys))
            f.write("\n")
    svg_chart(rows, out / "render-time-vs-triangles.svg")
    print(f"prism path, {a.res}x{a.res}, {a.spp} spp, {a.threads} threads\n")
    print("| triangles | render s | Mrays/s | setup s (load + BVH + write) | peak RSS MB | bytes/triangle (RSS over empty box) |")
    print("|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        bpt = f"{r['bytes_per_tri']:.0f}" if r["bytes_per_tri"] is not None else "-"
        print(f"| {r['triangles']:,} | {r['render_s']:.2f} | {r['mrays_per_s']:.2f} | {r['setup_s']:.2f} "
              f"| {r['peak_rss_mb']:.1f} | {bpt} |")


if __name__ == "__main__":
    main()
