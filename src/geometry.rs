//! Shared geometry: form factors by the contour integral, polygon clipping, convex pieces,
//! areas, barycentric coordinates, and a bucket grid of 2D boxes.
//!
//! Depends on nothing else in the crate (glam and std only). Everything is f64; lengths in
//! scene units, areas in scene units², form factors dimensionless. Polygons are corner lists,
//! closed implicitly (the last corner joins the first).

use glam::{DVec2, DVec3};
use std::collections::BTreeMap;
use std::f64::consts::PI;

// ---------------------------------------------------------------------------------------------
// Form factors

/// Form factor from a differential area at `p` with unit normal `n` to a planar polygon, by
/// Lambert's contour formula (Lambert, "Photometria", 1760; as used for radiosity by Baum,
/// Rushmeier, Winget, "Improving radiosity solutions through the use of analytically determined
/// form-factors", SIGGRAPH 1989):
///
/// ```text
/// F = 1/(2 pi) |sum_i gamma_i n·unit(r_i x r_(i+1))|
/// ```
///
/// after clipping the polygon to the horizon of `p` ([`clip_to_horizon`]). Unoccluded; either
/// winding. Dimensionless. A polygon entirely above the horizon is summed as it is, without the
/// clipping's copy (the same value).
pub fn point_polygon_form_factor(p: DVec3, n: DVec3, poly: &[DVec3]) -> f64 {
    // A NaN corner goes through the clipping too, which drops it.
    let below = |v: &DVec3| {
        let h = n.dot(*v - p);
        h < 0.0 || h.is_nan()
    };
    if poly.iter().any(below) {
        contour_form_factor(p, n, &clip_to_horizon(poly, p, n))
    } else {
        contour_form_factor(p, n, poly)
    }
}

/// `∫ ω dω` over the solid angle of the part of polygon `poly` above the horizon of `(p, n)`
/// (steradians, a vector): the vector form of Lambert's contour formula, `1/2 sum_i gamma_i
/// unit(r_i x r_(i+1))` (Arvo, "Applications of irradiance tensors to the simulation of
/// non-Lambertian phenomena", SIGGRAPH 1995), signed so that its component along `n` is
/// `pi F` ([`point_polygon_form_factor`]). Either winding; zero when nothing is above the
/// horizon.
pub(crate) fn polygon_light_vector(p: DVec3, n: DVec3, poly: &[DVec3]) -> DVec3 {
    let clipped = clip_to_horizon(poly, p, n);
    if clipped.len() < 3 {
        return DVec3::ZERO;
    }
    let v: DVec3 = (0..clipped.len())
        .map(|i| {
            let (a, b) = (clipped[i] - p, clipped[(i + 1) % clipped.len()] - p);
            let c = a.cross(b);
            let cl = c.length();
            if cl <= 0.0 {
                DVec3::ZERO
            } else {
                c * (angle(cl, a.dot(b)) / cl)
            }
        })
        .sum::<DVec3>()
        * 0.5;
    if n.dot(v) < 0.0 { -v } else { v }
}

/// [`point_polygon_form_factor`] of a polygon already clipped to the horizon of `p`.
fn contour_form_factor(p: DVec3, n: DVec3, clipped: &[DVec3]) -> f64 {
    if clipped.len() < 3 {
        return 0.0;
    }
    // A polygon in the tangent plane (coplanar with the receiver, up to rounding) subtends no
    // projected solid angle; its contour terms would only add rounding noise.
    let reach = clipped
        .iter()
        .map(|v| (*v - p).length())
        .fold(0.0, f64::max);
    let height = clipped.iter().map(|v| n.dot(*v - p)).fold(0.0, f64::max);
    if height <= 1e-9 * reach {
        return 0.0;
    }
    contour_sum(p, n, clipped).abs() / (2.0 * PI)
}

