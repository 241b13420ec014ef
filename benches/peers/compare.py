#!/usr/bin/env python3
"""Tabulate a benches/peers/run.sh run: throughput, ratios and error.

Reads target/peers/runs/*.json (one per renderer, its fastest round, written
by run.sh), rounds/*.json (every round's run) and the reference EXR; for each
renderer computes, against the reference, over the images of all its rounds
(each round renders with seeds of its own):
  relMSE  mean over pixels and channels of (x - r)^2 / (r^2 + 0.01)
          (prism's definition, src/stats.rs `rel_mse`), averaged over the
          rounds' images
  mean    the image mean per channel divided by the reference's (R, G, B),
          over the rounds' images: bias between renderers shows here, noise
          averages out
and the equal-time figures: efficiency = 1 / (relMSE' x seconds), and the
relMSE' each renderer would reach in prism path's time (relMSE scales as
1/time for an unbiased estimator: relMSE' x seconds / seconds_prism_path),
where relMSE' is relMSE less the reference's own noise (`noise_floor` of
its sidecar, written by `prism reference`): that noise adds the same
amount to every image's relMSE and does not shrink with the image's time.
Seconds are the fastest round's render wall seconds; the CPU columns use
user+sys seconds of the render (fairer on a machine shared with other jobs).

With ROUNDS > 1, rounds/*.json holds every round's run: the ratio of two
renderers run seconds apart in one round is measured under one load, so the
mean over rounds of those paired ratios, with its standard error (and the
median and range), is the figure a shared, noisy host can still report
(run.sh reverses every other round, so neither renderer of a pair always
runs first); the best-of-rounds ratio needs the
host quiet for the whole run. Prints Markdown and writes results.json next to
the runs, with the machine run.sh recorded (machine.json: CPU, vector ISA,
the target and float lanes of Dr.Jit's LLVM kernels).
"""

import json
import sys
from pathlib import Path

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")

# What results.json keeps of the reference's sidecar.
REFERENCE_KEYS = ("command", "commit", "build_target", "spp", "passes", "seed", "noise_floor")


def load(path):
    return np.array(mi.Bitmap(str(path)), dtype=np.float64)[..., :3]


def per_cpu_second(r):
    """Samples per CPU second; NaN when the render was too short for the
    10 ms resolution of the CPU clock."""
    return r["samples"] / r["cpu_seconds"] if r["cpu_seconds"] > 0 else float("nan")


def rel_mse(x, r):
    return float(np.mean((x - r) ** 2 / (r * r + 0.01)))


def rate(r):
    return r["samples"] / r["wall_seconds"]


def paired_ratios(out, a, b):
    """prism / Mitsuba samples/s of each round that ran both, in round order."""
    ratios = []
    for fa in sorted((out / "rounds").glob(f"{a}-r*.json"), key=lambda f: int(f.stem.rsplit("-r", 1)[1])):
        fb = fa.with_name(fa.name.replace(f"{a}-r", f"{b}-r", 1))
        if fb.exists():
            ratios.append(rate(json.loads(fa.read_text())) / rate(json.loads(fb.read_text())))
    return ratios


def paired_summary(paired):
    """Mean of the paired ratios with its standard error, then median,
    range and count; '-' without any."""
    if not paired:
        return "-"
    se = f" ± {np.std(paired, ddof=1) / np.sqrt(len(paired)):.2f}" if len(paired) > 1 else ""
    return (f"{np.mean(paired):.2f}x{se} (median {np.median(paired):.2f}x, "
            f"{min(paired):.2f}-{max(paired):.2f}, {len(paired)})")


def rounds(out, key):
    """Every round's run of one renderer, in round order."""
    files = (out / "rounds").glob(f"{key}-r*.json")
    return [json.loads(f.read_text()) for f in sorted(files, key=lambda f: int(f.stem.rsplit("-r", 1)[1]))]


def round_rates(out, key):
    return [rate(r) for r in rounds(out, key)]


def image_errors(paths, ref):
    """(relMSE, mean per channel over the reference's) of each image."""
    ref_mean = ref.reshape(-1, 3).mean(0)
    errors = []
    for path in paths:
        img = load(path)
        if img.shape != ref.shape:
            sys.exit(f"error: {path} is {img.shape}, the reference {ref.shape}")
        errors.append((rel_mse(img, ref), img.reshape(-1, 3).mean(0) / ref_mean))
    return errors


def reference_sidecar(ref_path):
    """The reference's sidecar; exits if it lacks the noise estimate that
    `prism reference` has written since session 38."""
    path = ref_path.with_suffix(".json")
    sidecar = json.loads(path.read_text())
    if sidecar.get("noise_floor") is None:
        sys.exit(f"error: {path} has no noise_floor (a reference older than session 38): "
                 f"delete {ref_path} and run run.sh again to render it anew")
    return sidecar


