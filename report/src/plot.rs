//! A small stacked-panel line-plot renderer on plotters' bitmap backend. Text uses a font
//! registered from bytes (no system fonts), so the plots render on a bare machine.

use std::path::Path;
use std::sync::OnceLock;

use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

use crate::error::ReportError;
use crate::series::{Range, decimate, in_time, visible_segments};

/// The font family name the panels ask for.
const FONT: &str = "sans-serif";

/// Registers the embedded font once per process (Ubuntu Light, open-licensed, shipped as bytes
/// by `epaint_default_fonts`).
fn ensure_font() -> Result<(), ReportError> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            register_font(FONT, FontStyle::Normal, epaint_default_fonts::UBUNTU_LIGHT)
                .map_err(|_| "invalid embedded font".to_string())
        })
        .clone()
        .map_err(ReportError::Font)
}

/// Colour of the truth lines (the paper's Figs. 4–5 draw ground truth in black).
pub const TRUTH_COLOR: RGBColor = RGBColor(0, 0, 0);

/// Run colours, in run order (first run blue as the paper's video-aided estimate).
const RUN_COLORS: [RGBColor; 5] = [
    RGBColor(20, 80, 220),
    RGBColor(220, 40, 30),
    RGBColor(0, 150, 70),
    RGBColor(230, 130, 0),
    RGBColor(140, 50, 170),
];

/// The colour of run `i`.
pub fn run_color(i: usize) -> RGBColor {
    RUN_COLORS[i % RUN_COLORS.len()]
}

/// Fill of the GNSS-outage bands.
const OUTAGE_FILL: RGBColor = RGBColor(225, 225, 225);

/// One polyline of a panel.
#[derive(Debug, Clone)]
pub struct Line {
    /// Legend entry (`None`: not in the legend).
    pub label: Option<String>,
    /// Colour.
    pub color: RGBColor,
    /// Dashed (stated uncertainty bounds) rather than solid.
    pub dashed: bool,
    /// Stroke width, px.
    pub width: u32,
    /// (seconds, value) points, any length (decimated when drawn).
    pub points: Vec<(f64, f64)>,
}

/// One chart of a stacked figure.
#[derive(Debug, Clone)]
pub struct Panel {
    /// Caption above the chart.
    pub title: String,
    /// Y-axis description (with its unit).
    pub y_label: String,
    /// Time range shown, s.
    pub x: Range,
    /// Value range shown; lines outside it are cut.
    pub y: Range,
    /// The polylines.
    pub lines: Vec<Line>,
    /// Shaded time bands (GNSS outages), s.
    pub bands: Vec<(f64, f64)>,
    /// Draw the legend box on this panel.
    pub legend: bool,
}

/// Size and density of the rendered figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlotParams {
    /// Figure width, px.
    pub width_px: u32,
    /// Height of one panel, px.
    pub panel_height_px: u32,
    /// Points kept per series (a 250 s flight has 50 000 outputs per run).
    pub max_points: usize,
}

impl Default for PlotParams {
    fn default() -> Self {
        Self {
            width_px: 1200,
            panel_height_px: 320,
            max_points: 5000,
        }
    }
}

/// Draws `panels` stacked top to bottom into the PNG at `path`.
pub fn render(path: &Path, panels: &[Panel], params: &PlotParams) -> Result<(), ReportError> {
    ensure_font()?;
    let fail = |e: &dyn std::fmt::Display| ReportError::Plot {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let rows = panels.len().max(1);
    let height = params.panel_height_px.saturating_mul(rows as u32);
    let root = BitMapBackend::new(path, (params.width_px, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(&e))?;
    for (panel, area) in panels.iter().zip(root.split_evenly((rows, 1))) {
        draw_panel(&area, panel, params).map_err(|e| fail(&e))?;
    }
    root.present().map_err(|e| fail(&e))?;
    Ok(())
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;
type DrawResult<'a> =
    Result<(), DrawingAreaErrorKind<<BitMapBackend<'a> as DrawingBackend>::ErrorType>>;

/// One chart: mesh, outage bands, lines (cut to the y range), legend.
fn draw_panel<'a>(area: &Area<'a>, panel: &Panel, params: &PlotParams) -> DrawResult<'a> {
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FONT, 18))
        .margin(8)
        .x_label_area_size(36)
        .y_label_area_size(70)
        .build_cartesian_2d(panel.x.lo..panel.x.hi, panel.y.lo..panel.y.hi)?;
    chart
        .configure_mesh()
        .x_desc("time [s]")
        .y_desc(panel.y_label.as_str())
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .light_line_style(RGBColor(240, 240, 240))
        .draw()?;
    for &(a, b) in &panel.bands {
        let (a, b) = (a.max(panel.x.lo), b.min(panel.x.hi));
        if b > a {
            chart.draw_series(std::iter::once(Rectangle::new(
                [(a, panel.y.lo), (b, panel.y.hi)],
                OUTAGE_FILL.filled(),
            )))?;
        }
    }
    // Legend entries in list order (empty series), then the data in reverse order so the
    // first-listed line (truth, then the first run) ends up on top.
    for line in panel.lines.iter().filter(|l| l.label.is_some()) {
        draw_legend_entry(&mut chart, line)?;
    }
    for line in panel.lines.iter().rev() {
        draw_line(&mut chart, line, panel.x, panel.y, params.max_points)?;
    }
    if panel.legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(120, 120, 120))
            .label_font((FONT, 14))
            .draw()?;
    }
    Ok(())
}

type Chart<'a, 'b> = ChartContext<
    'b,
    BitMapBackend<'a>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// Registers `line`'s legend entry with an empty series of its style.
fn draw_legend_entry<'a>(chart: &mut Chart<'a, '_>, line: &Line) -> DrawResult<'a> {
    let color = line.color;
    let empty: Vec<(f64, f64)> = Vec::new();
    let anno = chart.draw_series(LineSeries::new(empty, color.stroke_width(line.width)))?;
    if let Some(label) = &line.label {
        let dashed = line.dashed;
        anno.label(label.as_str()).legend(move |(x, y)| {
            let style = color.stroke_width(2);
            if dashed {
                PathElement::new(vec![(x, y), (x + 8, y)], style)
            } else {
                PathElement::new(vec![(x, y), (x + 24, y)], style)
            }
        });
    }
    Ok(())
}

/// Draws a (decimated) line as its visible segments.
fn draw_line<'a>(
    chart: &mut Chart<'a, '_>,
    line: &Line,
    x: Range,
    y: Range,
    max_points: usize,
) -> DrawResult<'a> {
    // crop to the shown time first, so a zoom keeps its full resolution
    let shown: Vec<(f64, f64)> = in_time(&line.points, x).copied().collect();
    let points = decimate(&shown, max_points);
    let style = line.color.stroke_width(line.width);
    for seg in visible_segments(&points, x, y) {
        if line.dashed {
            chart.draw_series(DashedLineSeries::new(seg, 6, 4, style))?;
        } else {
            chart.draw_series(LineSeries::new(seg, style))?;
        }
    }
    Ok(())
}
