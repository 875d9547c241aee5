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

use crate::scene::{Frame, Scene};
use crate::solve::point_polygon_form_factor;
use glam::{DVec2, DVec3};
use std::collections::BTreeMap;

// ---------------------------------------------------------------------------------------------
// Convex decomposition

/// Merges a triangulated planar polygon into convex pieces (Hertel-Mehlhorn): two pieces that
/// share a whole edge are merged when their union is convex; shared edges are visited in a fixed
/// order, so the result is deterministic.
///
/// `tris` are the triangles in plane coordinates; corners are matched by their exact
/// coordinates. Returns each piece as a counter-clockwise list of corner references `3 t + k`
/// (corner `k` of triangle `t`), and the piece each triangle went into (`usize::MAX` for a
/// degenerate triangle, which is left out). Vertices where a piece's boundary runs straight on
/// are removed.
pub fn convex_pieces(tris: &[[DVec2; 3]]) -> (Vec<Vec<usize>>, Vec<usize>) {
    // -0.0 and 0.0 are the same point.
    let key = |q: DVec2| [(q.x + 0.0).to_bits(), (q.y + 0.0).to_bits()];
    let corner = |c: usize| tris[c / 3][c % 3];
    let mut pieces: Vec<Vec<usize>> = tris
        .iter()
        .enumerate()
        .map(|(t, tri)| {
            let area2 = (tri[1] - tri[0]).perp_dot(tri[2] - tri[0]);
            if area2 > 0.0 {
                vec![3 * t, 3 * t + 1, 3 * t + 2]
            } else if area2 < 0.0 {
                vec![3 * t, 3 * t + 2, 3 * t + 1]
            } else {
                Vec::new()
            }
        })
        .collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    // Piece slots are indexed like the triangles; a merged piece lives in one slot and the
    // union-find sends the others there. Passes repeat until nothing merges: after a pass,
    // straight-on vertices are dropped, so strips of a grid then share whole edges.
    let mut parent: Vec<usize> = (0..pieces.len()).collect();
    loop {
        let mut edges: BTreeMap<([u64; 2], [u64; 2]), Vec<usize>> = BTreeMap::new();
        for (t, piece) in pieces.iter().enumerate() {
            for i in 0..piece.len() {
                let (a, b) = (
                    key(corner(piece[i])),
                    key(corner(piece[(i + 1) % piece.len()])),
                );
                if a != b {
                    edges.entry((a.min(b), a.max(b))).or_default().push(t);
                }
            }
        }
        let mut merged_any = false;
        for ((ka, kb), owners) in &edges {
            if owners.len() != 2 {
                continue;
            }
            let (i, j) = (find(&mut parent, owners[0]), find(&mut parent, owners[1]));
            if i == j {
                continue;
            }
            if let Some(merged) = merge_convex(&pieces[i], &pieces[j], *ka, *kb, &key, &corner) {
                pieces[i] = merged;
                pieces[j].clear();
                parent[j] = i;
                merged_any = true;
            }
        }
        for p in &mut pieces {
            if !p.is_empty() {
                *p = drop_straight_vertices(std::mem::take(p), &corner);
                if p.len() < 3 {
                    p.clear();
                }
            }
        }
        if !merged_any {
            break;
        }
    }
    let mut index = vec![usize::MAX; pieces.len()];
    let mut out = Vec::new();
    for (i, p) in pieces.into_iter().enumerate() {
        if p.len() >= 3 {
            index[i] = out.len();
            out.push(p);
        }
    }
    let owner = (0..tris.len())
        .map(|t| {
            let root = find(&mut parent, t);
            index[root]
        })
        .collect();
    (out, owner)
}

/// The union of two counter-clockwise convex pieces sharing the edge `{ka, kb}`, if convex.
fn merge_convex(
    p: &[usize],
    q: &[usize],
    ka: [u64; 2],
    kb: [u64; 2],
    key: &dyn Fn(DVec2) -> [u64; 2],
    corner: &dyn Fn(usize) -> DVec2,
) -> Option<Vec<usize>> {
    let (np, nq) = (p.len(), q.len());
    // In p the edge runs x -> y; in q it runs y -> x.
    let s = (0..np).find(|&s| {
        let (a, b) = (key(corner(p[s])), key(corner(p[(s + 1) % np])));
        (a == ka && b == kb) || (a == kb && b == ka)
    })?;
    let (x, y) = (key(corner(p[s])), key(corner(p[(s + 1) % np])));
    let r = (0..nq).find(|&r| key(corner(q[r])) == y && key(corner(q[(r + 1) % nq])) == x)?;
    let convex_at = |prev: DVec2, at: DVec2, next: DVec2| {
        let (e1, e2) = (at - prev, next - at);
        e1.perp_dot(e2) >= -1e-12 * e1.length() * e2.length()
    };
    let (px, py) = (corner(p[s]), corner(p[(s + 1) % np]));
    if !convex_at(corner(p[(s + np - 1) % np]), px, corner(q[(r + 2) % nq]))
        || !convex_at(corner(q[(r + nq - 1) % nq]), py, corner(p[(s + 2) % np]))
    {
        return None;
    }
    let mut merged = Vec::with_capacity(np + nq - 2);
    merged.extend((0..np).map(|k| p[(s + 1 + k) % np]));
    merged.extend((0..nq - 2).map(|k| q[(r + 2 + k) % nq]));
    Some(merged)
}

