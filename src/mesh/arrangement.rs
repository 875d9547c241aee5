//! The planar arrangement of a polygon's outline and its discontinuity segments: every segment
//! split at every crossing, T-junction and overlap, with near-coincident points merged, so that
//! the pieces can go into spade with `try_add_constraint` without ever crossing (spade's own
//! splitting panics on such inputs; see the README, "Insertion").
//!
//! Intersections are computed in f64; points closer than `tol` are merged into the first one
//! seen, so the result depends only on the order of the input.

use glam::DVec2;
use std::collections::BTreeMap;

/// The planar graph: merged points and non-crossing edges, each with the tag of the first input
/// segment that produced it.
#[derive(Clone, Debug, Default)]
pub(crate) struct Arrangement<T> {
    pub(crate) points: Vec<DVec2>,
    pub(crate) edges: Vec<(u32, u32, T)>,
}

/// Merges points closer than `tol` (grid hashing, first point wins).
struct Snapper {
    tol: f64,
    cells: BTreeMap<(i64, i64), Vec<u32>>,
    points: Vec<DVec2>,
}

impl Snapper {
    fn cell(&self, p: DVec2) -> (i64, i64) {
        (
            (p.x / self.tol).floor() as i64,
            (p.y / self.tol).floor() as i64,
        )
    }

    fn snap(&mut self, p: DVec2) -> u32 {
        let (cx, cy) = self.cell(p);
        let mut best: Option<(f64, u32)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                if let Some(ids) = self.cells.get(&(cx + dx, cy + dy)) {
                    for &i in ids {
                        let d = self.points[i as usize].distance(p);
                        if d <= self.tol && best.is_none_or(|b| d < b.0) {
                            best = Some((d, i));
                        }
                    }
                }
            }
        }
        if let Some((_, i)) = best {
            return i;
        }
        let id = self.points.len() as u32;
        self.points.push(p);
        self.cells.entry((cx, cy)).or_default().push(id);
        id
    }
}