/// Lambert's contour sum `sum_i gamma_i n·unit(r_i x r_(i+1))` of a polygon above the horizon
/// of `p` (no clipping), with `r_i` the corners relative to `p` and `gamma_i` the angle between
/// `r_i` and `r_(i+1)`, in radians; signed by the winding. The form factor is its absolute value
/// over `2 pi` (see [`point_polygon_form_factor`]). Edges through `p` contribute nothing.
pub(crate) fn contour_sum(p: DVec3, n: DVec3, poly: &[DVec3]) -> f64 {
    (0..poly.len())
        .map(|i| contour_term(p, n, poly[i], poly[(i + 1) % poly.len()]))
        .sum()
}

/// One edge's term of [`contour_sum`]: `gamma n · normalize(r_a x r_b)` for the directed edge
/// `a -> b` seen from `p`; 0 for an edge through `p`.
pub(crate) fn contour_term(p: DVec3, n: DVec3, a: DVec3, b: DVec3) -> f64 {
    let (a, b) = (a - p, b - p);
    let c = a.cross(b);
    let cl = c.length();
    if cl <= 0.0 {
        return 0.0;
    }
    // The angle from its sine and cosine keeps it accurate for tiny and near-straight angles.
    angle(cl, a.dot(b)) * n.dot(c) / cl
}

/// `y.atan2(x)` for `y >= 0` (an angle in `[0, pi]`, radians), within 3e-16 relative of it and
/// about 1.7x faster than libm's: the contour sum's one transcendental, which dominated the
/// hierarchical solver's link estimation. Cephes' `atan` (S. L. Moshier, "Methods and
/// Programs for Mathematical Functions", 1989): reduction to `|t| <= 0.66` about 0, pi/4 or
/// pi/2, then a (4, 5) rational approximation in `t²`.
fn angle(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};
    // tan(3 pi / 8), and the part of pi/2 that f64's FRAC_PI_2 leaves out.
    const T3P8: f64 = 2.414_213_562_373_095;
    const MOREBITS: f64 = 6.123_233_995_736_766e-17;
    let atan = |t: f64| {
        let (base, t, more) = if t > T3P8 {
            (FRAC_PI_2, -1.0 / t, MOREBITS)
        } else if t <= 0.66 {
            (0.0, t, 0.0)
        } else {
            (FRAC_PI_4, (t - 1.0) / (t + 1.0), 0.5 * MOREBITS)
        };
        let z = t * t;
        let p = (((-8.750_608_600_031_904e-1 * z - 1.615_753_718_733_365e1) * z
            - 7.500_855_792_314_705e1)
            * z
            - 1.228_866_684_490_136e2)
            * z
            - 6.485_021_904_942_025e1;
        let q = ((((z + 2.485_846_490_142_306e1) * z + 1.650_270_098_316_988_5e2) * z
            + 4.328_810_604_912_903e2)
            * z
            + 4.853_903_996_359_137e2)
            * z
            + 1.945_506_571_482_614e2;
        base + (t * (z * p / q) + t + more)
    };
    if x > 0.0 {
        atan(y / x)
    } else if x < 0.0 {
        std::f64::consts::PI - atan(y / -x)
    } else {
        // Zero (pi/2), or NaN.
        y.atan2(x)
    }
}

// ---------------------------------------------------------------------------------------------
// Clipping

/// Clips a polygon to the horizon of a point: the closed half-space `n·(x - p) >= 0`
/// (Sutherland-Hodgman, as [`clip_polygon_to_plane`]). Unlike that one, an edge with one end
/// exactly on the plane also yields an intersection point, at (or within rounding of) that end:
/// the contour sum gives such a repeated corner a zero or rounding-size term. The form factors
/// of the solve depend on these exact values, so this variant is kept as it is.
pub(crate) fn clip_to_horizon(poly: &[DVec3], p: DVec3, n: DVec3) -> Vec<DVec3> {
    let mut out = Vec::with_capacity(poly.len() + 2);
    for i in 0..poly.len() {
        let a = poly[i];
        let b = poly[(i + 1) % poly.len()];
        let da = n.dot(a - p);
        let db = n.dot(b - p);
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            let t = da / (da - db);
            out.push(a + (b - a) * t);
        }
    }
    out
}

