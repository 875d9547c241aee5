//! Log-log line charts (plotters), drawn once for both SVG and PNG: small multiples, one panel
//! per measure, one curve per method.

use crate::error::{Error, Result};
use plotters::coord::Shift;
use plotters::prelude::*;

/// One curve.
#[derive(Clone, Debug)]
pub(crate) struct Series {
    pub(crate) label: String,
    pub(crate) colour: (u8, u8, u8),
    /// Dashed (e.g. sampled direct light) rather than solid.
    pub(crate) dashed: bool,
    /// (x, y) points, both positive (log axes); others are skipped.
    pub(crate) points: Vec<(f64, f64)>,
}

/// One panel: log-log axes with its own ranges.
#[derive(Clone, Debug)]
pub(crate) struct Panel {
    pub(crate) title: String,
    pub(crate) x_label: String,
    pub(crate) y_label: String,
    pub(crate) series: Vec<Series>,
    /// A horizontal reference line (e.g. the reference's own noise), with its legend label.
    pub(crate) floor: Option<(f64, String)>,
}

/// The reference line's colour (and its legend sample's).
const FLOOR_GREY: (u8, u8, u8) = (150, 150, 150);

/// Panel size in pixels.
const PANEL: (u32, u32) = (480, 360);

fn chart_error<E: std::fmt::Debug>(e: E) -> Error {
    Error::Image(format!("chart: {e:?}"))
}

/// The panels as an SVG, `columns` panels per row.
pub(crate) fn svg(panels: &[Panel], columns: usize) -> Result<String> {
    let size = grid_size(panels.len(), columns);
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, size).into_drawing_area();
        draw(&root, panels, columns)?;
        root.present().map_err(chart_error)?;
    }
    Ok(out)
}

/// The panels as a PNG (text in DejaVu Sans, bundled), `columns` panels per row.
pub(crate) fn png(panels: &[Panel], columns: usize) -> Result<Vec<u8>> {
    let (w, h) = grid_size(panels.len(), columns);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        draw(&root, panels, columns)?;
        root.present().map_err(chart_error)?;
    }
    crate::write::png_bytes(&rgb, w, h)
}

fn grid_size(n: usize, columns: usize) -> (u32, u32) {
    let columns = columns.clamp(1, n.max(1));
    let rows = n.div_ceil(columns).max(1);
    (PANEL.0 * columns as u32, PANEL.1 * rows as u32)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    panels: &[Panel],
    columns: usize,
) -> Result<()> {
    // Text is laid out with the bundled font's metrics, for SVG too.
    super::pictures::register_font()?;
    root.fill(&WHITE).map_err(chart_error)?;
    let columns = columns.clamp(1, panels.len().max(1));
    let rows = panels.len().div_ceil(columns).max(1);
    let areas = root.split_evenly((rows, columns));
    // With a free slot in the grid, one legend there for every panel, off their curves;
    // else each panel carries its own.
    let spare = areas.get(panels.len());
    for (panel, area) in panels.iter().zip(areas.iter()) {
        draw_panel(area, panel, spare.is_none())?;
    }
    if let Some(area) = spare {
        draw_legend(area, panels)?;
    }
    Ok(())
}

/// Every curve's label (and the reference line's), once, in order of first appearance, as a
/// column of line samples and names in `area`.
fn draw_legend<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, panels: &[Panel]) -> Result<()> {
    struct Entry<'a> {
        label: &'a str,
        colour: (u8, u8, u8),
        dashed: bool,
        width: u32,
    }
    let mut entries: Vec<Entry> = Vec::new();
    for p in panels {
        if let Some((_, label)) = &p.floor
            && !entries.iter().any(|e| e.label == label)
        {
            entries.push(Entry {
                label,
                colour: FLOOR_GREY,
                dashed: true,
                width: 1,
            });
        }
        for s in &p.series {
            if !entries.iter().any(|e| e.label == s.label) {
                entries.push(Entry {
                    label: &s.label,
                    colour: s.colour,
                    dashed: s.dashed,
                    width: 2,
                });
            }
        }
    }
    let (x0, mut y) = (30i32, 40i32);
    for Entry {
        label,
        colour: (r, g, b),
        dashed,
        width,
    } in entries
    {
        let style = RGBColor(r, g, b).stroke_width(width);
        let pieces: Vec<(i32, i32)> = if dashed {
            vec![(x0, x0 + 9), (x0 + 14, x0 + 23), (x0 + 28, x0 + 36)]
        } else {
            vec![(x0, x0 + 36)]
        };
        for (a, b) in pieces {
            area.draw(&PathElement::new([(a, y), (b, y)], style))
                .map_err(chart_error)?;
        }
        area.draw(&Text::new(
            label,
            (x0 + 48, y - 7),
            ("sans-serif", 14).into_font().color(&BLACK),
        ))
        .map_err(chart_error)?;
        y += 22;
    }
    Ok(())
}

