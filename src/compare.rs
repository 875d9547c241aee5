//! Measuring meshers against each other: the error of a bake's mesh interpolant of the direct
//! light against the exact direct light, and a sweep over element budgets charted as error
//! against elements and against time (plotters, SVG).
//!
//! This is the seed of `penumbra compare`: today it measures the direct light on the floor (the
//! largest upward polygon) in its shadowed part, where meshers differ most.

use crate::lightmap::Locator;
use crate::mesh::Mesher;
use crate::solve::{Direct, SurfacePoint};
use crate::visibility::Visibility;
use crate::{Bake, BakeOptions};
use glam::DVec2;
use std::f64::consts::PI;

/// Error of the direct light in the shadowed part of the floor.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct ShadowError {
    /// RMS error relative to the floor's peak irradiance.
    pub rms: f64,
    /// Max error relative to the floor's peak irradiance.
    pub max: f64,
    /// Sample points in shadow (exact below 99.5% of unoccluded).
    pub points: usize,
}

/// Evaluates the bake's mesh interpolant of the irradiance against the exact direct light
/// ([`Direct`], backprojection) on a stratified grid of `points_per_side` points per side of
/// each triangle of the floor, keeping the points in shadow. Meaningful for bakes with
/// `bounces = Some(0)`. `None` when the scene has no upward polygon.
pub fn shadow_error(b: &Bake, points_per_side: usize) -> Option<ShadowError> {
    let scene = &b.scene;
    let vis = Visibility::new(scene);
    let direct = Direct::new(scene, &vis, 64);
    let floor = (0..scene.polygons.len())
        .filter(|&i| scene.polygons[i].frame.n.y > 0.99)
        .max_by(|&i, &j| scene.polygons[i].area.total_cmp(&scene.polygons[j].area))?;
    let poly = &scene.polygons[floor];
    let mi = b.meshes.iter().position(|m| m.polygon == floor)?;
    let loc = Locator::new(&b.meshes[mi], &b.solution.irradiance[mi]);
    let mut errors = Vec::new();
    let mut peak: f64 = 0.0;
    let n = points_per_side.max(1);
    for t in &poly.triangles_plane {
        for i in 0..n {
            for j in 0..n - i {
                let u = (i as f64 + 1.0 / 3.0) / n as f64;
                let v = (j as f64 + 1.0 / 3.0) / n as f64;
                let q: DVec2 = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
                let p = poly.frame.world_from_plane(q);
                let at = SurfacePoint::new(p, poly.frame.n, floor, &vis);
                let exact = direct.irradiance(&at).x;
                let unoccluded: f64 = direct
                    .emitters
                    .iter()
                    .map(|e| PI * e.radiance.x * e.form_factor(p, poly.frame.n))
                    .sum();
                peak = peak.max(exact);
                if exact < 0.995 * unoccluded {
                    errors.push((loc.value(q).x - exact).abs());
                }
            }
        }
    }
    let peak = peak.max(f64::MIN_POSITIVE);
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
    let max = errors.iter().copied().fold(0.0, f64::max);
    Some(ShadowError {
        rms: rms / peak,
        max: max / peak,
        points: errors.len(),
    })
}

/// One bake of a sweep.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SweepPoint {
    pub mesher: Mesher,
    pub budget: usize,
    pub elements: usize,
    /// Wall time of discontinuity + mesh + solve, seconds.
    pub seconds: f64,
    pub error: ShadowError,
}

/// Bakes `gltf` (direct light only) with every mesher at every budget.
pub fn sweep(
    gltf: &crate::load::Gltf,
    meshers: &[Mesher],
    budgets: &[usize],
    base: &BakeOptions,
) -> crate::Result<Vec<SweepPoint>> {
    let mut out = Vec::new();
    for &mesher in meshers {
        for &budget in budgets {
            let mut o = BakeOptions {
                mesher,
                budget,
                ..base.clone()
            };
            o.solve.bounces = Some(0);
            let b = crate::bake(gltf, &o, &|_, _, _| {})?;
            let t = &b.stats.timings_s;
            out.push(SweepPoint {
                mesher,
                budget,
                elements: b.stats.elements,
                seconds: t.discontinuity + t.mesh + t.solve,
                error: shadow_error(&b, 120).unwrap_or_default(),
            });
        }
    }
    Ok(out)
}

/// An SVG with two log-log panels: RMS shadow error against elements and against time, one
/// curve per mesher.
pub fn chart_svg(title: &str, points: &[SweepPoint]) -> Result<String, String> {
    use plotters::prelude::*;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (960, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (left, right) = root.split_horizontally(480);
        let meshers = [Mesher::Uniform, Mesher::Adaptive, Mesher::Discontinuity];
        let colours = [
            RGBColor(31, 119, 180),
            RGBColor(255, 127, 14),
            RGBColor(44, 160, 44),
        ];
        let range = |f: &dyn Fn(&SweepPoint) -> f64| {
            let lo = points.iter().map(f).fold(f64::INFINITY, f64::min);
            let hi = points.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
            (lo * 0.8).max(1e-9)..(hi * 1.25).max(1e-8)
        };
        let err = range(&|p| p.error.rms);
        for (area, (xlabel, x)) in [left, right].iter().zip([
            (
                "elements",
                &(|p: &SweepPoint| p.elements as f64) as &dyn Fn(&SweepPoint) -> f64,
            ),
            ("seconds (mesh + solve)", &|p: &SweepPoint| p.seconds),
        ]) {
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!("{title}: shadow RMS error vs {xlabel}"),
                    ("sans-serif", 15),
                )
                .margin(12)
                .x_label_area_size(36)
                .y_label_area_size(56)
                .build_cartesian_2d(range(x).log_scale(), err.clone().log_scale())
                .map_err(|e| e.to_string())?;
            let seconds = xlabel.starts_with("seconds");
            chart
                .configure_mesh()
                .x_desc(xlabel)
                .y_desc("RMS error / peak")
                .x_labels(5)
                .y_labels(6)
                .x_label_formatter(&|v| {
                    if seconds {
                        format!("{v:.3}")
                    } else {
                        format!("{v:.0}")
                    }
                })
                .y_label_formatter(&|v| format!("{v:.3}"))
                .light_line_style(WHITE)
                .draw()
                .map_err(|e| e.to_string())?;
            for (m, c) in meshers.iter().zip(colours) {
                let series: Vec<(f64, f64)> = points
                    .iter()
                    .filter(|p| p.mesher == *m)
                    .map(|p| (x(p), p.error.rms))
                    .collect();
                if series.is_empty() {
                    continue;
                }
                chart
                    .draw_series(LineSeries::new(series.clone(), c.stroke_width(2)))
                    .map_err(|e| e.to_string())?
                    .label(format!("{m:?}").to_lowercase())
                    .legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 16, y)], c.stroke_width(2))
                    });
                chart
                    .draw_series(series.iter().map(|&p| Circle::new(p, 3, c.filled())))
                    .map_err(|e| e.to_string())?;
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}
