//! The charts of `clatch-eval`, drawn with plotters' pure-Rust bitmap backend and an embedded DejaVu
//! font (ab_glyph), so nothing depends on system fonts or libraries; saved as PNG by the `image` crate.

use std::path::Path;
use std::sync::OnceLock;

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::error::{EvalError, write_file};
use crate::metrics::RatioPoint;

/// One panel of precision-recall curves: a title and one curve a method.
pub struct PrPanel {
    /// Panel title.
    pub title: String,
    /// (method, ratio-test curve), in legend order.
    pub curves: Vec<(String, Vec<RatioPoint>)>,
}

/// One panel of a figure against a swept parameter: (method, [(parameter, value)]).
pub struct SweepPanel {
    /// Panel title.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// (method, points), in legend order.
    pub series: Vec<(String, Vec<(f64, f64)>)>,
}

const FONT: &str = "sans-serif";
const PANEL: (u32, u32) = (560, 480);

/// Registers the embedded font once; plotters' ab_glyph text looks fonts up by family name.
fn register_font() -> Result<(), String> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    ok.then_some(())
        .ok_or_else(|| "the embedded DejaVu Sans font did not load".into())
}

/// A colour per method index, the same in every panel and chart.
fn colour(i: usize) -> RGBColor {
    const COLOURS: [RGBColor; 6] = [
        RGBColor(200, 30, 30),
        RGBColor(30, 90, 200),
        RGBColor(20, 150, 60),
        RGBColor(150, 60, 180),
        RGBColor(230, 140, 0),
        RGBColor(90, 90, 90),
    ];
    COLOURS[i % COLOURS.len()]
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// Where a panel's legend goes: the PR curves leave the lower left empty; the sweeps get head room
/// above 1 for it.
#[derive(Clone, Copy)]
enum Legend {
    LowerLeft,
    Above,
}

fn draw_lines(
    area: &Area,
    title: &str,
    (x_label, y_label): (&str, &str),
    x_range: std::ops::Range<f64>,
    series: &[(String, Vec<(f64, f64)>)],
    colour_of: &dyn Fn(&str) -> RGBColor,
    legend: Legend,
) -> Result<(), String> {
    let (y_range, position) = match legend {
        Legend::LowerLeft => (0.0..1.02, SeriesLabelPosition::LowerLeft),
        Legend::Above => (0.0..1.4, SeriesLabelPosition::UpperMiddle),
    };
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(x_range, y_range)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .label_style((FONT, 13))
        .light_line_style(WHITE)
        .x_label_formatter(&|x| format!("{}", (x * 100.0).round() / 100.0))
        .y_label_formatter(&|y| {
            if *y <= 1.0 {
                format!("{y:.1}")
            } else {
                String::new()
            }
        })
        .draw()
        .map_err(|e| e.to_string())?;
    for (method, points) in series {
        let c = colour_of(method);
        chart
            .draw_series(LineSeries::new(points.iter().copied(), c.stroke_width(2)))
            .map_err(|e| e.to_string())?
            .label(method.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 3, c.filled())))
            .map_err(|e| e.to_string())?;
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(position)
        .draw()
        .map_err(|e| e.to_string())
}

/// Precision (y) against recall (x) of the ratio test, a point per threshold.
fn pr_points(curve: &[RatioPoint]) -> Vec<(f64, f64)> {
    curve
        .iter()
        .filter_map(|p| Some((p.recall()?, p.precision()?)))
        .collect()
}

