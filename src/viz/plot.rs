//! Plots: stacked line panels and grouped bars, drawn with plotters.
//!
//! A replay plots, per stream and frame, the F-score and the visible recall
//! R_vis (recall on the part the camera saw: the seen-side accuracy the
//! replay measures, `pipeline::score`) in one panel and the frame latency
//! in another. The benchmark plots its sphere sweep (F-score and
//! Chamfer-L1 against the duplicates' σ, the paper's Fig. 8 experiment) and
//! the F-score per input condition of Table 1 beside the peers' figures.

use super::{draw_err, ensure_font, Canvas, VizError, FAMILY};
use plotters::prelude::*;
use std::path::Path;

/// One named line: `(x, y)` points in drawing order.
#[derive(Debug, Clone, Default)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points; non-finite values are left out.
    pub points: Vec<(f64, f64)>,
}

/// One panel of [`write_lines`].
#[derive(Debug, Clone, Default)]
pub struct Panel {
    /// Title above the panel.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Fixed y range (default: the data's, with a margin).
    pub y_range: Option<(f64, f64)>,
    /// The lines.
    pub series: Vec<Series>,
    /// Legend in the upper right corner (default: lower right).
    pub legend_top: bool,
}

/// Grouped bars: one group per category, one bar per series in each.
#[derive(Debug, Clone, Default)]
pub struct Bars {
    /// Title above the chart.
    pub title: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Category names, left to right.
    pub groups: Vec<String>,
    /// `(label, value per group)`; `None` leaves a gap.
    pub series: Vec<(String, Vec<Option<f64>>)>,
}

const WIDTH: u32 = 900;
const PANEL_H: u32 = 320;

fn colour(i: usize) -> RGBColor {
    const TABLE: [RGBColor; 8] = [
        RGBColor(52, 110, 235),
        RGBColor(245, 130, 20),
        RGBColor(30, 170, 60),
        RGBColor(200, 40, 40),
        RGBColor(140, 80, 190),
        RGBColor(120, 90, 60),
        RGBColor(220, 90, 180),
        RGBColor(110, 110, 110),
    ];
    TABLE[i % TABLE.len()]
}

/// The finite points of `series`.
fn finite(s: &Series) -> impl Iterator<Item = (f64, f64)> + '_ {
    s.points
        .iter()
        .copied()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
}

/// `(min, max)` of `values`, widened when degenerate, with a 5 % margin.
fn range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !lo.is_finite() {
        return None;
    }
    let pad = if hi > lo {
        0.05 * (hi - lo)
    } else {
        0.5_f64.max(lo.abs() * 0.1)
    };
    Some((lo - pad, hi + pad))
}

/// Write `panels` stacked top to bottom as one PNG.
///
/// # Errors
/// [`VizError::Empty`] when no panel has a finite point;
/// [`VizError::Draw`] / [`VizError::Write`] when drawing or writing fails.
pub fn write_lines(panels: &[Panel], path: &Path) -> Result<(), VizError> {
    ensure_font()?;
    if !panels
        .iter()
        .any(|p| p.series.iter().any(|s| finite(s).next().is_some()))
    {
        return Err(VizError::Empty(format!(
            "no finite point to plot in {}",
            path.display()
        )));
    }
    let h = PANEL_H * panels.len() as u32;
    let mut canvas = Canvas::new(WIDTH, h);
    {
        let root = BitMapBackend::with_buffer(&mut canvas.rgb, (WIDTH, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err("plot"))?;
        for (area, panel) in root.split_evenly((panels.len(), 1)).iter().zip(panels) {
            draw_panel(area, panel)?;
        }
        root.present().map_err(draw_err("plot"))?;
    }
    canvas.save_png(path)
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    panel: &Panel,
) -> Result<(), VizError> {
    let what = panel.title.as_str();
    let xs = range(panel.series.iter().flat_map(|s| finite(s).map(|p| p.0)));
    let ys = panel
        .y_range
        .or_else(|| range(panel.series.iter().flat_map(|s| finite(s).map(|p| p.1))));
    let (Some(xs), Some(ys)) = (xs, ys) else {
        return Ok(());
    };
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FAMILY, 20))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d(xs.0..xs.1, ys.0..ys.1)
        .map_err(draw_err(what))?;
    chart
        .configure_mesh()
        .x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .label_style((FAMILY, 14))
        .draw()
        .map_err(draw_err(what))?;
    for (i, s) in panel.series.iter().enumerate() {
        let c = colour(i);
        chart
            .draw_series(LineSeries::new(finite(s), c.stroke_width(2)))
            .map_err(draw_err(what))?
            .label(s.label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(finite(s).map(|p| Circle::new(p, 3, c.filled())))
            .map_err(draw_err(what))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FAMILY, 14))
        .position(if panel.legend_top {
            SeriesLabelPosition::UpperRight
        } else {
            SeriesLabelPosition::LowerRight
        })
        .draw()
        .map_err(draw_err(what))?;
    Ok(())
}