/// Removes vertices where the boundary goes straight on (or doubles back onto itself).
fn drop_straight_vertices(mut p: Vec<usize>, corner: &dyn Fn(usize) -> DVec2) -> Vec<usize> {
    let mut k = 0;
    while p.len() >= 3 && k < p.len() {
        let n = p.len();
        let (a, b, c) = (
            corner(p[(k + n - 1) % n]),
            corner(p[k]),
            corner(p[(k + 1) % n]),
        );
        let (e1, e2) = (b - a, c - b);
        if b == a || e1.perp_dot(e2).abs() <= 1e-12 * e1.length() * e2.length() {
            p.remove(k);
            k = k.saturating_sub(1);
        } else {
            k += 1;
        }
    }
    p
}

/// Convex hull of 2D points, counter-clockwise, without collinear points (Andrew's monotone
/// chain). Fewer than three points (or all collinear) give what is left of the chain.
pub fn convex_hull(points: &[DVec2]) -> Vec<DVec2> {
    let mut pts = points.to_vec();
    pts.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    // Lower chain left to right, then upper chain right to left.
    let chain = |iter: &mut dyn Iterator<Item = DVec2>| {
        let mut c: Vec<DVec2> = Vec::new();
        for q in iter {
            while c.len() >= 2 && cross(c[c.len() - 2], c[c.len() - 1], q) <= 0.0 {
                c.pop();
            }
            c.push(q);
        }
        c.pop();
        c
    };
    let mut hull = chain(&mut pts.iter().copied());
    hull.extend(chain(&mut pts.iter().rev().copied()));
    hull
}

fn signed_area(poly: &[DVec2]) -> f64 {
    if poly.len() < 3 {
        return 0.0;
    }
    let o = poly[0];
    let mut a = 0.0;
    for i in 1..poly.len() - 1 {
        a += (poly[i] - o).perp_dot(poly[i + 1] - o);
    }
    0.5 * a
}

// ---------------------------------------------------------------------------------------------
// Emitters and occluders

/// A planar area emitter prepared for backprojection: its convex pieces in its own plane frame.
#[derive(Clone, Debug)]
pub struct EmitterShape {
    /// The emitter's plane; `frame.n` is the emitting (front) side.
    pub frame: Frame,
    /// Convex pieces, counter-clockwise in `frame` coordinates (seen from the front).
    pub pieces: Vec<Vec<DVec2>>,
    /// The pieces in world space.
    pub pieces_world: Vec<Vec<DVec3>>,
    /// Convex hull of all pieces, counter-clockwise.
    pub hull: Vec<DVec2>,
    /// Area, scene units².
    pub area: f64,
    /// Diameter of the hull's bounding box: the length scale of the emitter's tolerances.
    pub size: f64,
}

impl EmitterShape {
    /// From the triangles of a planar polygon, in the plane coordinates of `frame`.
    pub fn new(frame: Frame, triangles_plane: &[[DVec2; 3]]) -> EmitterShape {
        let pieces: Vec<Vec<DVec2>> = convex_pieces(triangles_plane)
            .0
            .into_iter()
            .map(|p| {
                p.into_iter()
                    .map(|c| triangles_plane[c / 3][c % 3])
                    .collect()
            })
            .collect();
        let all: Vec<DVec2> = pieces.iter().flatten().copied().collect();
        let hull = convex_hull(&all);
        let (lo, hi) = all.iter().fold(
            (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), q| (lo.min(*q), hi.max(*q)),
        );
        EmitterShape {
            frame,
            area: pieces.iter().map(|p| signed_area(p)).sum(),
            pieces_world: pieces
                .iter()
                .map(|p| p.iter().map(|q| frame.world_from_plane(*q)).collect())
                .collect(),
            pieces,
            hull,
            size: if all.is_empty() {
                0.0
            } else {
                (hi - lo).length()
            },
        }
    }

