//! What the measurements say: the charts' panels, the plain-language findings and
//! `report.md`.

use super::{MIB, Method, Region, Report, Run, ScalingRow, SceneReport, chart};

#[derive(Clone, Copy, PartialEq)]
pub(super) enum Axis {
    Elements,
    Seconds,
}

fn series(report: &SceneReport, x: Axis, y: &dyn Fn(&Run) -> Option<f64>) -> Vec<chart::Series> {
    let mut methods: Vec<Method> = Vec::new();
    for r in &report.runs {
        let m = Method {
            mesher: r.mesher,
            direct: r.direct,
            solver: r.solver,
            form_factors: r.form_factors,
            hr_scale: r.hr_scale,
        };
        if !methods.contains(&m) {
            methods.push(m);
        }
    }
    methods
        .iter()
        .map(|m| chart::Series {
            label: m.name(),
            colour: m.colour(),
            dashed: m.dashed(),
            points: report
                .runs
                .iter()
                .filter(|r| r.method == m.name())
                .filter_map(|r| {
                    let xv = match x {
                        Axis::Elements => r.elements as f64,
                        Axis::Seconds => r.seconds,
                    };
                    y(r).map(|yv| (xv, yv))
                })
                .collect(),
        })
        .collect()
}

pub(super) fn error_panels(report: &SceneReport, x: Axis) -> Vec<chart::Panel> {
    let x_label = match x {
        Axis::Elements => "elements",
        Axis::Seconds => "seconds (discontinuity + mesh + solve + lightmap)",
    };
    let noise = |region: Option<Region>| {
        let r = report.runs.first()?;
        let e = match region {
            None => r.error,
            Some(g) => *r.regions.get(&g)?,
        };
        Some((e.noise, "reference noise".to_string()))
    };
    let mut panels = vec![chart::Panel {
        title: format!("{}: all texels", report.scene),
        x_label: x_label.into(),
        y_label: "RMSE / mean lit irradiance".into(),
        series: series(report, x, &|r| Some(r.error.rmse)),
        floor: noise(None),
    }];
    for region in [
        Region::Penumbra,
        Region::Umbra,
        Region::Contact,
        Region::Indirect,
    ] {
        if report.region_texels.get(&region).copied().unwrap_or(0) == 0 {
            continue;
        }
        panels.push(chart::Panel {
            title: format!(
                "{}: {} ({} texels)",
                report.scene,
                region.name(),
                report.region_texels[&region]
            ),
            x_label: x_label.into(),
            y_label: "RMSE / mean lit irradiance".into(),
            series: series(report, x, &|r| r.regions.get(&region).map(|e| e.rmse)),
            floor: noise(Some(region)),
        });
    }
    panels
}

pub(super) fn failure_panels(sweep: &[SceneReport]) -> Vec<chart::Panel> {
    sweep
        .iter()
        .map(|s| chart::Panel {
            title: s.scene.clone(),
            x_label: "elements".into(),
            y_label: "RMSE / mean lit irradiance".into(),
            series: series(s, Axis::Elements, &|r| Some(r.error.rmse)),
            floor: s
                .runs
                .first()
                .map(|r| (r.error.noise, "reference noise".to_string())),
        })
        .collect()
}

/// `y` at `x` on the piecewise-linear log-log curve through `points` (sorted by x), `None`
/// outside its range.
fn interpolate(points: &[(f64, f64)], x: f64) -> Option<f64> {
    points.windows(2).find_map(|w| {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        if x < x0.min(x1) || x > x0.max(x1) || x0 <= 0.0 || x1 <= 0.0 || y0 <= 0.0 || y1 <= 0.0 {
            return None;
        }
        let t = if x1 == x0 {
            0.0
        } else {
            (x / x0).ln() / (x1 / x0).ln()
        };
        Some((y0.ln() + t * (y1 / y0).ln()).exp())
    })
}

/// The smallest `x` at which the log-log curve through `points` (sorted by x) comes down to
/// `y`, `None` if it never does.
fn reaches(points: &[(f64, f64)], y: f64) -> Option<f64> {
    if points.first().is_some_and(|p| p.1 <= y) {
        return points.first().map(|p| p.0);
    }
    points.windows(2).find_map(|w| {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        if !(y1 <= y && y < y0) || x0 <= 0.0 || y1 <= 0.0 || y <= 0.0 {
            return None;
        }
        let t = (y / y0).ln() / (y1 / y0).ln();
        Some((x0.ln() + t * (x1 / x0).ln()).exp())
    })
}

