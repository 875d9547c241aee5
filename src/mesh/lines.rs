//! The discontinuity lines of one polygon made ready for its triangulation: the outline with
//! collinear runs merged, each segment kept clear of the outline or snapped onto it
//! ([`keep_clear`]), and the segments already placed, bucketed so that a new one can be tested
//! against its neighbours ([`Obstacles`]).

use super::ANGLE_LIMIT_DEG;
use glam::DVec2;

/// Merges chains of collinear boundary edges (T-junction vertices of the input mesh) into
/// single edges. Edges keep their direction (polygon on the left).
pub(super) fn merge_collinear(boundary: &[[DVec2; 2]]) -> Vec<[DVec2; 2]> {
    let key = |p: DVec2| (p.x.to_bits(), p.y.to_bits());
    let mut from: std::collections::BTreeMap<(u64, u64), Vec<usize>> = Default::default();
    let mut into: std::collections::BTreeMap<(u64, u64), usize> = Default::default();
    for (i, [a, b]) in boundary.iter().enumerate() {
        from.entry(key(*a)).or_default().push(i);
        *into.entry(key(*b)).or_default() += 1;
    }
    let straight = |d1: DVec2, d2: DVec2| {
        d1.perp_dot(d2).abs() <= 1e-9 * d1.length() * d2.length() && d1.dot(d2) > 0.0
    };
    // The edge that continues `i` straight on, if its end is a plain (degree-two) vertex.
    let next = |i: usize| -> Option<usize> {
        let [a, b] = boundary[i];
        let out = from.get(&key(b))?;
        if out.len() != 1 || into.get(&key(b)) != Some(&1) {
            return None;
        }
        let j = out[0];
        straight(b - a, boundary[j][1] - boundary[j][0]).then_some(j)
    };
    let mut has_prev = vec![false; boundary.len()];
    for i in 0..boundary.len() {
        if let Some(j) = next(i) {
            has_prev[j] = true;
        }
    }
    let mut used = vec![false; boundary.len()];
    let mut out = Vec::new();
    // Chains start at edges nothing continues into; then what is left are closed straight loops
    // (impossible for a polygon) or single edges.
    for start in (0..boundary.len())
        .filter(|&i| !has_prev[i])
        .chain(0..boundary.len())
    {
        if used[start] {
            continue;
        }
        used[start] = true;
        let a = boundary[start][0];
        let mut end = start;
        while let Some(j) = next(end) {
            if used[j] {
                break;
            }
            used[j] = true;
            end = j;
        }
        out.push([a, boundary[end][1]]);
    }
    out
}

/// Segment `a-b` made safe to insert beside the outline. With `onto` (a hard shadow line), an
/// end within `gap` of the outline is moved onto it along the segment's own line (the
/// arrangement then splits the outline edge there, a clean T-junction); where the line does
/// not reach the outline within `2 gap` (it runs along it near a corner), or without `onto`,
/// the end is pulled in to at least `gap` from the outline. `None` when little is left or the
/// segment runs along the outline. An end a hair off the outline would leave spade a sliver
/// face that refinement splits without end; a shadow line pulled away from the outline leaves
/// elements that straddle the jump and smear it over their whole width.
pub(super) fn keep_clear(
    a: DVec2,
    b: DVec2,
    outline: &[[DVec2; 2]],
    gap: f64,
    onto: bool,
) -> Option<(DVec2, DVec2)> {
    let len = a.distance(b);
    if len <= 3.0 * gap {
        return None;
    }
    let u = (b - a) / len;
    let mid = (a + b) * 0.5;
    if outline
        .iter()
        .any(|[p, q]| dist_to_segment(mid, *p, *q) < gap)
    {
        return None;
    }
    let near = |x: DVec2| {
        outline
            .iter()
            .any(|[p, q]| dist_to_segment(x, *p, *q) < gap)
    };
    // The nearest crossing of the line `x + t dir` with the outline for t in -gap..2 gap, and
    // the outward normal of the edge crossed.
    let snap = |x: DVec2, dir: DVec2| -> Option<(f64, DVec2)> {
        let mut best: Option<(f64, DVec2)> = None;
        for [p, q] in outline {
            let e = *q - *p;
            let den = dir.perp_dot(e);
            if den.abs() <= 1e-12 * e.length() {
                continue;
            }
            let w = *p - x;
            let t = w.perp_dot(e) / den;
            let s = w.perp_dot(dir) / den;
            if (-1e-9..=1.0 + 1e-9).contains(&s)
                && (-gap..=2.0 * gap).contains(&t)
                && best.is_none_or(|(b, _)| t.abs() < b.abs())
            {
                let e = e.normalize();
                best = Some((t, DVec2::new(e.y, -e.x)));
            }
        }
        best
    };
    let pull = |x: DVec2, dir: DVec2| -> f64 {
        let mut t: f64 = 0.0;
        for [p, q] in outline {
            let d = dist_to_segment(x, *p, *q);
            if d < gap {
                let e = (*q - *p).normalize_or_zero();
                let sin = dir.perp_dot(e).abs().max(0.1);
                t = t.max((gap - d) / sin + gap);
            }
        }
        t
    };
    // Each end where it goes: onto the outline (onto its vertex, where one is within `gap`:
    // a shadow line leaves its building's corner, and a point a hair beside the corner would
    // leave a tiny edge that refinement chases), or pulled in.
    let corner = |x: DVec2| -> DVec2 {
        outline
            .iter()
            .map(|[p, _]| *p)
            .filter(|p| p.distance(x) < gap)
            .min_by(|p, q| p.distance(x).total_cmp(&q.distance(x)))
            .unwrap_or(x)
    };
    // A point put on an outline edge is rounded a hair to either side of it; inside, it would
    // leave spade's convex hull a zero-area face outside the polygon (refined without end),
    // so it goes a hair outside, where the outline only bends through it.
    let hair = 1e-9 * outline.iter().map(|[p, q]| p.distance(*q)).sum::<f64>();
    let end = |x: DVec2, inward: DVec2| -> (DVec2, f64) {
        if !near(x) {
            (x, 0.0)
        } else if let Some((t, out)) = snap(x, -inward).filter(|_| onto) {
            let on = x - inward * t;
            let c = corner(on);
            (if c == on { on + out * hair } else { c }, 0.0)
        } else {
            let t = pull(x, inward);
            (x + inward * t, t)
        }
    };
    let ((a, ta), (b, tb)) = (end(a, u), end(b, -u));
    if ta + tb >= len - gap || a.distance(b) <= gap {
        return None;
    }
    Some((a, b))
}