def same_rays(fp, p, fm, m):
    """Exits unless the two ray runs traced the same rays in the same
    triangles: equal counts of rays, passes and triangles, hit fractions
    within 1e-4 (watertight tests may differ on rays through an edge) and
    mean closest-hit t within 1e-5 relative (a moved or mirrored scene
    changes it)."""
    problems = [f"{key}: {p[key]} against {m[key]}" for key in ("rays", "passes", "triangles") if p[key] != m[key]]
    if abs(p["mean_hit_t"] - m["mean_hit_t"]) > 1e-5 * abs(m["mean_hit_t"]):
        problems.append(f"mean closest-hit t: {p['mean_hit_t']:.6f} against {m['mean_hit_t']:.6f}")
    mitsuba_ops = {o["op"]: o for o in m["ops"]}
    for op in p["ops"]:
        mo = mitsuba_ops.get(op["op"])
        if mo is None:
            problems.append(f"no '{op['op']}' query in {fm}")
        elif abs(op["hit_fraction"] - mo["hit_fraction"]) > 1e-4:
            problems.append(f"hit fraction of '{op['op']}': {op['hit_fraction']:.6f} against {mo['hit_fraction']:.6f}")
    if problems:
        sys.exit(f"error: {fp} and {fm} are not the same rays in the same scene: " + "; ".join(problems))


def rays_alone(out):
    """The ray queries of step 5 of run.sh, prism and Mitsuba side by side:
    one row per query and thread count, once `same_rays` has checked that
    the comparison holds."""
    rows = []
    for fp in sorted((out / "rays").glob("prism-*.json")):
        fm = fp.with_name(fp.name.replace("prism-", "mitsuba-"))
        if not fm.exists():
            print(f"warning: {fp} has no Mitsuba counterpart {fm}; left out", file=sys.stderr)
            continue
        p, m = json.loads(fp.read_text()), json.loads(fm.read_text())
        same_rays(fp, p, fm, m)
        mitsuba_seconds = {o["op"]: o["seconds"] for o in m["ops"]}
        for op in p["ops"]:
            rows.append({"op": op["op"], "threads": p["threads"], "rays": p["rays"], "passes": p["passes"],
                         "triangles": p["triangles"], "hit_fraction": op["hit_fraction"],
                         "prism_mrays_s": p["rays"] / op["seconds"] / 1e6,
                         "mitsuba_mrays_s": m["rays"] / mitsuba_seconds[op["op"]] / 1e6, "mitsuba": m["renderer"]})
    if rows:
        r0 = rows[0]
        print(f"\nrays alone: {r0['rays']:,} random rays from inside the scene's box, in the same {r0['triangles']} "
              f"triangles (hit fraction {r0['hit_fraction']:.4f} in both), fastest of {r0['passes']} passes; "
              f"{r0['mitsuba']}. Not the rays of a render: on those Embree is 1.14x faster over a "
              f"sample's rays, all of it on shadow rays (docs/performance-log.md, \"Session 23\")\n")
        print("| query | threads | prism Mrays/s | Mitsuba Mrays/s | prism / Mitsuba |")
        print("|---|---:|---:|---:|---:|")
        for r in sorted(rows, key=lambda r: (r["threads"], r["op"])):
            print(f"| {r['op']} | {r['threads']} | {r['prism_mrays_s']:.1f} | {r['mitsuba_mrays_s']:.1f} "
                  f"| {r['prism_mrays_s'] / r['mitsuba_mrays_s']:.2f}x |")
    return rows


