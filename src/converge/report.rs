//! The files a run writes: results.csv, results.json, report.md, the
//! charts, the image panels and (`--save-exr`) the final images, moved into
//! place together (`output::Outputs`): all of them or none.

use super::chart::{chart_svg, svg_to_png, Axis};
use super::images::{auto_exposure, compose, error_range, false_colour, pixel_errors, tonemap};
use super::{Clock, ConvergeConfig, ConvergeResults};
use crate::output::{encode_png, Outputs};
use anyhow::Result;
use image::RgbImage;
use std::fmt::Write as _;
use std::path::Path;

pub(super) fn write_outputs(
    cfg: &ConvergeConfig,
    r: &ConvergeResults,
    reference: &[[f32; 3]],
    finals: &[Vec<[f32; 3]>],
) -> Result<()> {
    let dir = &cfg.out;
    let mut out = Outputs::default();
    out.bytes(&dir.join("results.csv"), results_csv(r).as_bytes())?;
    out.json(&dir.join("results.json"), r)?;
    let time_svg = chart_svg(r, Axis::Seconds)?;
    let spp_svg = chart_svg(r, Axis::Spp)?;
    for (name, svg) in [("error-vs-time", &time_svg), ("error-vs-spp", &spp_svg)] {
        out.bytes(&dir.join(format!("{name}.svg")), svg.as_bytes())?;
        png(&mut out, &dir.join(format!("{name}.png")), svg_to_png(svg, 1.0)?)?;
    }
    let scale = match cfg.exposure {
        Some(e) => 2f32.powf(e),
        None => auto_exposure(reference),
    };
    let ref_caption = match (&r.reference.integrator, r.reference.spp) {
        (Some(i), Some(spp)) => format!("reference ({i}, {spp} spp)"),
        _ => "reference".to_string(),
    };
    let mut panels = vec![(ref_caption, tonemap(reference, r.width, r.height, scale))];
    for (res, img) in r.integrators.iter().zip(finals) {
        panels.push((format!("{} ({} spp)", res.label, res.spp), tonemap(img, r.width, r.height, scale)));
    }
    png(&mut out, &dir.join("images.png"), compose(&panels, None)?)?;
    let maps: Vec<Vec<f64>> = finals.iter().map(|img| pixel_errors(img, reference)).collect();
    let (lo, hi) = error_range(&maps);
    let panels: Vec<(String, RgbImage)> = r
        .integrators
        .iter()
        .zip(&maps)
        .map(|(res, m)| {
            (format!("{}: relMSE {:.2e}", res.label, res.rel_mse), false_colour(m, r.width, r.height, lo, hi))
        })
        .collect();
    png(&mut out, &dir.join("errors.png"), compose(&panels, Some((lo, hi)))?)?;
    out.bytes(&dir.join("report.md"), report_md(r).as_bytes())?;
    if cfg.save_exr {
        for (spec, image) in cfg.integrators.iter().zip(finals) {
            out.exr(&dir.join(format!("{}.exr", spec.file_stem())), r.width, r.height, image)?;
        }
    }
    out.commit()
}

fn png(out: &mut Outputs, path: &Path, image: RgbImage) -> Result<()> {
    out.bytes(path, &encode_png(&image::DynamicImage::ImageRgb8(image))?)
}

/// One row per checkpoint: `integrator,spp,seconds,cpu_seconds,rel_mse,mse,mae,by_spp`
/// (seconds: wall; cpu_seconds: empty where unavailable).
pub fn results_csv(r: &ConvergeResults) -> String {
    let mut s = String::from("integrator,spp,seconds,cpu_seconds,rel_mse,mse,mae,by_spp\n");
    for res in &r.integrators {
        for c in &res.checkpoints {
            let cpu = c.cpu_seconds.map_or(String::new(), |v| format!("{v:.2}"));
            let _ = writeln!(
                s,
                "{},{},{:.6},{cpu},{:.6e},{:.6e},{:.6e},{}",
                res.label, c.spp, c.seconds, c.rel_mse, c.mse, c.mae, c.by_spp
            );
        }
    }
    s
}