/// The segments already placed in a polygon's plane, bucketed in a uniform grid so that
/// [`Obstacles::along`] looks only at those near a point (the polygon's wedges would otherwise
/// each be tested against every one placed before: quadratic in the wedges).
pub(super) struct Obstacles {
    segments: Vec<[DVec2; 2]>,
    /// The placed segments of each [`Segment::feature`] (but 0): the boundaries of one
    /// penumbra.
    by_feature: std::collections::HashMap<u64, Vec<u32>>,
    lo: DVec2,
    cell: f64,
    dims: usize,
    buckets: Vec<Vec<u32>>,
    clearance: f64,
}

impl Obstacles {
    /// A grid over `lo..hi` of about `expected` cells, none smaller than the clearance.
    pub(super) fn new(lo: DVec2, hi: DVec2, clearance: f64, expected: usize) -> Obstacles {
        let size = (hi - lo).max_element().max(1e-300);
        let dims = ((expected as f64).sqrt().ceil() as usize).clamp(1, 256);
        let cell = (size / dims as f64).max(clearance).max(1e-300);
        let dims = ((size / cell).ceil() as usize).clamp(1, 256);
        Obstacles {
            segments: Vec::new(),
            by_feature: Default::default(),
            lo,
            cell,
            dims,
            buckets: vec![Vec::new(); dims * dims],
            clearance,
        }
    }

    pub(super) fn cell_of(&self, p: DVec2) -> (usize, usize) {
        let c = ((p - self.lo) / self.cell).floor();
        let clamp = |x: f64| (x.max(0.0) as usize).min(self.dims - 1);
        (clamp(c.x), clamp(c.y))
    }

    /// Adds segment `p q` (of `feature`, see [`Segment::feature`]) to every cell its box, grown
    /// by the clearance, touches.
    pub(super) fn push(&mut self, p: DVec2, q: DVec2, feature: u64) {
        let k = self.segments.len() as u32;
        self.segments.push([p, q]);
        if feature != 0 {
            self.by_feature.entry(feature).or_default().push(k);
        }
        let (x0, y0) = self.cell_of(p.min(q) - DVec2::splat(self.clearance));
        let (x1, y1) = self.cell_of(p.max(q) + DVec2::splat(self.clearance));
        for y in y0..=y1 {
            for x in x0..=x1 {
                self.buckets[y * self.dims + x].push(k);
            }
        }
    }

    /// True when a placed segment passes within `d` of `p` (scene units).
    pub(super) fn near(&self, p: DVec2, d: f64) -> bool {
        let (x0, y0) = self.cell_of(p - DVec2::splat(d));
        let (x1, y1) = self.cell_of(p + DVec2::splat(d));
        (y0..=y1).any(|y| {
            (x0..=x1).any(|x| {
                self.buckets[y * self.dims + x].iter().any(|&k| {
                    let [a, b] = self.segments[k as usize];
                    dist_to_segment(p, a, b) < d
                })
            })
        })
    }