/// A log range around the positive values, padded a little, never empty.
fn log_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return 0.1..1.0;
    }
    if hi <= lo * 1.5 {
        (lo, hi) = (lo / 1.5, hi * 1.5);
    }
    lo * 0.8..hi * 1.25
}

/// Tick labels that stay short over many decades.
fn tick(v: f64) -> String {
    if v >= 100.0 {
        format!("{v:.0}")
    } else if v >= 1.0 {
        format!("{v:.1}")
    } else {
        let digits = (-v.log10()).ceil().max(1.0) as usize + 1;
        format!("{v:.digits$}")
    }
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
    legend: bool,
) -> Result<()> {
    let ok = |p: &&(f64, f64)| p.0 > 0.0 && p.1 > 0.0 && p.0.is_finite() && p.1.is_finite();
    let xs = panel
        .series
        .iter()
        .flat_map(|s| s.points.iter().filter(ok).map(|p| p.0));
    let ys = panel
        .series
        .iter()
        .flat_map(|s| s.points.iter().filter(ok).map(|p| p.1))
        .chain(panel.floor.iter().map(|f| f.0));
    let (x_range, y_range) = (log_range(xs), log_range(ys));
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x_range.clone().log_scale(), y_range.log_scale())
        .map_err(chart_error)?;
    chart
        .configure_mesh()
        .x_desc(&panel.x_label)
        .y_desc(&panel.y_label)
        .x_labels(6)
        .y_labels(6)
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .light_line_style(WHITE)
        .draw()
        .map_err(chart_error)?;
    if let Some((y, label)) = &panel.floor {
        let grey = RGBColor(FLOOR_GREY.0, FLOOR_GREY.1, FLOOR_GREY.2);
        chart
            .draw_series(DashedLineSeries::new(
                [(x_range.start, *y), (x_range.end, *y)],
                3,
                4,
                grey.stroke_width(1),
            ))
            .map_err(chart_error)?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 16, y)], grey.stroke_width(1)));
    }
    for s in &panel.series {
        let points: Vec<(f64, f64)> = s.points.iter().filter(ok).copied().collect();
        if points.is_empty() {
            continue;
        }
        let c = RGBColor(s.colour.0, s.colour.1, s.colour.2);
        let style = c.stroke_width(2);
        let drawn = if s.dashed {
            chart.draw_series(DashedLineSeries::new(points.clone(), 6, 4, style))
        } else {
            chart.draw_series(LineSeries::new(points.clone(), style))
        };
        let dashed = s.dashed;
        drawn
            .map_err(chart_error)?
            .label(s.label.as_str())
            .legend(move |(x, y)| {
                let end = if dashed { x + 8 } else { x + 16 };
                PathElement::new([(x, y), (end, y)], c.stroke_width(2))
            });
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 3, c.filled())))
            .map_err(chart_error)?;
    }
    if legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 12))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(chart_error)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn panel() -> Panel {
        Panel {
            title: "t".into(),
            x_label: "elements".into(),
            y_label: "RMSE".into(),
            series: vec![Series {
                label: "uniform-exact".into(),
                colour: (31, 119, 180),
                dashed: false,
                points: vec![(100.0, 0.1), (1000.0, 0.03), (0.0, 1.0)],
            }],
            floor: Some((0.01, "reference noise".into())),
        }
    }

    #[test]
    fn svg_and_png_draw_the_same_panels() {
        let svg = svg(&[panel(), panel()], 2).unwrap();
        assert!(svg.contains("uniform-exact") && svg.contains("reference noise"));
        let png = png(&[panel(), panel()], 2).unwrap();
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (960, 360));
        // Text and curves drew dark pixels; most of the image is white background.
        let dark = img
            .pixels()
            .filter(|p| p.0.iter().all(|&c| c < 100))
            .count();
        assert!(dark > 500 && dark < 960 * 360 / 4, "{dark} dark pixels");
    }

    /// Three panels on a grid of four: one legend, in the free slot, names every curve once.
    #[test]
    fn a_free_slot_holds_one_legend() {
        let mut other = panel();
        other.series[0].label = "discontinuity-exact".into();
        let three = svg(&[panel(), other, panel()], 2).unwrap();
        assert_eq!(three.matches("uniform-exact").count(), 1, "{three}");
        assert_eq!(three.matches("discontinuity-exact").count(), 1);
        assert_eq!(three.matches("reference noise").count(), 1);
        // Without a free slot each panel names its own curves.
        let two = svg(&[panel(), panel()], 2).unwrap();
        assert_eq!(two.matches("uniform-exact").count(), 2);
    }

    #[test]
    fn ticks_stay_short() {
        assert_eq!(tick(2000.0), "2000");
        assert_eq!(tick(2.5), "2.5");
        assert_eq!(tick(0.03), "0.030");
        assert_eq!(tick(0.0004), "0.00040");
    }
}