/// Clips a 3D polygon to the closed half-space `n·(x - o) >= 0` into `out` (cleared first): one
/// stage of Sutherland and Hodgman, "Reentrant polygon clipping", CACM 1974. An edge gets an
/// intersection point only when its ends lie strictly on opposite sides, so a corner on the
/// plane is kept once and never doubled. Convex in, convex out; `n` need not be unit.
pub(crate) fn clip_polygon_to_plane(poly: &[DVec3], n: DVec3, o: DVec3, out: &mut Vec<DVec3>) {
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

// ---------------------------------------------------------------------------------------------
// Convex decomposition and areas
/// Merges a triangulated planar polygon into convex pieces (Hertel-Mehlhorn): two pieces that
/// share a whole edge are merged when their union is convex; shared edges are visited in a fixed
/// order, so the result is deterministic.
///
/// `tris` are the triangles in plane coordinates; corners are matched by their exact
/// coordinates. Returns each piece as a counter-clockwise list of corner references `3 t + k`
/// (corner `k` of triangle `t`), and the piece each triangle went into (`usize::MAX` for a
/// degenerate triangle, which is left out). Vertices where a piece's boundary runs straight on
/// are removed.
pub(crate) fn convex_pieces(tris: &[[DVec2; 3]]) -> (Vec<Vec<usize>>, Vec<usize>) {
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

/// The midpoint of the longest edge of the triangle `t` (ties: the first edge).
pub(crate) fn longest_edge_midpoint(t: &[DVec2; 3]) -> DVec2 {
    let e = (0..3)
        .max_by(|&i, &j| {
            let li = t[i].distance_squared(t[(i + 1) % 3]);
            let lj = t[j].distance_squared(t[(j + 1) % 3]);
            li.total_cmp(&lj).then(j.cmp(&i))
        })
        .unwrap_or(0);
    (t[e] + t[(e + 1) % 3]) * 0.5
}

/// The angles of the triangle `p` under `limit` (radians): the smallest of those that
/// `forced(k, a, b)` does not excuse (the angle at corner `k`, between the edges to `a` and
/// `b`, as offsets from the corner), and whether any it excuses.
pub(crate) fn small_angles_of(
    p: &[DVec2; 3],
    limit: f64,
    mut forced: impl FnMut(usize, DVec2, DVec2) -> bool,
) -> (Option<f64>, bool) {
    let (mut sharpest, mut excused) = (None::<f64>, false);
    for k in 0..3 {
        let (v, a, b) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
        let angle = (a - v).angle_to(b - v).abs();
        if angle >= limit {
            continue;
        }
        if forced(k, a - v, b - v) {
            excused = true;
        } else {
            sharpest = Some(sharpest.map_or(angle, |s| s.min(angle)));
        }
    }
    (sharpest, excused)
}

/// Whether the wedge from `a` to `b` (at a vertex) lies inside a corner between two of the
/// constraint directions `dirs` (radians) that are less than `limit` apart.
pub(crate) fn inside_narrow_corner(dirs: &[f64], a: DVec2, b: DVec2, limit: f64) -> bool {
    if dirs.len() < 2 {
        return false;
    }
    use std::f64::consts::TAU;
    // The wedge's bisector, and the constraints next to it on either side.
    let (ta, tb) = (a.y.atan2(a.x), b.y.atan2(b.x));
    let mut span = (tb - ta).rem_euclid(TAU);
    let (start, mut width) = if span <= std::f64::consts::PI {
        (ta, span)
    } else {
        span = TAU - span;
        (tb, span)
    };
    width = width.max(0.0);
    let mid = start + width / 2.0;
    let ccw = dirs
        .iter()
        .map(|d| (d - mid).rem_euclid(TAU))
        .fold(TAU, f64::min);
    let cw = dirs
        .iter()
        .map(|d| (mid - d).rem_euclid(TAU))
        .fold(TAU, f64::min);
    ccw + cw < limit + 1e-9
}

/// Signed area of a 2D polygon (scene units²): positive when counter-clockwise. A fan from the
/// first corner (the shoelace formula); fewer than three corners give 0.
pub(crate) fn signed_area(poly: &[DVec2]) -> f64 {
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

/// Area of a 3D triangle, scene units².
pub(crate) fn triangle_area(p: &[DVec3; 3]) -> f64 {
    0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
}

// ---------------------------------------------------------------------------------------------
// Barycentric coordinates

/// The six faces of a box as quads of [`box_corners`] indices (corner `c` has x from bit 0,
/// y from bit 1, z from bit 2), counter-clockwise seen from outside: z = 0, z = 1, y = 0,
/// y = 1, x = 0, x = 1.
#[cfg(test)]
pub(crate) const BOX_FACES: [[u32; 4]; 6] = [
    [0, 2, 3, 1],
    [4, 5, 7, 6],
    [0, 1, 5, 4],
    [2, 6, 7, 3],
    [0, 4, 6, 2],
    [1, 3, 7, 5],
];

/// The eight corners of the axis-aligned box `[min, max]`.
pub(crate) fn box_corners(min: DVec3, max: DVec3) -> [DVec3; 8] {
    std::array::from_fn(|c| {
        DVec3::new(
            if c & 1 == 0 { min.x } else { max.x },
            if c & 2 == 0 { min.y } else { max.y },
            if c & 4 == 0 { min.z } else { max.z },
        )
    })
}

/// A stratified grid of `n (n + 1) / 2` points inside the plane triangle `t`: for `i + j < n`,
/// the point at `((i + 1/3) / n, (j + 1/3) / n)` along its two edges from `t[0]` (each point is
/// the centroid of one small triangle of the `n`-fold subdivision pointing the same way).
pub fn triangle_grid(t: &[DVec2; 3], n: usize) -> impl Iterator<Item = DVec2> + '_ {
    (0..n).flat_map(move |i| {
        (0..n - i).map(move |j| {
            let u = (i as f64 + 1.0 / 3.0) / n as f64;
            let v = (j as f64 + 1.0 / 3.0) / n as f64;
            t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v
        })
    })
}

/// Barycentric coordinates `[l0, l1, l2]` of plane point `q` in triangle `t` (by signed areas:
/// `l1 = area(a, q, c) / area(a, b, c)`, ...). Outside the triangle some are negative; a
/// degenerate triangle gives non-finite values.
pub fn barycentric_2d(t: &[DVec2; 3], q: DVec2) -> [f64; 3] {
    let [a, b, c] = *t;
    let d = (b - a).perp_dot(c - a);
    let l1 = (q - a).perp_dot(c - a) / d;
    let l2 = (b - a).perp_dot(q - a) / d;
    [1.0 - l1 - l2, l1, l2]
}

/// Barycentric coordinates of point `p` (projected onto the triangle's plane) in the 3D triangle
/// `t`, by least squares over the edge vectors; `[1, 0, 0]` for a degenerate triangle.
pub(crate) fn barycentric_3d(t: &[DVec3; 3], p: DVec3) -> [f64; 3] {
    let (e1, e2, d) = (t[1] - t[0], t[2] - t[0], p - t[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1p, d2p) = (e1.dot(d), e2.dot(d));
    let den = d11 * d22 - d12 * d12;
    if den == 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let v = (d22 * d1p - d12 * d2p) / den;
    let w = (d11 * d2p - d12 * d1p) / den;
    [1.0 - v - w, v, w]
}

// ---------------------------------------------------------------------------------------------
// A grid of buckets

/// The bounding box `(min, max)` of a 2D triangle.
pub(crate) fn triangle_bounds(t: &[DVec2; 3]) -> (DVec2, DVec2) {
    (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]))
}

/// Polygons with at least this many triangles get a grid of them ([`grid_of_triangles`]): a
/// ground plane cut around thousands of buildings has tens of thousands, and every wedge that
/// reaches it would otherwise clip against each.
pub(crate) const GRID_TRIANGLES: usize = 32;

/// A polygon's triangle grid holds at most this many cell entries per triangle (its memory and the
/// cells a query visits stay linear in the triangles).
const GRID_ENTRIES_PER_TRIANGLE: usize = 16;

/// The grid of a polygon's triangles in its plane ([`BoxGrid`], cells about square, about one
/// per triangle), or `None` when their boxes would fill more than
/// [`GRID_ENTRIES_PER_TRIANGLE`] cells each on average (long slivers across the polygon):
/// then every triangle is tested, as without a grid.
pub(crate) fn grid_of_triangles(triangles: &[[DVec2; 3]]) -> Option<BoxGrid> {
    let boxes: Vec<(DVec2, DVec2)> = triangles.iter().map(triangle_bounds).collect();
    let min = boxes.iter().fold(DVec2::INFINITY, |m, b| m.min(b.0));
    let max = boxes.iter().fold(DVec2::NEG_INFINITY, |m, b| m.max(b.1));
    let size = (max - min).max(DVec2::splat(1e-300));
    let cell = (size.x * size.y / triangles.len() as f64)
        .sqrt()
        .max(size.x.max(size.y) / 1024.0);
    let dims = (
        ((size.x / cell).ceil() as usize).clamp(1, 1024),
        ((size.y / cell).ceil() as usize).clamp(1, 1024),
    );
    let cell = DVec2::splat(cell);
    (BoxGrid::entries(min, cell, dims, &boxes) <= GRID_ENTRIES_PER_TRIANGLE * triangles.len())
        .then(|| BoxGrid::new(min, cell, dims, &boxes))
}

/// A uniform grid of buckets over a 2D box (plane coordinates): cell `(x, y)` lists, in
/// increasing order, the items whose bounding boxes meet it. Point location in a mesh and
/// the triangles a segment passes near use it.
pub(crate) struct BoxGrid {
    min: DVec2,
    cell: DVec2,
    dims: (usize, usize),
    /// Cell `(x, y)`'s items are `ids[starts[y nx + x]..starts[y nx + x + 1]]`.
    starts: Vec<u32>,
    ids: Vec<u32>,
}

impl BoxGrid {
    /// The grid of `dims` cells of size `cell` from `min`, over the items' `boxes` (min,
    /// max). Points outside it fall in its border cells.
    pub(crate) fn new(
        min: DVec2,
        cell: DVec2,
        dims: (usize, usize),
        boxes: &[(DVec2, DVec2)],
    ) -> Self {
        let mut grid = BoxGrid {
            min,
            cell,
            dims,
            starts: vec![0; dims.0 * dims.1 + 1],
            ids: Vec::new(),
        };
        // Count, then fill (compressed rows), in item order.
        for b in boxes {
            for k in grid.cells(*b) {
                grid.starts[k + 1] += 1;
            }
        }
        for k in 0..dims.0 * dims.1 {
            grid.starts[k + 1] += grid.starts[k];
        }
        let mut next = grid.starts.clone();
        grid.ids = vec![0; grid.starts[dims.0 * dims.1] as usize];
        for (item, b) in boxes.iter().enumerate() {
            for k in grid.cells(*b) {
                grid.ids[next[k] as usize] = item as u32;
                next[k] += 1;
            }
        }
        grid
    }

    /// How many cell entries [`BoxGrid::new`] would make (the cells each box meets, summed).
    pub(crate) fn entries(
        min: DVec2,
        cell: DVec2,
        dims: (usize, usize),
        boxes: &[(DVec2, DVec2)],
    ) -> usize {
        let probe = BoxGrid {
            min,
            cell,
            dims,
            starts: Vec::new(),
            ids: Vec::new(),
        };
        boxes.iter().map(|b| probe.cells(*b).count()).sum()
    }

    /// The index of every cell the box `(lo, hi)` meets.
    fn cells(&self, (lo, hi): (DVec2, DVec2)) -> impl Iterator<Item = usize> + use<> {
        let ((x0, y0), (x1, y1)) = (self.cell_of(lo), self.cell_of(hi));
        let nx = self.dims.0;
        (y0..=y1).flat_map(move |y| (x0..=x1).map(move |x| y * nx + x))
    }

    /// The grid's `(columns, rows)`.
    pub(crate) fn dims(&self) -> (usize, usize) {
        self.dims
    }

    /// The cell holding point `p`, clamped into the grid (NaN: the first cell).
    pub(crate) fn cell_of(&self, p: DVec2) -> (usize, usize) {
        let c = ((p - self.min) / self.cell).floor();
        let clamp = |v: f64, n: usize| {
            if v.is_nan() || v < 0.0 {
                0
            } else {
                (v as usize).min(n - 1)
            }
        };
        (clamp(c.x, self.dims.0), clamp(c.y, self.dims.1))
    }

    /// The items of cell `(x, y)`, in increasing order.
    pub(crate) fn bucket(&self, x: usize, y: usize) -> &[u32] {
        let k = y * self.dims.0 + x;
        &self.ids[self.starts[k] as usize..self.starts[k + 1] as usize]
    }

    /// The items (sorted, each once) whose boxes come within `margin` of the segment `p-q`:
    /// every item the segment passes within `margin` of is among them. Visits only the cells
    /// along the segment, column by column.
    pub(crate) fn near_segment(&self, p: DVec2, q: DVec2, margin: f64) -> Vec<u32> {
        let mut out = Vec::new();
        let (lo, hi) = (p.min(q) - margin, p.max(q) + margin);
        let (x0, _) = self.cell_of(lo);
        let (x1, _) = self.cell_of(hi);
        let dx = q.x - p.x;
        for x in x0..=x1 {
            // The segment's y range over this column's x range (widened by `margin`).
            let xa = (self.min.x + x as f64 * self.cell.x - margin).max(lo.x);
            let xb = (self.min.x + (x + 1) as f64 * self.cell.x + margin).min(hi.x);
            let (ya, yb) = if dx.abs() > 1e-300 {
                let y = |t: f64| p.y + (q.y - p.y) * ((t - p.x) / dx).clamp(0.0, 1.0);
                (y(xa).min(y(xb)), y(xa).max(y(xb)))
            } else {
                (p.y.min(q.y), p.y.max(q.y))
            };
            let (_, y0) = self.cell_of(DVec2::new(xa, ya - margin));
            let (_, y1) = self.cell_of(DVec2::new(xb, yb + margin));
            for y in y0..=y1 {
                out.extend_from_slice(self.bucket(x, y));
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The contour sum's `angle` against libm's atan2 over angles from 1e-12 to pi - 1e-12, at
    /// scales from 1e-9 to 1e9, and at the reduction's branch points.
    #[test]
    fn angle_matches_atan2() {
        let mut worst = 0.0f64;
        let mut check = |y: f64, x: f64| {
            let (got, want) = (angle(y, x), y.atan2(x));
            worst = worst.max((got - want).abs() / want);
        };
        for scale in [1e-9, 1e-3, 1.0, 1e3, 1e9] {
            for k in 0..=20_000 {
                let theta = 1e-12 + (std::f64::consts::PI - 2e-12) * k as f64 / 20_000.0;
                check(scale * theta.sin(), scale * theta.cos());
            }
            for t in [
                0.66,
                0.66 + 1e-16,
                2.414_213_562_373_095,
                1.0,
                1e-300,
                1e300,
            ] {
                check(scale * t, scale);
                check(scale * t, -scale);
            }
        }
        assert!(worst < 1e-15, "worst relative error {worst:e}");
        assert_eq!(angle(1.0, 0.0), std::f64::consts::FRAC_PI_2);
        assert!(angle(1.0, f64::NAN).is_nan() && angle(f64::NAN, 1.0).is_nan());
    }

    #[test]
    fn triangle_grid_covers_the_triangle_evenly() {
        let t = [
            DVec2::new(0.0, 0.0),
            DVec2::new(3.0, 0.0),
            DVec2::new(1.0, 2.0),
        ];
        for n in [1, 2, 7] {
            let points: Vec<DVec2> = triangle_grid(&t, n).collect();
            assert_eq!(points.len(), n * (n + 1) / 2);
            for q in &points {
                let l = barycentric_2d(&t, *q);
                assert!(l.iter().all(|x| *x > 0.0), "{q} outside: {l:?}");
            }
        }
        // One point: the centroid.
        let c = triangle_grid(&t, 1).next().unwrap();
        assert!((c - (t[0] + t[1] + t[2]) / 3.0).length() < 1e-12, "{c}");
    }

    fn square(z: f64, size: f64) -> Vec<DVec3> {
        let h = size / 2.0;
        vec![
            DVec3::new(-h, -h, z),
            DVec3::new(h, -h, z),
            DVec3::new(h, h, z),
            DVec3::new(-h, h, z),
        ]
    }

    /// Corner formula for a differential element under a parallel rectangle (Howell's catalogue).
    fn corner(a: f64, b: f64, h: f64) -> f64 {
        let sa = (a * a + h * h).sqrt();
        let sb = (b * b + h * h).sqrt();
        (a / sa * (b / sa).atan() + b / sb * (a / sb).atan()) / (2.0 * PI)
    }

    #[test]
    fn differential_under_coaxial_disk_is_half() {
        // r = h: F = r²/(h²+r²) = 0.5; a 4096-gon approximates the disk to ~4e-7.
        let n = 4096;
        let disk: Vec<DVec3> = (0..n)
            .map(|k| {
                let a = 2.0 * PI * k as f64 / n as f64;
                DVec3::new(a.cos(), a.sin(), 1.0)
            })
            .collect();
        let f = point_polygon_form_factor(DVec3::ZERO, DVec3::Z, &disk);
        // The inscribed polygon is smaller than the disk by a relative 4e-7.
        assert!((f - 0.5).abs() < 1e-6, "{f}");
    }

    #[test]
    fn rectangle_corner_formula_matches_contour_integral() {
        // Axis-aligned rectangle [x0,x1]x[y0,y1] at height h above the point.
        let (x0, x1, y0, y1, h) = (-0.3, 1.2, 0.4, 2.0, 0.7);
        let exact = corner(x1, y1, h) - corner(x0, y1, h) - corner(x1, y0, h) + corner(x0, y0, h);
        let poly = vec![
            DVec3::new(x0, y0, h),
            DVec3::new(x1, y0, h),
            DVec3::new(x1, y1, h),
            DVec3::new(x0, y1, h),
        ];
        let f = point_polygon_form_factor(DVec3::ZERO, DVec3::Z, &poly);
        assert!((f - exact).abs() < 1e-12, "{f} vs {exact}");
    }

    /// Area-to-area form factor by Gauss-Legendre quadrature of the point-to-polygon form factor
    /// over the receiving unit square.
    fn area_form_factor(receiver: &dyn Fn(f64, f64) -> (DVec3, DVec3), source: &[DVec3]) -> f64 {
        // 20-point Gauss-Legendre nodes and weights on [-1, 1], by Newton iteration.
        let n = 20;
        let mut nodes = vec![0.0; n];
        let mut weights = vec![0.0; n];
        for i in 0..n {
            let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                let dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-15 {
                    break;
                }
            }
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            nodes[i] = x;
            weights[i] = 2.0 / ((1.0 - x * x) * dp * dp);
        }
        // Composite over 4x4 cells so the edge singularity of adjacent squares converges.
        let cells = 4;
        let mut sum = 0.0;
        for cu in 0..cells {
            for cv in 0..cells {
                for i in 0..n {
                    for j in 0..n {
                        let u = (cu as f64 + 0.5 * (nodes[i] + 1.0)) / cells as f64;
                        let v = (cv as f64 + 0.5 * (nodes[j] + 1.0)) / cells as f64;
                        let (p, nn) = receiver(u, v);
                        let w = weights[i] * weights[j] * 0.25 / (cells * cells) as f64;
                        sum += w * point_polygon_form_factor(p, nn, source);
                    }
                }
            }
        }
        sum
    }

    #[test]
    fn parallel_unit_squares_match_howell() {
        for (d, exact) in [
            (1.0, 0.1998248957),
            (2.0, 0.0685895888),
            (0.5, 0.4152532836),
        ] {
            let src = square(d, 1.0);
            let f = area_form_factor(&|u, v| (DVec3::new(u - 0.5, v - 0.5, 0.0), DVec3::Z), &src);
            assert!((f - exact).abs() < 1e-6, "d={d}: {f} vs {exact}");
        }
    }

    #[test]
    fn perpendicular_unit_squares_match_howell() {
        // Receiver in z=0 (x in [0,1], y in [0,1]), source in the plane y=0 above it (x, z in
        // [0,1]), sharing the edge along x. Howell C-14: 0.2000437761.
        let src = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 1.0),
            DVec3::new(0.0, 0.0, 1.0),
        ];
        let f = area_form_factor(&|u, v| (DVec3::new(u, v, 0.0), DVec3::Z), &src);
        // The edge singularity limits quadrature accuracy; 1e-5 still catches any real error.
        assert!((f - 0.2000437761).abs() < 1e-5, "{f}");
    }

    #[test]
    fn horizon_clipping_halves_a_symmetric_source() {
        // A point on a wall's base looking sideways sees exactly the half of a symmetric source
        // above its horizon.
        let src = vec![
            DVec3::new(-1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(-1.0, 1.0, 1.0),
        ];
        let full = point_polygon_form_factor(DVec3::ZERO, DVec3::Y, &src);
        let half = point_polygon_form_factor(DVec3::ZERO, DVec3::X, &src);
        // By symmetry the x-facing point sees the x>0 half, weighted by cos to x.
        let right = vec![
            DVec3::new(0.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, -1.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(0.0, 1.0, 1.0),
        ];
        let expected = point_polygon_form_factor(DVec3::ZERO, DVec3::X, &right);
        assert!((half - expected).abs() < 1e-14);
        assert!(full > half && half > 0.0);
    }

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
    fn entirely_above_the_horizon_skips_the_clip_with_the_same_value() {
        let poly = square(1.0, 1.0);
        let (p, n) = (
            DVec3::new(0.3, -0.2, 0.0),
            DVec3::new(0.1, 0.0, 1.0).normalize(),
        );
        let clipped = clip_to_horizon(&poly, p, n);
        assert_eq!(clipped, poly);
        assert_eq!(
            point_polygon_form_factor(p, n, &poly),
            contour_sum(p, n, &poly).abs() / (2.0 * PI)
        );
    }

    #[test]
    fn barycentrics_reproduce_the_point() {
        let t2 = [
            DVec2::new(0.0, 0.0),
            DVec2::new(2.0, 0.0),
            DVec2::new(0.0, 1.0),
        ];
        let q = DVec2::new(0.5, 0.25);
        let l = barycentric_2d(&t2, q);
        let back = t2[0] * l[0] + t2[1] * l[1] + t2[2] * l[2];
        assert!((back - q).length() < 1e-15, "{l:?}");
        let t3 = t2.map(|v| DVec3::new(v.x, 1.0, v.y));
        let m = barycentric_3d(&t3, DVec3::new(0.5, 1.0, 0.25));
        for k in 0..3 {
            assert!((l[k] - m[k]).abs() < 1e-15, "{l:?} vs {m:?}");
        }
        assert!((triangle_area(&t3) - signed_area(&t2)).abs() < 1e-15);
    }
}