/// Draws `panels` side by side into a `width` x `height` RGB buffer and saves it as PNG.
fn save_panels(
    path: &Path,
    count: usize,
    draw: impl Fn(&Area, usize) -> Result<(), String>,
) -> Result<(), EvalError> {
    let chart_error = |reason: String| EvalError::Chart {
        path: path.to_path_buf(),
        reason,
    };
    register_font().map_err(chart_error)?;
    let (width, height) = (PANEL.0 * count.max(1) as u32, PANEL.1);
    let mut buffer = vec![0u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| chart_error(e.to_string()))?;
        for (i, area) in root.split_evenly((1, count.max(1))).iter().enumerate() {
            draw(area, i).map_err(chart_error)?;
        }
        root.present().map_err(|e| chart_error(e.to_string()))?;
    }
    let picture = image::RgbImage::from_raw(width, height, buffer)
        .ok_or_else(|| chart_error("buffer size".into()))?;
    // Charts are committed to the repository: spend time on compression, not bytes.
    let encode_error = |source| EvalError::Encode {
        path: path.to_path_buf(),
        source,
    };
    let mut encoded = Vec::new();
    let encoder =
        PngEncoder::new_with_quality(&mut encoded, CompressionType::Best, FilterType::Adaptive);
    picture.write_with_encoder(encoder).map_err(encode_error)?;
    write_file(path, &encoded)
}

/// The colour of each method, by its place in `methods`.
fn palette(methods: &[String]) -> impl Fn(&str) -> RGBColor + '_ {
    move |m| colour(methods.iter().position(|x| x == m).unwrap_or(0))
}

/// Saves precision-recall panels side by side as a PNG.
pub fn pr_chart(path: &Path, methods: &[String], panels: &[PrPanel]) -> Result<(), EvalError> {
    let colour_of = palette(methods);
    save_panels(path, panels.len(), |area, i| {
        let panel = &panels[i];
        let series: Vec<(String, Vec<(f64, f64)>)> = panel
            .curves
            .iter()
            .map(|(m, c)| (m.clone(), pr_points(c)))
            .collect();
        draw_lines(
            area,
            &panel.title,
            ("recall (correct kept / correct 1-NN)", "precision"),
            0.0..1.0,
            &series,
            &colour_of,
            Legend::LowerLeft,
        )
    })
}

/// Saves parameter-sweep panels side by side as a PNG.
pub fn sweep_chart(
    path: &Path,
    methods: &[String],
    panels: &[SweepPanel],
) -> Result<(), EvalError> {
    let colour_of = palette(methods);
    save_panels(path, panels.len(), |area, i| {
        let panel = &panels[i];
        let xs = panel.series.iter().flat_map(|(_, p)| p.iter().map(|q| q.0));
        let (lo, hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        });
        let x_range = if lo < hi { lo..hi } else { 0.0..1.0 };
        draw_lines(
            area,
            &panel.title,
            (&panel.x_label, &panel.y_label),
            x_range,
            &panel.series,
            &colour_of,
            Legend::Above,
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_a_png_with_curves() {
        let path = std::env::temp_dir().join(format!("clatch-chart-{}.png", std::process::id()));
        let curve = |k: usize| {
            vec![
                RatioPoint {
                    ratio: 0.5,
                    kept: 10,
                    correct_kept: 9,
                    correct_candidates: 40,
                },
                RatioPoint {
                    ratio: 1.0,
                    kept: 60,
                    correct_kept: 30 + k,
                    correct_candidates: 40,
                },
            ]
        };
        let methods = vec!["clatch".to_string(), "OpenCV ORB".to_string()];
        let panel = PrPanel {
            title: "test".into(),
            curves: vec![
                (methods[0].clone(), curve(0)),
                (methods[1].clone(), curve(5)),
            ],
        };
        pr_chart(&path, &methods, &[panel]).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        std::fs::remove_file(&path).ok();
        assert_eq!(img.dimensions(), PANEL);
        // Both method colours were drawn.
        for c in [colour(0), colour(1)] {
            assert!(img.pixels().any(|p| p.0 == [c.0, c.1, c.2]), "{c:?}");
        }
        // Text was drawn: some dark pixels that are not the curves' colours exist.
        assert!(img.pixels().any(|p| p.0.iter().all(|&v| v < 60)));
    }
}