/// Write grouped `bars` as one PNG.
///
/// # Errors
/// [`VizError::Empty`] without groups or values;
/// [`VizError::Draw`] / [`VizError::Write`] when drawing or writing fails.
pub fn write_bars(bars: &Bars, path: &Path) -> Result<(), VizError> {
    ensure_font()?;
    let top = bars
        .series
        .iter()
        .flat_map(|(_, v)| v.iter().flatten().copied())
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    if bars.groups.is_empty() || !top.is_finite() {
        return Err(VizError::Empty(format!(
            "no bar to draw in {}",
            path.display()
        )));
    }
    let what = bars.title.as_str();
    let (w, h) = (WIDTH, PANEL_H + 80);
    let mut canvas = Canvas::new(w, h);
    {
        let root = BitMapBackend::with_buffer(&mut canvas.rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err(what))?;
        let n = bars.groups.len();
        let mut chart = ChartBuilder::on(&root)
            .caption(&bars.title, (FAMILY, 20))
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(
                // Values 0..=n-1: one segment per group, none left empty.
                (0..n - 1).into_segmented(),
                0.0..(top.max(0.0) * 1.15).max(1e-9),
            )
            .map_err(draw_err(what))?;
        let groups = bars.groups.clone();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n)
            .x_label_formatter(&|v| match v {
                SegmentValue::CenterOf(i) => groups.get(*i).cloned().unwrap_or_default(),
                _ => String::new(),
            })
            .y_desc(bars.y_label.as_str())
            .label_style((FAMILY, 14))
            .draw()
            .map_err(draw_err(what))?;
        draw_bar_series(&mut chart, bars, what)?;
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FAMILY, 14))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(draw_err(what))?;
        root.present().map_err(draw_err(what))?;
    }
    canvas.save_png(path)
}

type SegmentedChart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<
        plotters::coord::ranged1d::SegmentedCoord<plotters::coord::types::RangedCoordusize>,
        plotters::coord::types::RangedCoordf64,
    >,
>;

/// The bars of every series, side by side within each group: each bar is
/// its group's segment narrowed by pixel margins (a tenth of the segment
/// free at each end, the rest shared by the series).
fn draw_bar_series<DB: DrawingBackend>(
    chart: &mut SegmentedChart<'_, DB>,
    bars: &Bars,
    what: &str,
) -> Result<(), VizError> {
    let (px, _) = chart.plotting_area().get_pixel_range();
    let segment = (px.end - px.start).max(1) as f64 / bars.groups.len().max(1) as f64;
    let gap = 0.1 * segment;
    let width = (segment - 2.0 * gap) / bars.series.len().max(1) as f64;
    for (si, (label, values)) in bars.series.iter().enumerate() {
        let c = colour(si);
        let left = (gap + si as f64 * width).round() as u32;
        let right = (segment - gap - (si + 1) as f64 * width).max(0.0).round() as u32;
        let rects = values.iter().enumerate().filter_map(|(g, v)| {
            let v = v.filter(|v| v.is_finite())?.max(0.0);
            let mut r = Rectangle::new(
                [
                    (SegmentValue::Exact(g), v),
                    (SegmentValue::Exact(g + 1), 0.0),
                ],
                c.filled(),
            );
            r.set_margin(0, 0, left, right);
            Some(r)
        });
        chart
            .draw_series(rects)
            .map_err(draw_err(what))?
            .label(label.as_str())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], c.filled()));
    }
    Ok(())
}
