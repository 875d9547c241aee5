//! Exact direct light at a point: the part of an area emitter that the point sees, by
//! backprojection by clipping.
//!
//! For a receiving point `p` with unit normal `n` and a planar emitter `E`, every occluder
//! between them is clipped to the pyramid with apex `p` over `E` (clipped to `p`'s horizon),
//! projected through `p` onto `E`'s plane, and subtracted from `E`. What remains is a set of
//! convex pieces, and Lambert's contour formula summed over them is the exact point-to-polygon
//! form factor of the visible part of the emitter, for polygonal occluders:
//!
//! ```text
//! F_visible = F(E \ union_k P_k),   P_k = projection of occluder k through p onto E's plane
//! ```
//!
//! (Drettakis and Fiume, "A fast shadow algorithm for area light sources using backprojection",
//! SIGGRAPH 1994; Stewart and Ghali, "Fast computation of shadow boundaries using spatial
//! coherence and backprojections", SIGGRAPH 1994. Both compute the backprojection per face of a
//! discontinuity mesh; here it is computed per mesh vertex.)
//!
//! Convex pieces are enough: a convex polygon minus a convex polygon is a union of at most as
//! many convex pieces as the subtracted polygon has edges. Emitters and occluders are first
//! merged into convex pieces of their planar polygons (Hertel and Mehlhorn, "Fast triangulation
//! of simple polygons", 1983: drop diagonals while the union stays convex), so a tessellated
//! panel counts as one rectangle, not hundreds of triangles.
//!
//! Coherence: [`Shaft`] bounds the convex hull of a cluster of receiving points and the emitter,
//! so the caller can cull the occluder list once per cluster (see
//! [`crate::solve::Direct::irradiance_points`]) and each vertex clips only the occluders that
//! can matter.
//!
//! All geometry is f64. Lengths in scene units; form factors are dimensionless.

use crate::geometry::{clip_polygon_to_plane, contour_sum, signed_area};
use crate::scene::Scene;
use glam::{DVec2, DVec3};

// The convex decomposition and the emitter shape live in the shared modules; re-exported here
// because the backprojection is where they are used.
pub use crate::geometry::convex_hull;
pub(crate) use crate::geometry::convex_pieces;
pub use crate::light::EmitterShape;

// ---------------------------------------------------------------------------------------------
// Occluders

/// One convex piece of a scene polygon, as an occluder.
#[derive(Clone, Debug)]
pub(crate) struct OccluderPiece {
    /// Index into [`Scene::polygons`].
    pub(crate) polygon: usize,
    /// Corners in world space (the scene's own triangle corners), convex, planar.
    pub(crate) vertices: Vec<DVec3>,
    /// True when the polygon is alpha-tested or see-through: its outline is not its shadow's
    /// (or its shadow is not black), so a point it may shadow takes shadow rays instead
    /// ([`crate::scene::Scene::cut_out_at`], [`crate::visibility::Visibility::transmitted_skipping`]).
    pub(crate) cut_out: bool,
}

/// Every polygon of a scene cut into convex pieces, for backprojection.
#[derive(Clone, Debug, Default)]
pub(crate) struct Occluders {
    pub(crate) pieces: Vec<OccluderPiece>,
    /// The piece each scene triangle belongs to (`u32::MAX`: none, a degenerate triangle).
    pub(crate) piece_of_triangle: Vec<u32>,
}

