//! D0: the contact segments where other surfaces touch, cross or lie on a receiver.

use super::NEAR_CONTACT;
use super::receivers::{PolygonIndex, clip_segment_to_polygon};
use crate::scene::Scene;
use glam::{DVec2, DVec3};

/// Contact segments on receiver `r`: other triangles touching, crossing or lying in its plane,
/// or hovering in front of it within [`NEAR_CONTACT`]. Then the corners: the pieces along its
/// outline where another surface reaches in front of it ([`Kind::Corner`](super::Kind::Corner)).
pub(super) fn contacts(
    scene: &Scene,
    index: &PolygonIndex,
    r: usize,
    tol: f64,
) -> [Vec<(DVec3, DVec3)>; 2] {
    let poly = &scene.polygons[r];
    let frame = &poly.frame;
    let near = NEAR_CONTACT * scene.extent();
    let corners: Vec<DVec3> = poly
        .triangles
        .iter()
        .flat_map(|&t| scene.triangles[t].p)
        .collect();
    let mut out = Vec::new();
    let mut along_outline = Vec::new();
    let in_front: Vec<DVec3> = corners
        .iter()
        .flat_map(|&c| [c, c + frame.n * near])
        .collect();
    for other in index.query(&in_front) {
        // The back side of a double-sided surface coincides with its front, which gives the
        // same contacts (the receiver's own back side gives none: its outline is the
        // receiver's).
        if other == r || scene.is_back_polygon(other) {
            continue;
        }
        let op = &scene.polygons[other];
        let height = |p: DVec3| frame.n.dot(p - frame.origin);
        let flat = op.triangles.iter().all(|&t| {
            scene.triangles[t]
                .p
                .iter()
                .all(|&p| (-tol..=near).contains(&height(p)))
        });
        let mut raw = Vec::new();
        if flat {
            // Coplanar: its outline is where a different surface starts. Hovering just in
            // front (a light fitted a hair below a ceiling): it hides the whole hemisphere but
            // a sliver, so the light jumps across its outline as at a contact.
            raw.extend(op.boundary.iter().map(|[a, b]| {
                let world = |p| op.frame.world_from_plane(p);
                (world(*a), world(*b), false)
            }));
        }
        for &t in op.triangles.iter().filter(|_| !flat) {
            let tri = &scene.triangles[t];
            let d = tri.p.map(height);
            if d.iter().any(|&x| x <= tol) && d.iter().any(|&x| x >= -tol) {
                let mut pts = Vec::new();
                for e in 0..3 {
                    let (i, j) = (e, (e + 1) % 3);
                    if d[i].abs() <= tol {
                        pts.push(tri.p[i]);
                    }
                    if (d[i] < -tol && d[j] > tol) || (d[i] > tol && d[j] < -tol) {
                        let s = d[i] / (d[i] - d[j]);
                        pts.push(tri.p[i] + (tri.p[j] - tri.p[i]) * s);
                    }
                }
                // The two farthest apart points span the contact.
                let mut best = (0.0, DVec3::ZERO, DVec3::ZERO);
                for i in 0..pts.len() {
                    for j in i + 1..pts.len() {
                        let l = pts[i].distance_squared(pts[j]);
                        if l > best.0 {
                            best = (l, pts[i], pts[j]);
                        }
                    }
                }
                if best.0 > tol * tol {
                    raw.push((best.1, best.2, d.iter().any(|&x| x > tol)));
                }
            }
        }
        for (a, b, in_front) in raw {
            // Project onto the plane, then keep the part inside the polygon and off its
            // outline (a contact along the outline is no jump inside it: a corner, when the
            // other surface reaches in front).
            let a = a - frame.n * frame.n.dot(a - frame.origin);
            let b = b - frame.n * frame.n.dot(b - frame.origin);
            for (p, q) in clip_segment_to_polygon(scene, index, r, a, b, &[], tol) {
                let (pp, pq) = (frame.plane_from_world(p), frame.plane_from_world(q));
                if !on_outline(poly, pp, pq, 10.0 * tol) {
                    out.push((p, q));
                } else if in_front {
                    along_outline.push((p, q));
                }
            }
        }
    }
    [out, along_outline]
}

/// True when the plane segment `a-b` lies along one of the polygon's boundary edges.
fn on_outline(poly: &crate::scene::Polygon, a: DVec2, b: DVec2, tol: f64) -> bool {
    let near = |x: DVec2, p: DVec2, q: DVec2| {
        let d = q - p;
        let t = ((x - p).dot(d) / d.length_squared().max(1e-300)).clamp(0.0, 1.0);
        x.distance(p + d * t) <= tol
    };
    poly.boundary
        .iter()
        .any(|[p, q]| near(a, *p, *q) && near(b, *p, *q) && near((a + b) * 0.5, *p, *q))
}
