//! Debug views: a receiver polygon's outline, its discontinuity segments coloured by kind, and
//! its final triangulation, as SVG.

use crate::discontinuity::{Kind, Segment};
use crate::mesh::ReceiverMesh;
use crate::scene::Polygon;
use glam::DVec2;
use std::fmt::Write;

/// Colour of each segment kind in the SVG.
pub(crate) fn colour(kind: Kind) -> &'static str {
    match kind {
        Kind::D0 => "#d62728",
        Kind::Ve => "#1f77b4",
        Kind::Ev => "#2ca02c",
        Kind::Punctual => "#9467bd",
        Kind::Corner => "#ff7f0e",
    }
}

/// An SVG of `polygon` (plane coordinates, y up) with its `mesh` in grey, `segments` coloured by
/// kind, and the outline in black. `size` is the width of the drawing in pixels.
pub fn mesh_svg(polygon: &Polygon, mesh: &ReceiverMesh, segments: &[Segment], size: f64) -> String {
    let pts = polygon.triangles_plane.iter().flatten();
    let (lo, hi) = pts.fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let span = (hi - lo).max(DVec2::splat(1e-300));
    let scale = size / span.x.max(span.y);
    let margin = 10.0;
    let (w, h) = (
        span.x * scale + 2.0 * margin,
        span.y * scale + 2.0 * margin + 24.0,
    );
    let map = |p: DVec2| (margin + (p.x - lo.x) * scale, margin + (hi.y - p.y) * scale);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w:.0}" height="{h:.0}" viewBox="0 0 {w:.1} {h:.1}">"#
    );
    let _ = writeln!(s, r#"<rect width="100%" height="100%" fill="white"/>"#);
    let _ = writeln!(s, r##"<g stroke="#aaa" stroke-width="0.5" fill="none">"##);
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| map(mesh.vertices[i as usize]));
        let _ = writeln!(
            s,
            r#"<path d="M{:.2},{:.2}L{:.2},{:.2}L{:.2},{:.2}Z"/>"#,
            a.0, a.1, b.0, b.1, c.0, c.1
        );
    }
    let _ = writeln!(s, "</g>");
    let _ = writeln!(s, r#"<g stroke="black" stroke-width="1.5">"#);
    for [a, b] in &polygon.boundary {
        let (a, b) = (map(*a), map(*b));
        let _ = writeln!(
            s,
            r#"<line x1="{:.2}" y1="{:.2}" x2="{:.2}" y2="{:.2}"/>"#,
            a.0, a.1, b.0, b.1
        );
    }
    let _ = writeln!(s, "</g>");
    for seg in segments {
        let (a, b) = (map(seg.a), map(seg.b));
        let _ = writeln!(
            s,
            r#"<line x1="{:.2}" y1="{:.2}" x2="{:.2}" y2="{:.2}" stroke="{}" stroke-width="1.5"><title>{:?} event {} significance {:.3}</title></line>"#,
            a.0,
            a.1,
            b.0,
            b.1,
            colour(seg.kind),
            seg.kind,
            seg.event,
            seg.significance
        );
    }
    let legend_y = h - 8.0;
    let mut x = margin;
    for kind in [Kind::D0, Kind::Ve, Kind::Ev, Kind::Punctual, Kind::Corner] {
        let _ = writeln!(
            s,
            r#"<text x="{x:.0}" y="{legend_y:.0}" font-family="sans-serif" font-size="12" fill="{}">{kind:?}</text>"#,
            colour(kind)
        );
        x += 60.0;
    }
    let _ = writeln!(
        s,
        r#"<text x="{x:.0}" y="{legend_y:.0}" font-family="sans-serif" font-size="12">{} triangles, {} segments</text>"#,
        mesh.triangles.len(),
        segments.len()
    );
    s.push_str("</svg>\n");
    s
}