def main():
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "target/peers")
    ref_path = out / "reference.exr"
    ref = load(ref_path)
    reference = reference_sidecar(ref_path)
    noise = reference["noise_floor"]
    rows = []
    for f in sorted((out / "runs").glob("*.json")):
        run = json.loads(f.read_text())
        images = [r["out"] for r in rounds(out, run["key"])] or [run["out"]]
        errors = image_errors(images, ref)
        run["rel_mse_images"] = len(images)
        run["rel_mse"] = float(np.mean([e[0] for e in errors]))
        run["mean_ratio"] = np.mean([e[1] for e in errors], axis=0).tolist()
        net = run["rel_mse"] - noise
        if net <= 0:
            print(f"warning: {run['label']}: relMSE {run['rel_mse']:.3e} is within the reference's own noise "
                  f"{noise:.3e}; its equal-time figures are left out", file=sys.stderr)
        run["rel_mse_net"] = net if net > 0 else float("nan")
        run["efficiency"] = 1.0 / (run["rel_mse_net"] * run["wall_seconds"])
        rows.append(run)
    by_key = {r["key"]: r for r in rows}
    base = by_key.get("prism-path")
    for r in rows:
        r["rel_mse_at_prism_path_time"] = r["rel_mse_net"] * r["wall_seconds"] / base["wall_seconds"] if base else None

    machine_path = out / "machine.json"
    machine = json.loads(machine_path.read_text()) if machine_path.exists() else None
    if machine:
        # The ratios depend on it: Dr.Jit compiles for the host's widest
        # vectors, prism for a fixed level.
        prism_target = base.get("build_target") if base else None
        print(f"machine: {machine['cpu']} (family {machine['cpu_family']}, model {machine['cpu_model']}), "
              f"{machine['cpus']} CPUs; ISA {' '.join(machine['isa'])}; Dr.Jit LLVM kernels for "
              f"{machine['drjit_target_cpu']}, {machine['drjit_float_lanes']} float lanes; prism built for {prism_target}\n")
    print(f"reference: {ref_path} ({reference['command']}; commit {reference.get('commit')}); its own noise "
          f"adds {noise:.3e} to every relMSE, taken out of the equal-time columns (relMSE')\n")
    print("| renderer | samples | render s | CPU s | Msamples/s | Msamples/CPU-s | relMSE (images) | relMSE' at prism-path time | efficiency 1/(relMSE' s) | mean R,G,B / reference |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for r in rows:
        at_path_time = f"{r['rel_mse_at_prism_path_time']:.3e}" if base else "-"
        extra = ""
        if r.get("first_seconds") is not None and r.get("first_seconds") != r["wall_seconds"]:
            extra = f" (first call {r['first_seconds']:.2f} s)"
        print(
            f"| {r['label']} | {r['samples'] / 1e6:.2f} M | {r['wall_seconds']:.2f}{extra} | {r['cpu_seconds']:.2f} "
            f"| {r['samples'] / r['wall_seconds'] / 1e6:.3f} | {per_cpu_second(r) / 1e6:.3f} "
            f"| {r['rel_mse']:.3e} ({r['rel_mse_images']}) | {at_path_time} | {r['efficiency']:.2f} "
            f"| {', '.join(f'{m:.4f}' for m in r['mean_ratio'])} |"
        )
    pairs = [
        ("prism-path", "mitsuba-llvm-path", 2.0),
        ("prism-path", "mitsuba-scalar-path", None),
        ("prism-light", "mitsuba-llvm-ptracer", 2.0),
        ("prism-path", "mitsuba-avx2-path", None),
        ("prism-light", "mitsuba-avx2-ptracer", None),
        ("prism-pgo-path", "mitsuba-llvm-path", 2.0),
        ("prism-pgo-light", "mitsuba-llvm-ptracer", 2.0),
    ]
    print("\n| ratio (prism / Mitsuba) | samples/s (wall) | samples/CPU-s | efficiency (equal time) | paired by round: mean ± se (median, range, rounds) | target (samples/s) |")
    print("|---|---:|---:|---:|---:|---:|")
    ratios = []
    for a, b, target in pairs:
        if a in by_key and b in by_key:
            ra, rb = by_key[a], by_key[b]
            wall = rate(ra) / rate(rb)
            cpu = per_cpu_second(ra) / per_cpu_second(rb)
            eff = ra["efficiency"] / rb["efficiency"]
            paired = paired_ratios(out, a, b)
            ratios.append({"prism": a, "mitsuba": b, "wall": wall, "cpu": cpu, "efficiency": eff, "target": target,
                           "paired_by_round": paired})
            print(f"| {ra['label']} / {rb['label']} | {wall:.2f}x | {cpu:.2f}x | {eff:.2f}x | {paired_summary(paired)} "
                  f"| {f'>= {target:.0f}x' if target else '-'} |")
    for key in ["prism-bdpt", "prism-pgo-bdpt"]:
        if key in by_key:
            r = by_key[key]
            rates = sorted(round_rates(out, key))
            spread = f"; rounds {rates[0] / 1e6:.3f}-{rates[-1] / 1e6:.3f}" if len(rates) > 1 else ""
            print(f"\n{r['label']}: {rate(r) / 1e6:.3f} Msamples/s, best round (target >= 1){spread}")
    rays = rays_alone(out)
    (out / "results.json").write_text(
        json.dumps({"machine": machine, "reference": {k: reference.get(k) for k in REFERENCE_KEYS},
                    "runs": rows, "round_rates": {r["key"]: round_rates(out, r["key"]) for r in rows},
                    "ratios": ratios, "rays_alone": rays}, indent=2) + "\n")


if __name__ == "__main__":
    main()