impl Occluders {
    pub(crate) fn new(scene: &Scene) -> Occluders {
        let mut pieces = Vec::new();
        let mut piece_of_triangle = vec![u32::MAX; scene.triangles.len()];
        for (id, poly) in scene.polygons.iter().enumerate() {
            let first = pieces.len() as u32;
            let (convex, owner) = convex_pieces(&poly.triangles_plane);
            let cut_out = poly
                .triangles
                .iter()
                .any(|&t| scene.is_cut_out(t) || scene.is_see_through(t));
            for piece in convex {
                let vertices = piece
                    .iter()
                    .map(|&c| scene.triangles[poly.triangles[c / 3]].p[c % 3])
                    .collect();
                pieces.push(OccluderPiece {
                    polygon: id,
                    vertices,
                    cut_out,
                });
            }
            for (&t, &k) in poly.triangles.iter().zip(&owner) {
                if k != usize::MAX {
                    piece_of_triangle[t] = first + k as u32;
                }
            }
        }
        Occluders {
            pieces,
            piece_of_triangle,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Shafts

/// A convex region bounded by planes: a conservative stand-in for the convex hull of a point
/// set (a cluster of receiving points and an emitter), used to cull occluders.
#[derive(Clone, Debug, Default)]
pub(crate) struct Shaft {
    /// Outward unit normal and a point of each bounding plane.
    planes: Vec<(DVec3, DVec3)>,
    tol: f64,
}

impl Shaft {
    /// The face planes of the convex hull of `points` (brute force over point triples: for a
    /// dozen points or so). A degenerate set gives fewer planes, so a larger region.
    pub(crate) fn hull(points: &[DVec3]) -> Shaft {
        let c = points.iter().copied().sum::<DVec3>() / points.len().max(1) as f64;
        let scale = points.iter().map(|q| q.distance(c)).fold(0.0, f64::max);
        // Coincidence to rounding, relative to the points' own size.
        let tol = crate::scene::tolerance::COINCIDENT * scale;
        let mut planes: Vec<(DVec3, DVec3)> = Vec::new();
        let m = points.len();
        for i in 0..m {
            for j in i + 1..m {
                for k in j + 1..m {
                    let nrm = (points[j] - points[i]).cross(points[k] - points[i]);
                    let len = nrm.length();
                    // An area, so squared scale: a triple this close to collinear has a
                    // normal of rounding noise.
                    if len <= 1e-12 * scale * scale {
                        continue;
                    }
                    let nrm = nrm / len;
                    let (mut above, mut below) = (false, false);
                    for q in points {
                        let d = nrm.dot(*q - points[i]);
                        above |= d > tol;
                        below |= d < -tol;
                    }
                    let outward = match (above, below) {
                        (false, _) => nrm,
                        (true, false) => -nrm,
                        (true, true) => continue,
                    };
                    let o = points[i];
                    if !planes
                        .iter()
                        .any(|(n, p)| n.dot(outward) > 1.0 - 1e-12 && n.dot(o - *p).abs() <= tol)
                    {
                        planes.push((outward, o));
                    }
                }
            }
        }
        Shaft { planes, tol }
    }

    /// Adds the half-space `normal·(x - point) <= 0` (`normal` unit and outward).
    pub(crate) fn with_plane(mut self, normal: DVec3, point: DVec3) -> Shaft {
        self.planes.push((normal, point));
        self
    }

    /// True when the convex polygon `vertices` lies entirely outside the region (beyond one of
    /// its planes by more than the tolerance). False does not mean it intersects.
    pub(crate) fn excludes(&self, vertices: &[DVec3]) -> bool {
        self.planes
            .iter()
            .any(|(n, p)| vertices.iter().all(|v| n.dot(*v - *p) > self.tol))
    }

    #[cfg(test)]
    pub(crate) fn plane_count(&self) -> usize {
        self.planes.len()
    }

    /// The distance by which a polygon must be beyond a plane to be excluded (scene units).
    pub(crate) fn tolerance(&self) -> f64 {
        self.tol
    }
}

// ---------------------------------------------------------------------------------------------
// Backprojection at one point

/// Bounds on the work of one exact evaluation; past them the caller falls back to sampling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Occluders whose clipped projection has area.
    pub(crate) max_occluders: usize,
    /// Convex pieces of the visible emitter part at any time.
    pub(crate) max_pieces: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_occluders: 256,
            max_pieces: 4096,
        }
    }
}

/// The result of [`visible_form_factor`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Backprojection {
    /// Form factor of the visible part of the emitter; `None` when a limit was passed.
    pub form_factor: Option<f64>,
    /// Occluders whose clipped projection onto the emitter has area (counted up to the first
    /// one past the limit).
    pub(crate) occluders: usize,
    /// Largest number of visible pieces held.
    pub(crate) pieces: usize,
}

/// Convex polygons in the emitter's plane, stored flat, each with its bounding box.
#[derive(Clone, Debug, Default)]
struct PieceSet {
    verts: Vec<DVec2>,
    spans: Vec<Span>,
}

#[derive(Clone, Copy, Debug)]
struct Span {
    start: usize,
    len: usize,
    lo: DVec2,
    hi: DVec2,
}