/// The efficiency table in Markdown, best first.
pub fn efficiency_table(r: &ConvergeResults) -> String {
    let unit = r.clock.unit();
    let mut s = format!(
        "| rank | integrator | spp | {unit} | Msamples/s (wall) | relMSE | MSE | MAE | efficiency 1/(relMSE x s) | vs best | vs best, reference noise out | slope (spp) |\n\
         |---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let order = r.ranking();
    let best = order.first().map_or(1.0, |&i| r.integrators[i].efficiency);
    let best_net = order.first().map_or(f64::NAN, |&i| r.integrators[i].efficiency_net);
    for (rank, &i) in order.iter().enumerate() {
        let x = &r.integrators[i];
        let flag = if x.warnings.is_empty() { "" } else { " (!)" };
        // An unmeasurably short or an exact run has no efficiency and no rank.
        let measured = !x.efficiency.is_nan();
        let or_dash = |v: String| if measured { v } else { "-".to_string() };
        let _ = writeln!(
            s,
            "| {} | {}{flag} | {} | {:.2} | {:.3} | {:.3e} | {:.3e} | {:.3e} | {} | {} | {} | {} |",
            or_dash((rank + 1).to_string()),
            x.label,
            x.spp,
            x.seconds,
            x.samples_per_second / 1e6,
            x.rel_mse,
            x.mse,
            x.mae,
            or_dash(format!("{:.3e}", x.efficiency)),
            or_dash(format!("{:.3}", x.efficiency / best)),
            Some(x.efficiency_net / best_net).filter(|v| v.is_finite()).map_or("-".to_string(), |v| format!("{v:.3}")),
            x.slope.map_or("-".to_string(), |v| format!("{v:.2}"))
        );
    }
    s
}

fn report_md(r: &ConvergeResults) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Convergence: {}\n", r.scene);
    if let Some(c) = &r.scene_comment {
        let _ = writeln!(s, "> {c}\n");
    }
    let unit = r.clock.unit();
    let budget = match (r.budget_seconds, r.max_spp) {
        (Some(t), Some(n)) => format!("{t} {unit} or {n} spp per integrator, whichever comes first"),
        (Some(t), None) => format!("{t} {unit} per integrator"),
        (None, Some(n)) => format!("{n} spp per integrator"),
        (None, None) => "-".to_string(),
    };
    let _ = writeln!(
        s,
        "- resolution {}x{}, seed {}, max depth {}, {} threads\n- budget: {budget}\n- prism {} (commit {}, built for {})",
        r.width, r.height, r.seed, r.max_depth, r.threads, r.prism_version, r.commit, r.build_target
    );
    let rf = &r.reference;
    let _ = write!(s, "- reference: `{}`", rf.path);
    match (&rf.integrator, rf.spp, rf.passes) {
        (Some(i), Some(spp), Some(p)) => {
            let _ = write!(s, ", {i}, {spp} spp in {p} passes (seeds from {})", rf.seed.unwrap_or(0));
        }
        (Some(i), Some(spp), None) => {
            let _ = write!(s, ", {i}, {spp} spp (seed {})", rf.seed.unwrap_or(0));
        }
        _ => {}
    }
    if let Some(t) = rf.wall_seconds {
        let _ = write!(s, ", {t:.1} s{}", if rf.rendered_here { ", rendered by this run" } else { "" });
    }
    if let Some(f) = rf.noise_floor {
        let how = rf.noise_floor_method.as_deref().unwrap_or("-");
        let _ =
            write!(s, "; its own noise adds about {f:.2e} to every relMSE (grey dashed line; estimated from: {how})");
    }
    let _ = writeln!(s, "\n- command: `{}`\n", r.command);
    let _ = writeln!(s, "## Efficiency (last checkpoint, best first)\n\n{}", efficiency_table(r));
    let _ = writeln!(
        s,
        "Efficiency = 1 / (relMSE x {unit} of rendering). Slope: least-squares slope of log relMSE against log spp \
         over the checkpoints from 4 spp whose relMSE is at least ten times the reference's own noise, where that \
         is known (-1 for an unbiased estimator, flatter where a bias dominates).\n"
    );
    if r.integrators.iter().any(|x| !x.warnings.is_empty()) {
        let _ = writeln!(s, "(!) marks integrators that cannot sample some paths of this scene:\n");
    }
    for x in r.integrators.iter().filter(|x| !x.warnings.is_empty()) {
        for w in &x.warnings {
            let _ = writeln!(s, "- {}: {w}", x.label);
        }
    }
    if !r.notes.is_empty() {
        let _ = writeln!(s, "\nNotes:\n");
    }
    for n in &r.notes {
        let _ = writeln!(s, "- {n}");
    }
    let _ = writeln!(
        s,
        "\n## Error against time and spp\n\n![relMSE vs time](error-vs-time.svg)\n\n![relMSE vs spp](error-vs-spp.svg)\n\n\
         PNG versions: [error-vs-time.png](error-vs-time.png), [error-vs-spp.png](error-vs-spp.png). \
         Every checkpoint is in [results.csv](results.csv) and [results.json](results.json).\n\n\
         ## Final images\n\n![final images](images.png)\n\n\
         ## Per-pixel error\n\nmean over channels of (x - ref)^2 / (ref^2 + 0.01), log colour scale shared by all \
         panels (the mean of each map is the integrator's relMSE):\n\n![per-pixel error](errors.png)\n\n\
         ## Determinism\n\nThe image at a grid checkpoint (1, 2, ..., 8, then multiples of 8 near quarter octaves: 16, 24, 32, 40, ... spp; `by_spp = \
         true` in the CSV) depends only on the scene, the seed and spp, so its errors are reproduced bit for bit by \
         the same command, at the same commit and build target. {} are measurements and vary from run to run \
         and machine to machine; the last checkpoint of a time-limited run ends where the budget ran out \
         (`by_spp = false`), so its spp, and the efficiency computed from it, vary too.",
        match r.clock {
            Clock::Wall => "Seconds (wall clock)",
            Clock::Cpu => "CPU seconds (all rendering threads)",
        }
    );
    s
}
