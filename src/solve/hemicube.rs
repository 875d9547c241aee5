//! Hemicube form factors (Cohen and Greenberg, "The hemi-cube: a radiosity solution for complex
//! environments", SIGGRAPH 1985).
//!
//! A half cube of side 2 stands on the receiving (or shooting) point, its top face one unit
//! above the point along the normal, its four side faces half height. Each face is a grid of
//! cells: `R x R` on the top, `R x R/2` on each side (`R` the resolution, even), `3 R²` in all.
//! Every triangle of the scene is projected onto the five faces through the point, clipped to
//! each face's frustum, and scan-converted at the cell centres with a depth buffer (an item
//! buffer: the nearest triangle per cell). A cell's *delta form factor* is the form factor from
//! the point to that cell:
//!
//! ```text
//! top face,  cell at (x, y, 1):  dF = dA / (pi (x² + y² + 1)²)
//! side face, cell at (1, y, z):  dF = z dA / (pi (y² + z² + 1)²)
//! ```
//!
//! with `dA = (2/R)²` the cell's area (units of the unit hemicube). The form factor from the
//! point to a triangle is the sum of the delta form factors of the cells it wins. The delta
//! form factors sum to 1 only in the limit (the error is `O(1/R²)`); they are used as they are,
//! so the hemicube's own error stays visible.
//!
//! The method's two known failures (Baum, Rushmeier, Winget, "Improving radiosity solutions
//! through the use of analytically determined form-factors", SIGGRAPH 1989) are measured by
//! the tests and the failure sweep, not corrected:
//!
//! * **Aliasing**: a triangle is seen only through the cell centres it covers. A small or far
//!   triangle (a small bright emitter far away) covers one cell or none, so its form factor is
//!   0 or a whole cell's, and moves in steps across a receiver.
//! * **Proximity**: the hemicube samples directions from one point, the centre of the
//!   shooting patch. A receiver touching that patch sees it under a very different solid angle
//!   across its extent; the reciprocity `F_ji = F_ij A_i / A_j` of shooting then magnifies the
//!   error on small receivers (`F_ji` is capped at 1 there).
//!
//! Lengths in scene units; form factors dimensionless. Deterministic: triangles are drawn in
//! index order and a cell keeps the first of equally near triangles.

use crate::geometry::clip_polygon_to_plane;
use glam::{DVec2, DVec3};
use std::f64::consts::PI;

/// Default `--hemicube-resolution`: cells across the top face. Cohen and Greenberg used 50 to
/// 100; at 64 the parallel unit squares' form factor is within 0.2% (see the known-answer
/// tests).
pub const DEFAULT_RESOLUTION: u32 = 64;

/// Smallest and largest resolution accepted (even values only).
pub(crate) const RESOLUTION_RANGE: std::ops::RangeInclusive<u32> = 2..=2048;

/// The five faces, as `(forward, right, up)` in the point's frame `(u, v, n)`: index 0 is the
/// top face, 1 to 4 the sides. Local coordinates of a point `q` (relative to the hemicube's
/// centre) on a face: `x = q·right`, `y = q·up`, `z = q·forward`; its image is `(x/z, y/z)`.
fn faces(u: DVec3, v: DVec3, n: DVec3) -> [(DVec3, DVec3, DVec3); 5] {
    [(n, u, v), (u, v, n), (-u, v, n), (v, u, n), (-v, u, n)]
}

/// A hemicube of a given resolution: its delta form factors, reused for every point.
#[derive(Clone, Debug)]
pub struct Hemicube {
    /// Cells across the top face (even).
    resolution: usize,
    /// Delta form factor of every cell: the top face row by row, then each side face.
    delta: Vec<f64>,
}

/// What one hemicube saw: the form factor from its point to each triangle it was given.
pub struct View {
    pub form_factors: Vec<f64>,
}

impl Hemicube {
    /// A hemicube with `resolution` cells across its top face. `resolution` must be even and
    /// within [`RESOLUTION_RANGE`] (checked by the bake's options; clamped here).
    pub fn new(resolution: u32) -> Hemicube {
        let r =
            (resolution.clamp(*RESOLUTION_RANGE.start(), *RESOLUTION_RANGE.end()) & !1) as usize;
        let h = r / 2;
        let da = (2.0 / r as f64).powi(2);
        let centre = |i: usize| -1.0 + (i as f64 + 0.5) * 2.0 / r as f64;
        let mut delta = Vec::with_capacity(3 * r * r);
        for j in 0..r {
            for i in 0..r {
                let (x, y) = (centre(i), centre(j));
                delta.push(da / (PI * (x * x + y * y + 1.0).powi(2)));
            }
        }
        for _ in 0..4 {
            for j in 0..h {
                for i in 0..r {
                    let (y, z) = (centre(i), (j as f64 + 0.5) * 2.0 / r as f64);
                    delta.push(z * da / (PI * (y * y + z * z + 1.0).powi(2)));
                }
            }
        }
        Hemicube {
            resolution: r,
            delta,
        }
    }

