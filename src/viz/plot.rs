//! Plots: stacked line panels and grouped bars, drawn with plotters.
//!
//! A replay plots, per stream and frame, the F-score and the visible recall
//! R_vis (recall on the part the camera saw: the seen-side accuracy the
//! replay measures, `pipeline::score`) in one panel and the frame latency
//! in another. The benchmark plots its sphere sweep (F-score and
//! Chamfer-L1 against the duplicates' σ, the paper's Fig. 8 experiment) and
//! the F-score per input condition of Table 1 beside the peers' figures.
//!
//! The legend sits in its own column right of the chart, never on the data:
//! drawn inside the chart, it hid the last sweep point, the last frames of a
//! replay's F curve and two bars of `conditions.png` (seen in those pictures).

use super::{draw_err, ensure_font, Canvas, VizError, FAMILY};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
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
/// Width of the legend column right of each chart.
const LEGEND_W: u32 = 210;
/// Legend rows: height, and the top of the first (below the caption).
const LEGEND_ROW: i32 = 20;
const LEGEND_TOP: i32 = 40;

/// How a legend entry shows its series.
#[derive(Clone, Copy)]
enum Swatch {
    Line,
    Bar,
}

/// Split `area` into the chart (left) and the legend column (right).
fn with_legend_column<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
) -> (
    DrawingArea<DB, plotters::coord::Shift>,
    DrawingArea<DB, plotters::coord::Shift>,
) {
    let w = area.dim_in_pixel().0;
    area.split_horizontally(w.saturating_sub(LEGEND_W))
}

/// One row per label, top down: the series' colour `colour(i)` as a short
/// line or a filled square, then the label; the rows that do not fit in
/// the column's height are counted in a last row instead.
fn draw_legend<'a, DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    labels: impl ExactSizeIterator<Item = &'a str>,
    swatch: Swatch,
    what: &str,
) -> Result<(), VizError> {
    let style = TextStyle::from((FAMILY, 14).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    let h = area.dim_in_pixel().1 as i32;
    let fit = ((h - LEGEND_TOP) / LEGEND_ROW).max(1) as usize;
    let n = labels.len();
    let shown = if n > fit { fit - 1 } else { n };
    if shown < n {
        let y = LEGEND_TOP + LEGEND_ROW * shown as i32;
        area.draw(&Text::new(
            format!("+ {} more", n - shown),
            (30, y),
            style.clone(),
        ))
        .map_err(draw_err(what))?;
    }
    for (i, label) in labels.take(shown).enumerate() {
        let (c, y) = (colour(i), LEGEND_TOP + LEGEND_ROW * i as i32);
        match swatch {
            Swatch::Line => area.draw(&PathElement::new(vec![(4, y), (24, y)], c.stroke_width(2))),
            Swatch::Bar => area.draw(&Rectangle::new([(7, y - 6), (19, y + 6)], c.filled())),
        }
        .map_err(draw_err(what))?;
        area.draw(&Text::new(label, (30, y), style.clone()))
            .map_err(draw_err(what))?;
    }
    Ok(())
}

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
    let (area, legend) = with_legend_column(area);
    let mut chart = ChartBuilder::on(&area)
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
            .map_err(draw_err(what))?;
        chart
            .draw_series(finite(s).map(|p| Circle::new(p, 3, c.filled())))
            .map_err(draw_err(what))?;
    }
    let labels = panel.series.iter().map(|s| s.label.as_str());
    draw_legend(&legend, labels, Swatch::Line, what)
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
        let (area, legend) = with_legend_column(&root);
        let mut chart = ChartBuilder::on(&area)
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
        let labels = bars.series.iter().map(|(l, _)| l.as_str());
        draw_legend(&legend, labels, Swatch::Bar, what)?;
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
    for (si, (_, values)) in bars.series.iter().enumerate() {
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
        chart.draw_series(rects).map_err(draw_err(what))?;
    }
    Ok(())
}
