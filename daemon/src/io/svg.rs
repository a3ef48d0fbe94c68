//! SVG pictures of a map: the estimate over the ground truth and the initial
//! guess, so a reader sees at a glance whether the map closed.

use crate::geometry::Pose2;
use plotters::prelude::*;
use std::path::Path;

/// One trajectory to draw.
pub struct Layer<'a> {
    /// Legend text.
    pub label: &'a str,
    /// Positions in keyframe order.
    pub poses: &'a [Pose2],
    /// Stroke colour.
    pub color: RGBColor,
}

/// Colour of the estimate.
pub const ESTIMATE: RGBColor = RGBColor(200, 30, 30);
/// Colour of the ground truth.
pub const TRUTH: RGBColor = RGBColor(40, 40, 40);
/// Colour of the initial guess.
pub const GUESS: RGBColor = RGBColor(150, 170, 220);

/// Draws the layers as polylines into one SVG, equal axes, with a legend.
/// The first layer is drawn last, on top.
pub fn write_svg(path: &Path, title: &str, layers: &[Layer<'_>]) -> Result<(), String> {
    write_panels(path, &[(title, layers)])
}

/// Draws several titled panels side by side into one SVG.
pub fn write_panels(path: &Path, panels: &[(&str, &[Layer<'_>])]) -> Result<(), String> {
    let width = 800 * panels.len() as u32;
    let root = SVGBackend::new(path, (width, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let areas = root.split_evenly((1, panels.len()));
    for (area, (title, layers)) in areas.iter().zip(panels) {
        draw_panel(area, title, layers).map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| format!("{}: {e}", path.display()))
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    layers: &[Layer<'_>],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let pts = layers
        .iter()
        .flat_map(|l| l.poses.iter())
        .filter(|p| p.is_finite());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for p in pts {
        x0 = x0.min(p.x);
        x1 = x1.max(p.x);
        y0 = y0.min(p.y);
        y1 = y1.max(p.y);
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    // equal aspect: pad the shorter side
    let span = (x1 - x0).max(y1 - y0).max(1e-9) * 1.05;
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(30)
        .y_label_area_size(45)
        .build_cartesian_2d(cx - span / 2.0..cx + span / 2.0, cy - span / 2.0..cy + span / 2.0)?;
    chart
        .configure_mesh()
        .light_line_style(WHITE)
        .x_desc("x (m)")
        .y_desc("y (m)")
        .draw()?;
    for layer in layers.iter().rev() {
        let color = layer.color;
        chart
            .draw_series(LineSeries::new(
                layer.poses.iter().filter(|p| p.is_finite()).map(|p| (p.x, p.y)),
                color.stroke_width(1),
            ))?
            .label(layer.label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()?;
    Ok(())
}