fn curve(report: &SceneReport, method: &str, x: Axis, region: Option<Region>) -> Vec<(f64, f64)> {
    let mut points: Vec<(f64, f64)> = report
        .runs
        .iter()
        .filter(|r| r.method == method)
        .filter_map(|r| {
            let e = match region {
                None => r.error.rmse,
                Some(g) => r.regions.get(&g)?.rmse,
            };
            let xv = match x {
                Axis::Elements => r.elements as f64,
                Axis::Seconds => r.seconds,
            };
            Some((xv, e))
        })
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points
}

/// Plain-language findings: discontinuity meshing against each other mesher, at the finest
/// budget by region, at equal time, and the cost of reaching its error.
fn findings(report: &SceneReport) -> Vec<String> {
    let dm = "discontinuity-exact";
    let Some(d) = report.finest(dm) else {
        return vec!["No discontinuity-exact runs: nothing to compare against.".into()];
    };
    let mut out = Vec::new();
    for other in ["uniform-exact", "adaptive-exact"] {
        let Some(o) = report.finest(other) else {
            continue;
        };
        let mut parts = vec![format!("all texels {}", ratio(d.error.rmse, o.error.rmse))];
        for region in [
            Region::Lit,
            Region::Penumbra,
            Region::Umbra,
            Region::Contact,
        ] {
            if let (Some(a), Some(b)) = (d.regions.get(&region), o.regions.get(&region)) {
                parts.push(format!("{} {}", region.name(), ratio(a.rmse, b.rmse)));
            }
        }
        out.push(format!(
            "At its largest budget ({} elements, {:.2} s) {dm}'s RMSE against {other}'s ({} elements, {:.2} s): {}.",
            d.elements,
            d.seconds,
            o.elements,
            o.seconds,
            parts.join(", ")
        ));
        let mut equal_time = Vec::new();
        let mut cost = Vec::new();
        for r in report.runs.iter().filter(|r| r.method == dm) {
            if let Some(e) = interpolate(&curve(report, other, Axis::Seconds, None), r.seconds) {
                equal_time.push(format!(
                    "at {:.2} s {} vs {}",
                    r.seconds,
                    pct(r.error.rmse),
                    pct(e)
                ));
            }
            let elements = reaches(&curve(report, other, Axis::Elements, None), r.error.rmse);
            let seconds = reaches(&curve(report, other, Axis::Seconds, None), r.error.rmse);
            cost.push(match (elements, seconds) {
                (Some(n), Some(t)) => format!(
                    "{} ({} elements, {:.2} s): {other} needs {:.0} elements, {:.2} s",
                    pct(r.error.rmse),
                    r.elements,
                    r.seconds,
                    n,
                    t
                ),
                _ => format!(
                    "{} ({} elements, {:.2} s): {other} does not reach it in this sweep",
                    pct(r.error.rmse),
                    r.elements,
                    r.seconds
                ),
            });
        }
        if !equal_time.is_empty() {
            out.push(format!(
                "At equal time, all-texel RMSE {dm} vs {other} (interpolated): {}.",
                equal_time.join("; ")
            ));
        }
        if !cost.is_empty() {
            out.push(format!("Reaching {dm}'s error: {}.", cost.join("; ")));
        }
    }
    if let Some(s) = report.finest("discontinuity-sampled") {
        out.push(format!(
            "Sampled direct light with discontinuity meshing, largest budget: RMSE {} in {:.2} s, against {} in {:.2} s exact.",
            pct(s.error.rmse),
            s.seconds,
            pct(d.error.rmse),
            d.seconds
        ));
    }
    out
}

/// Both errors, and the ratio when both are above 0.01% (below that, noise decides).
fn ratio(a: f64, b: f64) -> String {
    let both = format!("{} vs {}", pct(a), pct(b));
    if a < 1e-4 || b < 1e-4 {
        both
    } else if a <= b {
        format!("{both} ({:.2}x lower)", b / a)
    } else {
        format!("{both} ({:.2}x HIGHER)", a / b)
    }
}