impl Span {
    fn overlaps(&self, other: &Span) -> bool {
        self.lo.x <= other.hi.x
            && other.lo.x <= self.hi.x
            && self.lo.y <= other.hi.y
            && other.lo.y <= self.hi.y
    }
}

impl PieceSet {
    fn clear(&mut self) {
        self.verts.clear();
        self.spans.clear();
    }

    fn push(&mut self, v: &[DVec2]) {
        let (lo, hi) = v.iter().fold(
            (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), q| (lo.min(*q), hi.max(*q)),
        );
        self.spans.push(Span {
            start: self.verts.len(),
            len: v.len(),
            lo,
            hi,
        });
        self.verts.extend_from_slice(v);
    }

    fn get(&self, s: &Span) -> &[DVec2] {
        &self.verts[s.start..s.start + s.len]
    }
}

/// Reusable buffers of [`Scratch::visible_form_factor`]: one per thread saves the allocations
/// of every evaluation.
#[derive(Clone, Debug, Default)]
pub(crate) struct Scratch {
    pieces: PieceSet,
    next: PieceSet,
    projected: PieceSet,
    order: Vec<(f64, usize)>,
    s: Vec<f64>,
    rest: Vec<DVec2>,
    inside: Vec<DVec2>,
    outside: Vec<DVec2>,
    poly: Vec<DVec2>,
    buf_a: Vec<DVec3>,
    buf_b: Vec<DVec3>,
    planes: Vec<(DVec3, DVec3)>,
    hull_world: Vec<DVec3>,
}

/// into its parts with `s <= 0` (`outside`) and `s >= 0` (`inside`).
fn split2(poly: &[DVec2], s: &[f64], outside: &mut Vec<DVec2>, inside: &mut Vec<DVec2>) {
    outside.clear();
    inside.clear();
    let n = poly.len();
    for j in 0..n {
        let (a, b) = (poly[j], poly[(j + 1) % n]);
        let (sa, sb) = (s[j], s[(j + 1) % n]);
        if sa >= 0.0 {
            inside.push(a);
        }
        if sa <= 0.0 {
            outside.push(a);
        }
        if (sa > 0.0 && sb < 0.0) || (sa < 0.0 && sb > 0.0) {
            let x = a + (b - a) * (sa / (sa - sb));
            inside.push(x);
            outside.push(x);
        }
    }
}

/// Buffers of [`subtract`].
#[derive(Clone, Debug, Default)]
struct SubtractBuffers {
    s: Vec<f64>,
    rest: Vec<DVec2>,
    inside: Vec<DVec2>,
    outside: Vec<DVec2>,
}

/// `p \ q` for convex `p` and convex counter-clockwise `q`: the convex pieces of `p` outside `q`
/// are appended to `out` (pieces of area at most `area_tol` are dropped). `tol` is the distance
/// within which a vertex counts as on an edge's line.
fn subtract(
    p: &[DVec2],
    q: &[DVec2],
    tol: f64,
    area_tol: f64,
    out: &mut PieceSet,
    buf: &mut SubtractBuffers,
) {
    let SubtractBuffers {
        s,
        rest,
        inside,
        outside,
    } = buf;
    rest.clear();
    rest.extend_from_slice(p);
    let m = q.len();
    for i in 0..m {
        let a = q[i];
        let e = q[(i + 1) % m] - a;
        let len = e.length();
        if len <= tol {
            continue;
        }
        s.clear();
        let (mut any_out, mut any_in) = (false, false);
        for v in rest.iter() {
            let mut d = e.perp_dot(*v - a) / len;
            if d.abs() <= tol {
                d = 0.0;
            }
            any_out |= d < 0.0;
            any_in |= d > 0.0;
            s.push(d);
        }
        if !any_out {
            continue;
        }
        if !any_in {
            // Entirely outside this edge: the rest does not meet q.
            if signed_area(rest) > area_tol {
                out.push(rest);
            }
            return;
        }
        split2(rest, s, outside, inside);
        if signed_area(outside) > area_tol {
            out.push(outside);
        }
        std::mem::swap(rest, inside);
        if signed_area(rest) <= area_tol {
            return;
        }
    }
    // What is left lies inside q: hidden.
}