    /// Cells across the top face.
    pub(crate) fn resolution(&self) -> usize {
        self.resolution
    }

    /// Cells in all five faces, `3 R²`.
    pub(crate) fn cells(&self) -> usize {
        self.delta.len()
    }

    /// The sum of all delta form factors (1 in the limit of fine cells).
    pub(crate) fn delta_sum(&self) -> f64 {
        self.delta.iter().sum()
    }

    /// Form factors from a differential area at `p` with unit normal `n` to each of
    /// `triangles` (world space), each hiding what lies behind it (at equal depth, a triangle
    /// facing `p` hides one showing it its back: the two sides of a double-sided surface).
    /// Triangles for which `skip`
    /// is true are not drawn at all (the point's own plane). A triangle's form factor counts
    /// whatever side of it faces `p`: the caller zeroes the back faces it does not want
    /// (one-sided surfaces still hide what is behind them).
    pub fn form_factors(
        &self,
        p: DVec3,
        n: DVec3,
        triangles: &[[DVec3; 3]],
        skip: &dyn Fn(usize) -> bool,
    ) -> View {
        let r = self.resolution;
        let h = r / 2;
        let (u, v) = n.any_orthonormal_pair();
        let mut depth = vec![f64::INFINITY; self.delta.len()];
        let mut item = vec![u32::MAX; self.delta.len()];
        let mut clipped = Vec::with_capacity(8);
        let mut scratch = Vec::with_capacity(8);
        // Which triangles face `p`: at equal depth (the two sides of a double-sided surface,
        // coincident triangles of opposite winding) the one facing `p` is what it sees.
        let facing: Vec<bool> = triangles
            .iter()
            .map(|t| {
                let c = (t[0] + t[1] + t[2]) / 3.0;
                (t[1] - t[0]).cross(t[2] - t[0]).dot(p - c) > 0.0
            })
            .collect();
        let mut front = vec![false; self.delta.len()];
        for (f, &(fwd, right, up)) in faces(u, v, n).iter().enumerate() {
            let (rows, offset, y_min) = if f == 0 {
                (r, 0, -1.0)
            } else {
                (h, r * r + (f - 1) * r * h, 0.0)
            };
            // The face's frustum: |x| <= z, y_min <= y/z <= 1 (the side faces stop at the
            // horizon, y >= 0).
            let planes = [
                DVec3::new(-1.0, 0.0, 1.0),
                DVec3::new(1.0, 0.0, 1.0),
                DVec3::new(0.0, -1.0, 1.0),
                if f == 0 {
                    DVec3::new(0.0, 1.0, 1.0)
                } else {
                    DVec3::new(0.0, 1.0, 0.0)
                },
            ];
            for (k, tri) in triangles.iter().enumerate() {
                if skip(k) {
                    continue;
                }
                let local = tri.map(|q| {
                    let d = q - p;
                    DVec3::new(d.dot(right), d.dot(up), d.dot(fwd))
                });
                if local.iter().all(|q| q.z <= 0.0) {
                    continue;
                }
                clipped.clear();
                clipped.extend_from_slice(&local);
                let size = local.iter().map(|q| q.length()).fold(0.0, f64::max);
                for plane in planes {
                    clip_polygon_to_plane(&clipped, plane, DVec3::ZERO, &mut scratch);
                    std::mem::swap(&mut clipped, &mut scratch);
                    if clipped.len() < 3 {
                        break;
                    }
                }
                // Keep away from z = 0, where the projection divides by zero (only a triangle
                // through the point itself reaches it).
                clip_polygon_to_plane(
                    &clipped,
                    DVec3::Z,
                    DVec3::new(0.0, 0.0, 1e-12 * size),
                    &mut scratch,
                );
                std::mem::swap(&mut clipped, &mut scratch);
                if clipped.len() < 3 {
                    continue;
                }
                // The triangle's plane in local coordinates, for the depth along a cell's ray.
                let m = (local[1] - local[0]).cross(local[2] - local[0]);
                let m0 = m.dot(local[0]);
                // Image in cell units: x in [0, r], y in [0, rows].
                let scale = r as f64 / 2.0;
                let mut img: Vec<DVec2> = Vec::with_capacity(clipped.len());
                for q in &clipped {
                    let c = DVec2::new((q.x / q.z + 1.0) * scale, (q.y / q.z - y_min) * scale);
                    // Corners the clipping left a rounding error apart would make an edge of
                    // no length and random direction, whose inside test cuts the polygon.
                    if img.last().is_none_or(|l: &DVec2| l.distance(c) > 1e-9) {
                        img.push(c);
                    }
                }
                while img.len() > 1 && img[0].distance(img[img.len() - 1]) <= 1e-9 {
                    img.pop();
                }
                if img.len() < 3 {
                    continue;
                }
                let area2: f64 = (0..img.len())
                    .map(|i| img[i].perp_dot(img[(i + 1) % img.len()]))
                    .sum();
                if area2 == 0.0 || area2.is_nan() {
                    continue;
                }
                let sign = area2.signum();
                let (lo, hi) = img.iter().fold(
                    (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
                    |(lo, hi), q| (lo.min(*q), hi.max(*q)),
                );
                // Cells whose centre (i + 0.5) lies within the bounding box, widened by the
                // inside test's tolerance (a column of centres on a shared axis-aligned edge
                // must not fall out of both triangles' boxes).
                let first = |a: f64| (a - 0.5 - 1e-7).ceil().max(0.0) as usize;
                let last =
                    |b: f64, len: usize| ((b - 0.5 + 1e-7).floor().min(len as f64 - 1.0)) as i64;
                let (i0, j0) = (first(lo.x), first(lo.y));
                let (i1, j1) = (last(hi.x, r), last(hi.y, rows));
                if i1 < i0 as i64 || j1 < j0 as i64 {
                    continue;
                }
                for j in j0..=j1 as usize {
                    for i in i0..=i1 as usize {
                        let c = DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
                        // Inside or within 1e-7 cell widths of an edge: a centre on the edge
                        // two triangles share goes to both (the depth test then keeps the
                        // first), never to neither through rounding.
                        let inside = (0..img.len()).all(|e| {
                            let (a, b) = (img[e], img[(e + 1) % img.len()]);
                            sign * (b - a).perp_dot(c - a) >= -1e-7 * (b - a).length()
                        });
                        if !inside {
                            continue;
                        }
                        // The cell centre's ray w = (x, y, 1) meets the plane at t w.
                        let w = DVec3::new(c.x / scale - 1.0, c.y / scale + y_min, 1.0);
                        let t = m0 / m.dot(w);
                        let cell = offset + j * r + i;
                        if !(t.is_finite() && t > 0.0) {
                            continue;
                        }
                        let tie = (t - depth[cell]).abs() <= 1e-9 * t;
                        let nearer = if tie {
                            facing[k] && !front[cell] || t < depth[cell] && facing[k] == front[cell]
                        } else {
                            t < depth[cell]
                        };
                        if nearer {
                            depth[cell] = t;
                            item[cell] = k as u32;
                            front[cell] = facing[k];
                        }
                    }
                }
            }
        }
        let mut form_factors = vec![0.0; triangles.len()];
        for (cell, &k) in item.iter().enumerate() {
            if k != u32::MAX {
                form_factors[k as usize] += self.delta[cell];
            }
        }
        View { form_factors }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delta_form_factors_sum_to_one_in_the_limit() {
        let errors: Vec<f64> = [8, 32, 128]
            .iter()
            .map(|&r| (Hemicube::new(r).delta_sum() - 1.0).abs())
            .collect();
        assert!(errors[0] < 1e-2, "{errors:?}");
        assert!(errors[2] < 1e-4, "{errors:?}");
        assert!(errors[1] < errors[0] && errors[2] < errors[1], "{errors:?}");
        assert_eq!(Hemicube::new(32).cells(), 3 * 32 * 32);
    }

    #[test]
    fn a_triangle_hides_what_lies_behind_it() {
        let hc = Hemicube::new(64);
        let big = |h: f64| [[-5.0, -5.0, h], [5.0, -5.0, h], [0.0, 5.0, h]].map(DVec3::from_array);
        // Near first or far first: the near one wins either way.
        for order in [[1.0, 2.0], [2.0, 1.0]] {
            let tris = [big(order[0]), big(order[1])];
            let f = hc
                .form_factors(DVec3::ZERO, DVec3::Z, &tris, &|_| false)
                .form_factors;
            let near = if order[0] < order[1] { 0 } else { 1 };
            assert!(f[near] > 0.5, "{f:?}");
            assert_eq!(f[1 - near], 0.0, "{f:?}");
        }
    }

    #[test]
    fn of_two_sides_back_to_back_the_one_facing_the_point_is_seen() {
        // A double-sided surface: the same triangle twice, winding reversed. Whichever comes
        // first, the side facing the point takes the whole form factor, seen from either side.
        let hc = Hemicube::new(32);
        let up = [[-5.0, -5.0, 1.0], [5.0, -5.0, 1.0], [0.0, 5.0, 1.0]].map(DVec3::from_array);
        let down = [up[0], up[2], up[1]];
        for tris in [[up, down], [down, up]] {
            let facing_down = if tris[0] == down { 0 } else { 1 };
            let below = hc
                .form_factors(DVec3::ZERO, DVec3::Z, &tris, &|_| false)
                .form_factors;
            assert!(below[facing_down] > 0.5, "{below:?}");
            assert_eq!(below[1 - facing_down], 0.0, "{below:?}");
            let above = hc
                .form_factors(DVec3::new(0.0, 0.0, 2.0), -DVec3::Z, &tris, &|_| false)
                .form_factors;
            assert!(above[1 - facing_down] > 0.5, "{above:?}");
            assert_eq!(above[facing_down], 0.0, "{above:?}");
        }
    }
}
