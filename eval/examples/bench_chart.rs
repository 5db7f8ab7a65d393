//! Draws BENCHMARKS.md's charts: figures against problem size for clatch and its peers, from a
//! `panel,series,x,y` CSV (`tools/collect.py` writes one from a benchmark run).
//!
//! ```sh
//! cargo run --release -p clatch-eval --example bench_chart -- docs/bench/RUN/figures.csv docs/bench/RUN/throughput.png
//! ```
//!
//! Log-log panels side by side. Lines `#panel,NAME,TITLE,X LABEL,Y LABEL` name the panels and their
//! order; without them, two: matching (G pairs/s against N for N x N, k = 2, 512 bits) and extraction
//! (M descriptors/s against keypoints). Drawn with plotters' bitmap backend and the embedded DejaVu
//! font, so no system library is needed.

use std::collections::BTreeMap;
use std::error::Error;
use std::ops::Range;

use plotters::prelude::*;
use plotters::style::FontStyle;

type Series = BTreeMap<String, Vec<(f64, f64)>>;
/// Series by panel name.
type Panels = BTreeMap<String, Series>;

/// A panel: its name in the CSV, title and axis labels.
struct Panel {
    name: String,
    title: String,
    x_label: String,
    y_label: String,
}

/// The panels of BENCHMARKS.md's first chart, for a CSV that names none.
fn default_panels() -> Vec<Panel> {
    let panel = |name: &str, title: &str, x: &str, y: &str| Panel {
        name: name.into(),
        title: title.into(),
        x_label: x.into(),
        y_label: y.into(),
    };
    vec![
        panel(
            "matching",
            "Hamming kNN, k = 2, 512 bits, N x N",
            "N",
            "G pairs/s",
        ),
        panel(
            "extraction",
            "Descriptor extraction, 512 bits",
            "keypoints",
            "M descriptors/s",
        ),
    ]
}

/// Rows of the CSV by panel, then series, in file order, and the panels its `#panel` lines name.
fn read(path: &str) -> Result<(Panels, Vec<Panel>), Box<dyn Error>> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut panels = Panels::new();
    let mut named = Vec::new();
    for (number, line) in text.lines().enumerate().skip(1) {
        if let Some(declared) = line.strip_prefix("#panel,") {
            let [name, title, x_label, y_label] = declared.split(',').collect::<Vec<_>>()[..]
            else {
                return Err(
                    format!("{path}:{}: expected #panel,NAME,TITLE,X,Y", number + 1).into(),
                );
            };
            named.push(Panel {
                name: name.into(),
                title: title.into(),
                x_label: x_label.into(),
                y_label: y_label.into(),
            });
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        let [panel, series, x, y] = fields[..] else {
            return Err(format!("{path}:{}: expected panel,series,x,y", number + 1).into());
        };
        let parse = |v: &str| {
            v.parse::<f64>()
                .map_err(|e| format!("{path}:{}: {v:?}: {e}", number + 1))
        };
        panels
            .entry(panel.to_string())
            .or_default()
            .entry(series.to_string())
            .or_default()
            .push((parse(x)?, parse(y)?));
    }
    Ok((panels, named))
}

/// A log range with some head room around the values.
fn log_range(values: impl Iterator<Item = f64>) -> Range<f64> {
    let (lo, hi) = values
        .filter(|v| *v > 0.0)
        .fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return 1.0..10.0;
    }
    lo / 2.0..hi * 3.0
}

fn colour(i: usize) -> RGBColor {
    const COLOURS: [RGBColor; 8] = [
        RGBColor(200, 30, 30),
        RGBColor(230, 140, 0),
        RGBColor(30, 90, 200),
        RGBColor(20, 150, 60),
        RGBColor(150, 60, 180),
        RGBColor(90, 90, 90),
        RGBColor(0, 160, 170),
        RGBColor(160, 110, 60),
    ];
    COLOURS[i % COLOURS.len()]
}

fn panel(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    title: &str,
    (x_label, y_label): (&str, &str),
    series: &Series,
) -> Result<(), Box<dyn Error>> {
    let xs = log_range(series.values().flatten().map(|p| p.0));
    // Room below the lowest point for the legend (lower right).
    let ys = log_range(series.values().flatten().map(|p| p.1));
    let ys = ys.start / 4.0..ys.end;
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(xs.log_scale(), ys.log_scale())?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .label_style(("sans-serif", 13))
        .draw()?;
    for (i, (name, points)) in series.iter().enumerate() {
        let c = colour(i);
        chart
            .draw_series(LineSeries::new(points.iter().copied(), c.stroke_width(2)))?
            .label(name)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], c.stroke_width(2)));
        chart.draw_series(points.iter().map(|&p| Circle::new(p, 4, c.filled())))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .draw()?;
    Ok(())
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, input, output] = &args[..] else {
        return Err("usage: bench_chart FIGURES.csv OUT.png".into());
    };
    plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
        .map_err(|_| "the embedded DejaVu Sans font did not load")?;
    let (series, named) = read(input)?;
    let panels = if named.is_empty() {
        default_panels()
    } else {
        named
    };
    let empty = Series::new();
    let (width, height) = (640 * panels.len() as u32, 560u32);
    let mut pixels = vec![0u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
        root.fill(&WHITE)?;
        for (area, p) in root.split_evenly((1, panels.len())).iter().zip(&panels) {
            panel(
                area,
                &p.title,
                (&p.x_label, &p.y_label),
                series.get(&p.name).unwrap_or(&empty),
            )?;
        }
        root.present()?;
    }
    image::save_buffer(
        output,
        &pixels,
        width,
        height,
        image::ExtendedColorType::Rgb8,
    )?;
    println!("wrote {output}");
    Ok(())
}