    /// A convex polygon given by its world-space corners, counter-clockwise seen from the side
    /// it emits to.
    pub fn convex(corners: &[DVec3]) -> EmitterShape {
        // Newell's normal: the winding's area vector.
        let mut normal = DVec3::ZERO;
        for i in 0..corners.len() {
            normal += corners[i].cross(corners[(i + 1) % corners.len()]);
        }
        let frame = Frame::new(corners[0], normal, corners[1] - corners[0]);
        let q: Vec<DVec2> = corners.iter().map(|c| frame.plane_from_world(*c)).collect();
        let tris: Vec<[DVec2; 3]> = (1..q.len() - 1).map(|i| [q[0], q[i], q[i + 1]]).collect();
        EmitterShape::new(frame, &tris)
    }

    /// Occluders no farther than this in front of the emitter's plane (scene units) are taken
    /// to lie in it, and never block it.
    pub fn plane_tolerance(&self) -> f64 {
        1e-9 * self.size
    }

    /// The hull's corners in world space.
    pub fn hull_world(&self) -> Vec<DVec3> {
        self.hull
            .iter()
            .map(|q| self.frame.world_from_plane(*q))
            .collect()
    }

    /// Unoccluded form factor from `(p, n)` to the emitter's front face (Lambert's contour
    /// formula over the pieces, clipped to the horizon of `p`).
    pub fn form_factor(&self, p: DVec3, n: DVec3) -> f64 {
        if self.frame.n.dot(p - self.frame.origin) <= 0.0 {
            return 0.0;
        }
        self.pieces_world
            .iter()
            .map(|piece| {
                // Entirely above the horizon: the contour sum as is, without the clipping's
                // copy (the same value as `point_polygon_form_factor`).
                let (mut reach, mut height, mut below) = (0.0f64, 0.0f64, false);
                for v in piece {
                    let h = n.dot(*v - p);
                    below |= h < 0.0;
                    height = height.max(h);
                    reach = reach.max((*v - p).length());
                }
                if below {
                    point_polygon_form_factor(p, n, piece)
                } else if height <= 1e-9 * reach {
                    0.0
                } else {
                    contour_sum(p, n, piece).abs() / (2.0 * std::f64::consts::PI)
                }
            })
            .sum()
    }
}

/// One convex piece of a scene polygon, as an occluder.
#[derive(Clone, Debug)]
pub struct OccluderPiece {
    /// Index into [`Scene::polygons`].
    pub polygon: usize,
    /// Corners in world space (the scene's own triangle corners), convex, planar.
    pub vertices: Vec<DVec3>,
}

/// Every polygon of a scene cut into convex pieces, for backprojection.
#[derive(Clone, Debug, Default)]
pub struct Occluders {
    pub pieces: Vec<OccluderPiece>,
    /// The piece each scene triangle belongs to (`u32::MAX`: none, a degenerate triangle).
    pub piece_of_triangle: Vec<u32>,
}