    /// The pieces of the wedge segment `a b` (of `feature`, see [`Segment::feature`]) that do
    /// not run close along the other boundary of its own penumbra: the parts within the
    /// clearance of a placed segment of the same feature, at an angle under
    /// [`ANGLE_LIMIT_DEG`], are left out, and so are the pieces left shorter than the
    /// clearance.
    ///
    /// A small light's penumbra is thinner than an element for most of its length: its two
    /// boundaries leave the occluder a few degrees apart, and Delaunay refinement filled the
    /// wedge between them with fans of needles (on a town lit by 256 street lamps, half the
    /// ground's elements on 4% of its area, and the mesh showed the direct light worse than
    /// uniform meshing). One boundary resolves such a penumbra as well as two at that element
    /// size. Only the other boundary of the same penumbra counts: lines of different
    /// occluders that run close (neighbouring boxes' shadows) stay, and a penumbra that opens
    /// wide (a large light near its occluder) meets the limit angle within the clearance.
    pub(super) fn apart_from_its_pair(
        &self,
        a: DVec2,
        b: DVec2,
        feature: u64,
    ) -> Vec<(DVec2, DVec2)> {
        let d = b - a;
        let len = d.length();
        if feature == 0 || len <= 0.0 {
            return vec![(a, b)];
        }
        let sin_limit = ANGLE_LIMIT_DEG.to_radians().sin();
        let Some(pair) = self.by_feature.get(&feature) else {
            return vec![(a, b)];
        };
        let mut blocked: Vec<(f64, f64)> = pair
            .iter()
            .filter_map(|&k| {
                let [p, q] = self.segments[k as usize];
                let e = (q - p).normalize_or_zero();
                if (d / len).perp_dot(e).abs() >= sin_limit {
                    return None;
                }
                within_of_segment(a, d, [p, q], self.clearance)
            })
            .collect();
        if blocked.is_empty() {
            return vec![(a, b)];
        }
        blocked.sort_by(|x, y| x.0.total_cmp(&y.0));
        let mut pieces = Vec::new();
        let mut from = 0.0;
        let min_piece = self.clearance / len;
        for (lo, hi) in blocked.into_iter().chain([(1.0, 1.0)]) {
            if lo - from >= min_piece {
                pieces.push((a + d * from, a + d * lo));
            }
            from = f64::max(from, hi);
        }
        pieces
    }

    /// True when both `a` and `b` lie within the clearance of one placed segment: the new
    /// segment would run along it.
    pub(super) fn along(&self, a: DVec2, b: DVec2) -> bool {
        let (x, y) = self.cell_of(a);
        self.buckets[y * self.dims + x].iter().any(|&k| {
            let [p, q] = self.segments[k as usize];
            dist_to_segment(a, p, q) < self.clearance && dist_to_segment(b, p, q) < self.clearance
        })
    }
}

/// The interval of `t` in `0..1` where the point `a + t d` lies within `c` of the segment `p q`
/// (scene units), if any: the line's intersection with the stadium around the segment (two
/// disks and the rectangle between them), one interval since the stadium is convex.
pub(super) fn within_of_segment(
    a: DVec2,
    d: DVec2,
    [p, q]: [DVec2; 2],
    c: f64,
) -> Option<(f64, f64)> {
    let dd = d.length_squared();
    if dd <= 0.0 {
        return None;
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for centre in [p, q] {
        // |a - centre + t d|² < c²
        let f = a - centre;
        let (b, cc) = (2.0 * f.dot(d), f.length_squared() - c * c);
        let disc = b * b - 4.0 * dd * cc;
        if disc > 0.0 {
            let r = disc.sqrt();
            lo = lo.min((-b - r) / (2.0 * dd));
            hi = hi.max((-b + r) / (2.0 * dd));
        }
    }
    let len = p.distance(q);
    if len > 0.0 {
        let e = (q - p) / len;
        // `x0 + t x1` within `lo_b..hi_b`, as an interval of `t`.
        let slab = |x0: f64, x1: f64, lo_b: f64, hi_b: f64| -> Option<(f64, f64)> {
            if x1 == 0.0 {
                return (lo_b..=hi_b)
                    .contains(&x0)
                    .then_some((f64::NEG_INFINITY, f64::INFINITY));
            }
            let (t0, t1) = ((lo_b - x0) / x1, (hi_b - x0) / x1);
            Some((t0.min(t1), t0.max(t1)))
        };
        let f = a - p;
        if let (Some(s), Some(h)) = (
            slab(f.dot(e), d.dot(e), 0.0, len),
            slab(f.dot(e.perp()), d.dot(e.perp()), -c, c),
        ) {
            let (t0, t1) = (s.0.max(h.0), s.1.min(h.1));
            if t0 < t1 {
                lo = lo.min(t0);
                hi = hi.max(t1);
            }
        }
    }
    let (lo, hi) = (lo.max(0.0), hi.min(1.0));
    (lo < hi).then_some((lo, hi))
}

pub(super) fn dist_to_segment(x: DVec2, p: DVec2, q: DVec2) -> f64 {
    let d = q - p;
    let l2 = d.length_squared();
    let t = if l2 > 0.0 {
        ((x - p).dot(d) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    x.distance(p + d * t)
}