/// Slope of `y` against `x` on log-log axes, by least squares (the exponent of a power law).
fn log_log_slope(points: &[(f64, f64)]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// The other solvers and form factors against `discontinuity-exact` (progressive, closed
/// form, the same mesh) at the largest budget, by region and time; and the matrix's growth.
fn classic_findings(report: &SceneReport) -> Vec<String> {
    let base = "discontinuity-exact";
    let mut out = Vec::new();
    if let Some(d) = report.finest(base) {
        for m in Method::known().iter().filter(|m| !m.is_default_solve()) {
            let name = m.name();
            let Some(r) = report.finest(&name) else {
                continue;
            };
            let mut parts = vec![format!("all texels {}", ratio(r.error.rmse, d.error.rmse))];
            for region in Region::ALL {
                if let (Some(a), Some(b)) = (r.regions.get(&region), d.regions.get(&region)) {
                    parts.push(format!("{} {}", region.name(), ratio(a.rmse, b.rmse)));
                }
            }
            let mut cost = format!("indirect solve {:.2} s", r.indirect_seconds);
            if let Some(bytes) = r.matrix_bytes {
                cost.push_str(&format!(", matrix {:.1} MiB", bytes as f64 / MIB));
            }
            if let Some(h) = r.hemicubes {
                cost.push_str(&format!(", {h} hemicubes"));
            }
            out.push(format!(
                "{name} at its largest budget ({} elements, {:.2} s; {cost}) against {base} ({:.2} s; indirect solve {:.2} s), RMSE: {}.",
                r.elements,
                r.seconds,
                d.seconds,
                d.indirect_seconds,
                parts.join(", ")
            ));
        }
    }
    let s = &report.scaling;
    if let (Some(first), Some(last)) = (s.first(), s.last())
        && s.len() >= 2
    {
        let slope = |f: &dyn Fn(&ScalingRow) -> f64| {
            log_log_slope(
                &s.iter()
                    .map(|r| (r.patches as f64, f(r)))
                    .collect::<Vec<_>>(),
            )
            .map_or("-".into(), |k| format!("{k:.2}"))
        };
        out.push(format!(
            "Growth with the patch count ({} to {} patches, patch solve alone): the matrix takes {:.2} to {:.1} MiB (exponent {}), filling it {:.2} to {:.2} s (exponent {}), Gauss-Seidel {:.3} to {:.3} s; progressive refinement to 0.1% unshot takes {:.2} to {:.2} s (exponent {}, {} to {} shots) in O(n) memory. At this rate 100 000 patches would need a {:.0} GiB matrix.",
            first.patches,
            last.patches,
            first.matrix_bytes as f64 / MIB,
            last.matrix_bytes as f64 / MIB,
            slope(&|r| r.matrix_bytes as f64),
            first.matrix_fill_seconds,
            last.matrix_fill_seconds,
            slope(&|r| r.matrix_fill_seconds),
            first.matrix_solve_seconds,
            last.matrix_solve_seconds,
            first.progressive_seconds,
            last.progressive_seconds,
            slope(&|r| r.progressive_seconds),
            first.progressive_shots,
            last.progressive_shots,
            crate::solve::matrix::bytes(100_000) as f64 / (MIB * 1024.0)
        ));
    }
    out
}

fn scaling_table(s: &[ScalingRow], md: &mut String) {
    use std::fmt::Write;
    let _ = writeln!(
        md,
        "| patches | matrix MiB | matrix fill s | Gauss-Seidel s | sweeps | progressive s | shots |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|");
    for r in s {
        let _ = writeln!(
            md,
            "| {} | {:.2} | {:.2} | {:.3} | {} | {:.2} | {} |",
            r.patches,
            r.matrix_bytes as f64 / MIB,
            r.matrix_fill_seconds,
            r.matrix_solve_seconds,
            r.matrix_sweeps,
            r.progressive_seconds,
            r.progressive_shots
        );
    }
}

fn pct(v: f64) -> String {
    format!("{:.2}%", 100.0 * v)
}

fn runs_table(report: &SceneReport, md: &mut String) {
    use std::fmt::Write;
    let regions: Vec<Region> = Region::ALL
        .into_iter()
        .filter(|r| report.region_texels.contains_key(r))
        .collect();
    let _ = write!(
        md,
        "| method | budget | elements | seconds | indirect s | RMSE all |"
    );
    for r in &regions {
        let _ = write!(md, " {} |", r.name());
    }
    let _ = writeln!(md, " max |");
    let _ = writeln!(md, "|{}", "---|".repeat(7 + regions.len()));
    for run in &report.runs {
        let _ = write!(
            md,
            "| {} | {} | {} | {:.2} | {:.2} | {} |",
            run.method,
            run.budget,
            run.elements,
            run.seconds,
            run.indirect_seconds,
            pct(run.error.rmse)
        );
        for r in &regions {
            let _ = write!(
                md,
                " {} |",
                run.regions.get(r).map_or("-".into(), |e| pct(e.rmse))
            );
        }
        let _ = writeln!(md, " {} |", pct(run.error.max));
    }
}

fn scene_summary(s: &SceneReport) -> String {
    let regions: Vec<String> = s
        .region_texels
        .iter()
        .map(|(r, n)| format!("{} {n}", r.name()))
        .collect();
    format!(
        "Lightmap {}x{}, {} covered texels ({}). Reference: {} spp, {:.0} s, mean relative \
         standard error {}. Mean lit irradiance E_lit = {:.4} W/m².",
        s.lightmap_width,
        s.lightmap_height,
        s.covered_texels,
        regions.join(", "),
        s.reference_spp,
        s.reference_seconds,
        pct(s.reference_mean_relative_std_error),
        s.mean_lit_irradiance
    )
}

/// `report.md`: the findings and every run, for the scene and the failure sweep.
pub(super) fn markdown(report: &Report) -> String {
    use std::fmt::Write;
    let s = &report.scene;
    let mut md = String::new();
    let _ = writeln!(md, "# penumbra compare: {}\n", s.scene);
    let _ = writeln!(
        md,
        "`{}` (penumbra {}, {} threads, {:.0} s in all)\n",
        report.command, report.penumbra_version, report.threads, report.seconds
    );
    let _ = writeln!(md, "{}\n", scene_summary(s));
    let _ = writeln!(
        md,
        "Errors are RMSE relative to E_lit with the reference's own variance removed (raw RMSE \
         and the noise are in report.json); `max` is the largest texel error beyond three \
         reference standard errors. Seconds are the method-dependent stages (discontinuity, \
         mesh, solve, lightmap) on this machine: compare them within one run.\n"
    );
    let _ = writeln!(md, "## Findings\n");
    for f in findings(s) {
        let _ = writeln!(md, "- {f}");
    }
    let classic = classic_findings(s);
    if !classic.is_empty() {
        let _ = writeln!(
            md,
            "\n## Classic methods\n\nThe other solvers and form factors on the discontinuity \
             mesh, against progressive refinement with closed-form form factors \
             (discontinuity-exact), and the classic 1985 pipeline (uniform mesh, hemicube, \
             matrix). Hemicube methods carry the area emitters' light through the hemicube \
             too.\n"
        );
        for f in classic {
            let _ = writeln!(md, "- {f}");
        }
        if !s.scaling.is_empty() {
            let _ = writeln!(
                md,
                "\nThe patch solve alone as the patches grow (uniform mesh, budget 250, \
                 closed-form form factors, both to convergence):\n"
            );
            scaling_table(&s.scaling, &mut md);
        }
    }
    let _ = writeln!(md, "\n## All runs\n");
    runs_table(s, &mut md);
    if !report.failure_sweep.is_empty() {
        let _ = writeln!(
            md,
            "\n## Failure sweep\n\nScenes built to break a method, at smaller settings (exact \
             direct light, budgets 500 / 2000 / 8000). Chart: failure_sweep.png.\n"
        );
        for f in &report.failure_sweep {
            let _ = writeln!(
                md,
                "### {}\n\n{}\n\n{}\n",
                f.scene,
                f.description,
                scene_summary(f)
            );
            for line in findings(f).into_iter().chain(classic_findings(f)) {
                let _ = writeln!(md, "- {line}");
            }
            let _ = writeln!(md);
            runs_table(f, &mut md);
            let _ = writeln!(md);
        }
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_log_interpolation() {
        let c = [(100.0, 0.1), (1000.0, 0.01)];
        assert!((interpolate(&c, 316.227_766).unwrap() - 0.031_622_776).abs() < 1e-6);
        assert_eq!(interpolate(&c, 50.0), None);
        assert!((reaches(&c, 0.031_622_776).unwrap() - 316.227_766).abs() < 1e-3);
        assert_eq!(reaches(&c, 0.001), None);
        assert_eq!(reaches(&c, 0.5), Some(100.0));
    }
}
