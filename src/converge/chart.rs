//! The error-vs-time and error-vs-spp charts (plotters SVG), and their
//! rasterisation by resvg with the embedded font.

use super::{Checkpoint, Clock, ConvergeResults};
use anyhow::{Context, Result};
use image::RgbImage;
use plotters::prelude::*;
use std::path::Path;
use std::sync::{Arc, OnceLock};

/// The font chart text is rasterised with (see assets/fonts/LICENSE-DejaVu.txt).
const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
const FONT_FAMILY: &str = "DejaVu Sans";

/// Line colours (Tableau 10), one per integrator, in command-line order.
const PALETTE: [(u8, u8, u8); 8] = [
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (255, 127, 14),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (23, 190, 207),
];

#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Axis {
    Seconds,
    Spp,
}

/// Tick labels: plain numbers in a readable range, else scientific.
fn tick(v: f64) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    if (1e-3..1e5).contains(&v.abs()) {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.0e}")
    }
}

fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (1e-3, 1.0);
    }
    let (lo, hi) = if hi / lo < 10.0 { ((lo * hi).sqrt() / 3.2, (lo * hi).sqrt() * 3.2) } else { (lo, hi) };
    (lo / 1.3, hi * 1.3)
}

pub(super) fn chart_svg(r: &ConvergeResults, axis: Axis) -> Result<String> {
    let x_of = |c: &Checkpoint| match axis {
        Axis::Seconds => c.time(r.clock),
        Axis::Spp => c.spp as f64,
    };
    let all = || r.integrators.iter().flat_map(|x| x.checkpoints.iter());
    let (x0, x1) = log_range(all().map(x_of));
    let floor = r.reference.noise_floor.filter(|f| *f > 0.0);
    let (y0, y1) = log_range(all().map(|c| c.rel_mse).chain(floor));
    let title = match axis {
        Axis::Seconds => format!("{}: relMSE vs time ({}x{})", scene_stem(&r.scene), r.width, r.height),
        Axis::Spp => format!("{}: relMSE vs samples per pixel ({}x{})", scene_stem(&r.scene), r.width, r.height),
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc(match axis {
                Axis::Seconds => match r.clock {
                    Clock::Wall => "seconds of rendering (log)",
                    Clock::Cpu => "CPU seconds of rendering, all threads (log)",
                },
                Axis::Spp => "samples per pixel (log)",
            })
            .y_desc("relMSE (log)")
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(200, 200, 200))
            .draw()
            .map_err(plot_err)?;
        for (i, x) in r.integrators.iter().enumerate() {
            let (cr, cg, cb) = PALETTE[i % PALETTE.len()];
            let colour = RGBColor(cr, cg, cb);
            let pts: Vec<(f64, f64)> = x
                .checkpoints
                .iter()
                .filter(|c| c.rel_mse > 0.0 && x_of(c) > 0.0)
                .map(|c| (x_of(c), c.rel_mse))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(plot_err)?
                .label(x.label.clone())
                .legend(move |(lx, ly)| PathElement::new(vec![(lx, ly), (lx + 24, ly)], colour.stroke_width(3)));
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled()))).map_err(plot_err)?;
        }
        if axis == Axis::Spp {
            // Slope -1 through the geometric mean of the first checkpoints
            // with an error (a relMSE of 0, an exact image, has no log).
            let firsts: Vec<f64> = r
                .integrators
                .iter()
                .filter_map(|x| x.checkpoints.first())
                .map(|c| (c.rel_mse * c.spp as f64).ln())
                .filter(|l| l.is_finite())
                .collect();
            if !firsts.is_empty() {
                let k = (firsts.iter().sum::<f64>() / firsts.len() as f64).exp();
                let line: Vec<(f64, f64)> = [x0, x1].into_iter().map(|x| (x, k / x)).collect();
                chart
                    .draw_series(DashedLineSeries::new(line, 8, 6, BLACK.stroke_width(1)))
                    .map_err(plot_err)?
                    .label("slope -1")
                    .legend(|(lx, ly)| PathElement::new(vec![(lx, ly), (lx + 24, ly)], BLACK.stroke_width(1)));
            }
        }
        if let Some(f) = floor {
            let grey = RGBColor(120, 120, 120);
            chart
                .draw_series(DashedLineSeries::new(vec![(x0, f), (x1, f)], 4, 4, grey.stroke_width(1)))
                .map_err(plot_err)?
                .label("reference noise (est.)")
                .legend(move |(lx, ly)| PathElement::new(vec![(lx, ly), (lx + 24, ly)], grey.stroke_width(1)));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 15))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .draw()
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
    }
    Ok(svg)
}

fn plot_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("chart: {e:?}")
}

fn scene_stem(scene: &str) -> String {
    Path::new(scene).file_stem().map_or(scene.to_string(), |s| s.to_string_lossy().to_string())
}

// --------------------------------------------------------- rasterising SVG

fn usvg_options() -> &'static resvg::usvg::Options<'static> {
    static OPTIONS: OnceLock<resvg::usvg::Options<'static>> = OnceLock::new();
    OPTIONS.get_or_init(|| {
        let mut db = resvg::usvg::fontdb::Database::new();
        db.load_font_data(FONT.to_vec());
        db.set_sans_serif_family(FONT_FAMILY);
        resvg::usvg::Options { font_family: FONT_FAMILY.to_string(), fontdb: Arc::new(db), ..Default::default() }
    })
}

/// Rasterises an SVG (on white) with the embedded font.
pub fn svg_to_png(svg: &str, scale: f32) -> Result<RgbImage> {
    let tree = resvg::usvg::Tree::from_str(svg, usvg_options()).context("cannot parse the chart SVG")?;
    let size = tree.size();
    let (w, h) = ((size.width() * scale).ceil() as u32, (size.height() * scale).ceil() as u32);
    let mut pixmap = resvg::tiny_skia::Pixmap::new(w, h).context("empty SVG")?;
    pixmap.fill(resvg::tiny_skia::Color::WHITE);
    resvg::render(&tree, resvg::tiny_skia::Transform::from_scale(scale, scale), &mut pixmap.as_mut());
    // Opaque background: premultiplied RGBA equals straight RGBA.
    let rgb: Vec<u8> = pixmap.data().chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
    RgbImage::from_raw(w, h, rgb).context("pixmap size")
}

pub(super) fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_text_is_rasterised_with_the_embedded_font() {
        let blank = r#"<svg xmlns="http://www.w3.org/2000/svg" width="60" height="30"><rect width="60" height="30" fill="white"/></svg>"#;
        let text =
            blank.replace("</svg>", r#"<text x="5" y="20" font-family="sans-serif" font-size="16">Ag</text></svg>"#);
        let dark = |img: &RgbImage| img.pixels().filter(|p| p.0[0] < 128).count();
        assert_eq!(dark(&svg_to_png(blank, 1.0).unwrap()), 0);
        assert!(dark(&svg_to_png(&text, 1.0).unwrap()) > 20, "no glyphs drawn");
    }
}