/// Builds the arrangement of `segments` (earlier segments' tags win on shared pieces).
pub(crate) fn build<T: Copy>(segments: &[(DVec2, DVec2, T)], tol: f64) -> Arrangement<T> {
    let tol = tol.max(f64::MIN_POSITIVE);
    let mut snapper = Snapper {
        tol,
        cells: BTreeMap::new(),
        points: Vec::new(),
    };
    let ends: Vec<(u32, u32)> = segments
        .iter()
        .map(|(a, b, _)| (snapper.snap(*a), snapper.snap(*b)))
        .collect();
    // Split points of each segment: (parameter along it, point id).
    let mut splits: Vec<Vec<(f64, u32)>> = ends
        .iter()
        .map(|&(a, b)| vec![(0.0, a), (1.0, b)])
        .collect();
    let boxes: Vec<(DVec2, DVec2)> = segments
        .iter()
        .map(|(a, b, _)| (a.min(*b) - tol, a.max(*b) + tol))
        .collect();
    // Sweep over x so only segments whose x-ranges overlap are paired.
    let mut order: Vec<usize> = (0..segments.len()).collect();
    order.sort_by(|&i, &j| boxes[i].0.x.total_cmp(&boxes[j].0.x).then(i.cmp(&j)));
    for (k, &i) in order.iter().enumerate() {
        for &j in &order[k + 1..] {
            if boxes[j].0.x > boxes[i].1.x {
                break;
            }
            if boxes[j].0.y > boxes[i].1.y || boxes[i].0.y > boxes[j].1.y {
                continue;
            }
            let (i, j) = (i.min(j), i.max(j));
            let (p, p2, _) = segments[i];
            let (q, q2, _) = segments[j];
            let (r, s) = (p2 - p, q2 - q);
            let (lr, ls) = (r.length(), s.length());
            if lr <= tol || ls <= tol {
                continue;
            }
            let d = r.perp_dot(s);
            // Nearly parallel segments within `tol` of each other's line are collinear: their
            // intersection point would be ill-conditioned.
            let line_dist =
                |x: DVec2, o: DVec2, dir: DVec2, l: f64| (x - o).perp_dot(dir).abs() / l;
            let collinear = (line_dist(q, p, r, lr) <= tol && line_dist(q2, p, r, lr) <= tol)
                || (line_dist(p, q, s, ls) <= tol && line_dist(p2, q, s, ls) <= tol);
            if !collinear && d.abs() > 1e-12 * lr * ls {
                let t = (q - p).perp_dot(s) / d;
                let u = (q - p).perp_dot(r) / d;
                let (et, eu) = (tol / lr, tol / ls);
                if t >= -et && t <= 1.0 + et && u >= -eu && u <= 1.0 + eu {
                    let id = snapper.snap(p + r * t.clamp(0.0, 1.0));
                    splits[i].push((t.clamp(0.0, 1.0), id));
                    splits[j].push((u.clamp(0.0, 1.0), id));
                }
            } else if collinear {
                // Collinear: each one's endpoints that lie on the other split it.
                for (x, id) in [(q, ends[j].0), (q2, ends[j].1)] {
                    let t = (x - p).dot(r) / (lr * lr);
                    if t > 0.0 && t < 1.0 {
                        splits[i].push((t, id));
                    }
                }
                for (x, id) in [(p, ends[i].0), (p2, ends[i].1)] {
                    let u = (x - q).dot(s) / (ls * ls);
                    if u > 0.0 && u < 1.0 {
                        splits[j].push((u, id));
                    }
                }
            }
        }
    }
    let mut seen: BTreeMap<(u32, u32), ()> = BTreeMap::new();
    let mut edges = Vec::new();
    for (i, mut sp) in splits.into_iter().enumerate() {
        sp.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        sp.dedup_by_key(|x| x.1);
        for w in sp.windows(2) {
            let (a, b) = (w[0].1, w[1].1);
            if a == b {
                continue;
            }
            if seen.insert((a.min(b), a.max(b)), ()).is_none() {
                edges.push((a, b, segments[i].2));
            }
        }
    }
    Arrangement {
        points: snapper.points,
        edges,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(a: (f64, f64), b: (f64, f64)) -> (DVec2, DVec2, u32) {
        (DVec2::new(a.0, a.1), DVec2::new(b.0, b.1), 0)
    }

    /// No two edges of an arrangement cross or overlap.
    fn assert_planar(arr: &Arrangement<u32>) {
        for (i, &(a, b, _)) in arr.edges.iter().enumerate() {
            for &(c, d, _) in &arr.edges[i + 1..] {
                let (p, p2, q, q2) = (
                    arr.points[a as usize],
                    arr.points[b as usize],
                    arr.points[c as usize],
                    arr.points[d as usize],
                );
                let shared = a == c || a == d || b == c || b == d;
                let o = |x: DVec2, y: DVec2, z: DVec2| (y - x).perp_dot(z - x);
                let proper = o(p, p2, q) * o(p, p2, q2) < 0.0 && o(q, q2, p) * o(q, q2, p2) < 0.0;
                assert!(shared || !proper, "edges {a}-{b} and {c}-{d} cross");
            }
        }
    }

    #[test]
    fn crossing_segments_are_split_at_their_intersection() {
        let arr = build(
            &[seg((0.0, 0.0), (2.0, 2.0)), seg((0.0, 2.0), (2.0, 0.0))],
            1e-9,
        );
        assert_eq!(arr.points.len(), 5);
        assert_eq!(arr.edges.len(), 4);
        assert!(arr.points.contains(&DVec2::new(1.0, 1.0)));
        assert_planar(&arr);
    }

    #[test]
    fn overlapping_and_t_junctions_merge() {
        let arr = build(
            &[
                seg((0.0, 0.0), (4.0, 0.0)),
                seg((1.0, 0.0), (3.0, 0.0)),    // overlap
                seg((2.0, 0.0), (2.0, 1.0)),    // T-junction
                seg((3.0, 1e-12), (3.0, -1.0)), // near-coincident endpoint
            ],
            1e-9,
        );
        // Points 0,1,2,3,4 on the axis plus (2,1) and (3,-1).
        assert_eq!(arr.points.len(), 7);
        // Axis pieces 0-1, 1-2, 2-3, 3-4, plus the two stems.
        assert_eq!(arr.edges.len(), 6);
        assert_planar(&arr);
    }

    #[test]
    fn spade_five_segment_repro_builds_a_planar_arrangement() {
        // The 5-segment case on which spade's add_constraint_and_split panics.
        let arr = build(
            &[
                seg((1.5, 0.5), (1.0, 4.0)),
                seg((1.0, 1.5), (3.5, 0.0)),
                seg((1.0, 3.0), (1.5, 2.5)),
                seg((0.0, 0.0), (2.5, 1.5)),
                seg((0.5, 0.0), (1.5, 3.0)),
            ],
            1e-9,
        );
        assert_planar(&arr);
    }
}