impl Occluders {
    pub fn new(scene: &Scene) -> Occluders {
        let mut pieces = Vec::new();
        let mut piece_of_triangle = vec![u32::MAX; scene.triangles.len()];
        for (id, poly) in scene.polygons.iter().enumerate() {
            let first = pieces.len() as u32;
            let (convex, owner) = convex_pieces(&poly.triangles_plane);
            for piece in convex {
                let vertices = piece
                    .iter()
                    .map(|&c| scene.triangles[poly.triangles[c / 3]].p[c % 3])
                    .collect();
                pieces.push(OccluderPiece {
                    polygon: id,
                    vertices,
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
pub struct Shaft {
    /// Outward unit normal and a point of each bounding plane.
    planes: Vec<(DVec3, DVec3)>,
    tol: f64,
}

impl Shaft {
    /// The face planes of the convex hull of `points` (brute force over point triples: for a
    /// dozen points or so). A degenerate set gives fewer planes, so a larger region.
    pub fn hull(points: &[DVec3]) -> Shaft {
        let c = points.iter().copied().sum::<DVec3>() / points.len().max(1) as f64;
        let scale = points.iter().map(|q| q.distance(c)).fold(0.0, f64::max);
        let tol = 1e-9 * scale;
        let mut planes: Vec<(DVec3, DVec3)> = Vec::new();
        let m = points.len();
        for i in 0..m {
            for j in i + 1..m {
                for k in j + 1..m {
                    let nrm = (points[j] - points[i]).cross(points[k] - points[i]);
                    let len = nrm.length();
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
    pub fn with_plane(mut self, normal: DVec3, point: DVec3) -> Shaft {
        self.planes.push((normal, point));
        self
    }

    /// True when the convex polygon `vertices` lies entirely outside the region (beyond one of
    /// its planes by more than the tolerance). False does not mean it intersects.
    pub fn excludes(&self, vertices: &[DVec3]) -> bool {
        self.planes
            .iter()
            .any(|(n, p)| vertices.iter().all(|v| n.dot(*v - *p) > self.tol))
    }

    pub fn plane_count(&self) -> usize {
        self.planes.len()
    }

    /// The distance by which a polygon must be beyond a plane to be excluded (scene units).
    pub fn tolerance(&self) -> f64 {
        self.tol
    }
}

// ---------------------------------------------------------------------------------------------
// Backprojection at one point

/// Bounds on the work of one exact evaluation; past them the caller falls back to sampling.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Occluders whose clipped projection has area.
    pub max_occluders: usize,
    /// Convex pieces of the visible emitter part at any time.
    pub max_pieces: usize,
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
    pub occluders: usize,
    /// Largest number of visible pieces held.
    pub pieces: usize,
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
pub struct Scratch {
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

/// Clips a 3D polygon to `n·(x - o) >= 0` (Sutherland-Hodgman).
fn clip3(poly: &[DVec3], n: DVec3, o: DVec3, out: &mut Vec<DVec3>) {
    out.clear();
    let len = poly.len();
    for i in 0..len {
        let (a, b) = (poly[i], poly[(i + 1) % len]);
        let (da, db) = (n.dot(a - o), n.dot(b - o));
        if da >= 0.0 {
            out.push(a);
        }
        if (da > 0.0 && db < 0.0) || (da < 0.0 && db > 0.0) {
            out.push(a + (b - a) * (da / (da - db)));
        }
    }
}

/// Splits convex `poly` by the signed distances `s` (already snapped to 0 within tolerance)
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

/// Lambert's contour sum `sum_i gamma_i n·unit(r_i x r_(i+1))` of a polygon above the horizon
/// of `p` (no clipping), signed by its winding; `F` is its absolute value over `2 pi`.
fn contour_sum(p: DVec3, n: DVec3, poly: &[DVec3]) -> f64 {
    let mut sum = 0.0;
    for i in 0..poly.len() {
        let a = poly[i] - p;
        let b = poly[(i + 1) % poly.len()] - p;
        let c = a.cross(b);
        let cl = c.length();
        if cl <= 0.0 {
            continue;
        }
        // atan2 keeps the angle accurate for tiny and near-straight angles.
        sum += cl.atan2(a.dot(b)) * n.dot(c) / cl;
    }
    sum
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
    pub fn visible_form_factor<'a>(
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
                    clip3(&self.buf_a, *m, *o, &mut self.buf_b);
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

    fn square_tris(n: usize) -> Vec<[DVec2; 3]> {
        // An n x n grid of the unit square, two triangles per cell.
        let mut out = Vec::new();
        let h = 1.0 / n as f64;
        for i in 0..n {
            for j in 0..n {
                let a = DVec2::new(i as f64 * h, j as f64 * h);
                let b = a + DVec2::new(h, 0.0);
                let c = a + DVec2::new(h, h);
                let d = a + DVec2::new(0.0, h);
                out.push([a, b, c]);
                out.push([a, c, d]);
            }
        }
        out
    }

    #[test]
    fn tessellated_square_merges_into_one_piece() {
        let tris = square_tris(8);
        let (pieces, owner) = convex_pieces(&tris);
        assert!(owner.iter().all(|&k| k < pieces.len()));
        assert_eq!(pieces.len(), 1, "{pieces:?}");
        let q: Vec<DVec2> = pieces[0].iter().map(|&c| tris[c / 3][c % 3]).collect();
        assert_eq!(q.len(), 4);
        assert!((signed_area(&q) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn l_shape_gives_convex_pieces_covering_it() {
        // An L of three unit squares.
        let mut tris = Vec::new();
        for (x, y) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)] {
            let a = DVec2::new(x, y);
            tris.push([a, a + DVec2::X, a + DVec2::ONE]);
            tris.push([a, a + DVec2::ONE, a + DVec2::Y]);
        }
        let (pieces, owner) = convex_pieces(&tris);
        assert!(owner.iter().all(|&k| k < pieces.len()));
        assert!(pieces.len() == 2, "{pieces:?}");
        let mut total = 0.0;
        for p in &pieces {
            let q: Vec<DVec2> = p.iter().map(|&c| tris[c / 3][c % 3]).collect();
            for i in 0..q.len() {
                let (a, b, c) = (q[i], q[(i + 1) % q.len()], q[(i + 2) % q.len()]);
                assert!((b - a).perp_dot(c - b) > 0.0, "not strictly convex: {q:?}");
            }
            total += signed_area(&q);
        }
        assert!((total - 3.0).abs() < 1e-12);
    }

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
        // ../shared/reference: source [-0.5,0.5]^2 at height 2, occluder the same at height 1.
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