/// The form factor from `(p, n)` to the part of `emitter` that the polygons `occluders` leave
/// visible (exact for polygonal occluders). Occluders are convex planar polygons in world space,
/// on either side facing; the receiving and emitting surfaces themselves must not be among them.
/// See [`Scratch::visible_form_factor`], which this calls with fresh buffers.
pub fn visible_form_factor<'a>(
    p: DVec3,
    n: DVec3,
    emitter: &EmitterShape,
    occluders: impl IntoIterator<Item = &'a [DVec3]>,
    limits: &Limits,
) -> Backprojection {
    Scratch::default().visible_form_factor(p, n, emitter, occluders, limits, None)
}

impl Scratch {
    /// The form factor from `(p, n)` to the part of `emitter` that the polygons `occluders`
    /// leave visible (exact for polygonal occluders). Occluders are convex planar polygons in
    /// world space, on either side facing; the receiving and emitting surfaces themselves must
    /// not be among them.
    ///
    /// Each occluder is clipped to the open side of the emitter's plane facing `p` and to the
    /// pyramid with apex `p` over the emitter's hull (clipped to the horizon of `p`), projected
    /// through `p` onto that plane, and subtracted from the emitter's convex pieces, largest
    /// projection first. Lambert's contour formula over the remaining pieces gives the form
    /// factor. When no occluder projects with area, `unoccluded` (if given) is returned as the
    /// form factor instead of recomputing it.
    pub(crate) fn visible_form_factor<'a>(
        &mut self,
        p: DVec3,
        n: DVec3,
        emitter: &EmitterShape,
        occluders: impl IntoIterator<Item = &'a [DVec3]>,
        limits: &Limits,
        unoccluded: Option<f64>,
    ) -> Backprojection {
        let fr = &emitter.frame;
        let mut result = Backprojection {
            form_factor: Some(0.0),
            occluders: 0,
            pieces: 0,
        };
        let d_p = fr.n.dot(p - fr.origin);
        if d_p <= 0.0 || emitter.pieces.is_empty() {
            return result;
        }
        let tol = 1e-12 * emitter.size;
        let area_tol = 1e-15 * emitter.area;
        // The horizon of p in the emitter's plane: h(q) = a q.x + b q.y + c >= 0.
        let (ha, hb, hc) = (n.dot(fr.u), n.dot(fr.v), n.dot(fr.origin - p));
        let hlen = (ha * ha + hb * hb).sqrt();
        self.pieces.clear();
        let mut clipped = false;
        for piece in &emitter.pieces {
            self.s.clear();
            self.s.extend(piece.iter().map(|q| {
                let h = ha * q.x + hb * q.y + hc;
                // Snap to the horizon within the tolerance (when the line exists).
                if hlen > 0.0 && (h / hlen).abs() <= tol {
                    0.0
                } else {
                    h
                }
            }));
            if self.s.iter().all(|&h| h >= 0.0) {
                self.pieces.push(piece);
            } else if self.s.iter().any(|&h| h > 0.0) {
                split2(piece, &self.s, &mut self.outside, &mut self.inside);
                if signed_area(&self.inside) > area_tol {
                    self.pieces.push(&self.inside);
                }
                clipped = true;
            } else {
                clipped = true;
            }
        }
        if self.pieces.spans.is_empty() {
            return result;
        }
        // Side planes of the pyramid p -> hull, inward normals, after the emitter's plane
        // (first: it culls the emitter's neighbours at once).
        self.hull_world.clear();
        if clipped {
            let hull = convex_hull(&self.pieces.verts);
            self.hull_world
                .extend(hull.iter().map(|q| fr.world_from_plane(*q)));
        } else {
            self.hull_world
                .extend(emitter.hull.iter().map(|q| fr.world_from_plane(*q)));
        }
        let hw = &self.hull_world;
        let centre = hw.iter().copied().sum::<DVec3>() / hw.len().max(1) as f64;
        self.planes.clear();
        self.planes
            .push((fr.n, fr.origin + fr.n * emitter.plane_tolerance()));
        for i in 0..hw.len() {
            let m = (hw[i] - p).cross(hw[(i + 1) % hw.len()] - p);
            let len = m.length();
            if len == 0.0 {
                continue;
            }
            let m = m / len;
            self.planes
                .push((if m.dot(centre - p) < 0.0 { -m } else { m }, p));
        }

        // Clip and project every occluder.
        self.projected.clear();
        self.order.clear();
        for occ in occluders {
            if occ.len() < 3 {
                continue;
            }
            // Clip to the pyramid; planes the polygon lies inside of are skipped, and one it
            // lies outside of ends the clip.
            self.buf_a.clear();
            self.buf_a.extend_from_slice(occ);
            for (m, o) in &self.planes {
                let (mut any_in, mut any_out) = (false, false);
                for v in &self.buf_a {
                    let d = m.dot(*v - *o);
                    any_in |= d > 0.0;
                    any_out |= d < 0.0;
                }
                if !any_in {
                    self.buf_a.clear();
                    break;
                }
                if any_out {
                    clip_polygon_to_plane(&self.buf_a, *m, *o, &mut self.buf_b);
                    std::mem::swap(&mut self.buf_a, &mut self.buf_b);
                    if self.buf_a.len() < 3 {
                        break;
                    }
                }
            }
            if self.buf_a.len() < 3 {
                continue;
            }
            // An occluder whose plane passes through p projects to a segment.
            let mut normal = DVec3::ZERO;
            for i in 0..occ.len() {
                normal += occ[i].cross(occ[(i + 1) % occ.len()]);
            }
            let nl = normal.length();
            let reach = occ.iter().map(|v| v.distance(p)).fold(0.0, f64::max);
            if nl == 0.0 || (normal.dot(p - occ[0]) / nl).abs() <= 1e-12 * reach {
                continue;
            }
            self.poly.clear();
            let mut ok = true;
            for x in &self.buf_a {
                let denom = fr.n.dot(p - *x);
                if denom <= 1e-15 * d_p {
                    ok = false;
                    break;
                }
                let y = (p - fr.origin) + (*x - p) * (d_p / denom);
                self.poly.push(DVec2::new(y.dot(fr.u), y.dot(fr.v)));
            }
            if !ok {
                continue;
            }
            let mut area = signed_area(&self.poly);
            if area < 0.0 {
                self.poly.reverse();
                area = -area;
            }
            if area <= area_tol {
                continue;
            }
            result.occluders += 1;
            if result.occluders > limits.max_occluders {
                result.form_factor = None;
                return result;
            }
            self.order.push((area, self.projected.spans.len()));
            self.projected.push(&self.poly);
        }
        result.pieces = self.pieces.spans.len();
        if result.occluders == 0
            && let Some(f) = unoccluded
        {
            result.form_factor = Some(f);
            return result;
        }
        // Largest first: big occluders remove most of the emitter before small ones fragment
        // it.
        self.order
            .sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let mut buf = SubtractBuffers {
            s: std::mem::take(&mut self.s),
            rest: std::mem::take(&mut self.rest),
            inside: std::mem::take(&mut self.inside),
            outside: std::mem::take(&mut self.outside),
        };
        for &(_, k) in &self.order {
            let qs = self.projected.spans[k];
            let q = self.projected.get(&qs);
            self.next.clear();
            for ps in &self.pieces.spans {
                let piece = self.pieces.get(ps);
                if ps.overlaps(&qs) {
                    subtract(piece, q, tol, area_tol, &mut self.next, &mut buf);
                } else {
                    self.next.push(piece);
                }
            }
            std::mem::swap(&mut self.pieces, &mut self.next);
            result.pieces = result.pieces.max(self.pieces.spans.len());
            if self.pieces.spans.len() > limits.max_pieces {
                result.form_factor = None;
                break;
            }
            if self.pieces.spans.is_empty() {
                break;
            }
        }
        self.s = buf.s;
        self.rest = buf.rest;
        self.inside = buf.inside;
        self.outside = buf.outside;
        if result.form_factor.is_none() {
            return result;
        }
        let mut sum = 0.0;
        for ps in &self.pieces.spans {
            self.buf_a.clear();
            self.buf_a
                .extend(self.pieces.get(ps).iter().map(|q| fr.world_from_plane(*q)));
            sum += contour_sum(p, n, &self.buf_a);
        }
        result.form_factor = Some(sum.abs() / (2.0 * std::f64::consts::PI));
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::point_polygon_form_factor;

    #[test]
    fn subtracting_keeps_the_area_outside() {
        let sq = |x0: f64, y0: f64, s: f64| {
            vec![
                DVec2::new(x0, y0),
                DVec2::new(x0 + s, y0),
                DVec2::new(x0 + s, y0 + s),
                DVec2::new(x0, y0 + s),
            ]
        };
        let mut buf = SubtractBuffers::default();
        let mut out = PieceSet::default();
        let sub = |a: &[DVec2], b: &[DVec2], out: &mut PieceSet, buf: &mut SubtractBuffers| {
            out.clear();
            subtract(a, b, 1e-12, 0.0, out, buf);
        };
        sub(&sq(0.0, 0.0, 2.0), &sq(0.5, 0.5, 1.0), &mut out, &mut buf);
        let area: f64 = out.spans.iter().map(|p| signed_area(out.get(p))).sum();
        assert!((area - 3.0).abs() < 1e-12, "{area}");
        assert_eq!(out.spans.len(), 4);
        sub(&sq(0.0, 0.0, 1.0), &sq(-1.0, -1.0, 3.0), &mut out, &mut buf);
        assert!(out.spans.is_empty());
        sub(&sq(0.0, 0.0, 1.0), &sq(2.0, 0.0, 1.0), &mut out, &mut buf);
        assert_eq!(out.spans.len(), 1);
    }

    #[test]
    fn without_occluders_it_is_the_unoccluded_form_factor() {
        let corners = [
            DVec3::new(-0.5, 2.0, -0.5),
            DVec3::new(0.5, 2.0, -0.5),
            DVec3::new(0.5, 2.0, 0.5),
            DVec3::new(-0.5, 2.0, 0.5),
        ];
        // Counter-clockwise seen from below (the emitting side).
        let down: Vec<DVec3> = corners.to_vec();
        let e = EmitterShape::convex(&down);
        assert!(e.frame.n.y < 0.0);
        for (p, n) in [
            (DVec3::ZERO, DVec3::Y),
            (DVec3::new(1.0, 0.0, 0.3), DVec3::Y),
            (DVec3::new(1.0, 0.5, 0.3), DVec3::new(-1.0, 0.0, 0.0)),
        ] {
            let r = visible_form_factor(p, n, &e, std::iter::empty(), &Limits::default());
            let f = point_polygon_form_factor(p, n, &down);
            assert!((r.form_factor.unwrap() - f).abs() < 1e-15, "{r:?} vs {f}");
        }
    }

    #[test]
    fn square_occluder_profile() {
        // The known square-occluder case: source [-0.5,0.5]^2 at height 2, occluder the same at height 1.
        let src: Vec<DVec3> = [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)]
            .iter()
            .map(|&(x, z)| DVec3::new(x, 2.0, z))
            .collect();
        let e = EmitterShape::convex(&src);
        assert!(e.frame.n.y < 0.0);
        let occ: Vec<DVec3> = src.iter().map(|v| DVec3::new(v.x, 1.0, v.z)).collect();
        for (x, f) in [
            (0.0, 0.0),
            (0.5, 0.0),
            (0.6, 0.007557182),
            (1.0, 0.029443796),
            (1.5, 0.032663266),
            (3.0, 0.007739699),
        ] {
            let r = visible_form_factor(
                DVec3::new(x, 0.0, 0.0),
                DVec3::Y,
                &e,
                [occ.as_slice()],
                &Limits::default(),
            );
            let got = r.form_factor.unwrap();
            assert!((got - f).abs() < 1e-9, "x = {x}: {got} vs {f}");
        }
    }

    #[test]
    fn shaft_of_a_cube_culls_outside() {
        let pts: Vec<DVec3> = (0..8)
            .map(|i| DVec3::new((i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64))
            .collect();
        let s = Shaft::hull(&pts);
        assert_eq!(s.plane_count(), 6);
        let tri = |o: DVec3| vec![o, o + DVec3::X * 0.1, o + DVec3::Y * 0.1];
        assert!(s.excludes(&tri(DVec3::new(2.0, 0.5, 0.5))));
        assert!(!s.excludes(&tri(DVec3::new(0.5, 0.5, 0.5))));
        assert!(!s.excludes(&tri(DVec3::new(0.95, 0.5, 0.5))));
    }
}
