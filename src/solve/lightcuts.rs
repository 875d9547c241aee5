//! Many area emitters: a light tree, and per receiving point a *cut* through it that says which
//! emitters the exact direct light must evaluate and which it may bound (Walter, Fernandez,
//! Arbree, Bala, Donikian, Greenberg, "Lightcuts: a scalable approach to illumination",
//! SIGGRAPH 2005).
//!
//! # Tree
//!
//! A binary tree over the area emitters, split at the median emitter centre along the longest
//! axis of their bounding box. Each node stores its emitters' bounding box (of their hulls),
//! their summed `L A` (radiance times area, W/sr per RGB channel), the `L A`-weighted sum of their
//! normals, and a representative: its brightest emitter.
//!
//! # Cut
//!
//! For a point `(p, n)`, a node's contribution to the irradiance is bounded by
//! `L A · cos_r · cos_e / d²` (`L A` its summed radiance × area, channel mean), with `d` the
//! distance from `p` to the node's box and the cosine bounds of Lightcuts (Walter et al. 2005,
//! section 4.1):
//!
//! * `cos_r`, the receiver cosine: the largest `n · (q − p) / |q − p|` over the box. The box's
//!   corners go to a frame with `n` as `z`; over their bounding box there `z / |(x, y, z)|` is
//!   largest at the largest `z` and the smallest `|x|` and `|y|`. Zero when the whole box is
//!   below the point's horizon.
//! * `cos_e`, the emitter cosine, when the node's emitters share one normal `N`: the same bound
//!   of `−N · (q − p) / |q − p|`. Zero when the point is behind all of them; 1 for mixed normals.
//!
//! This is a true bound of the emitters' unoccluded irradiance at any distance, near ones
//! included: each emitter gives `L ∫ cos_r⁺(q) cos_e⁺(q) / |q − p|² dq` over its polygon (the
//! exact evaluation, `π L F`), every `q` lies in the box, so each factor of the integrand is at
//! most its bound (`1 / |q − p|² ≤ 1 / d²`), and the areas sum to `A` (a unit test checks it
//! against the form factors near, far and inside the boxes). With `p` in the box (`d = 0`) the
//! bound is infinite and the node is refined.
//!
//! A node's *estimate* treats it as one small Lambertian source at its `L A`-weighted centre
//! with the weighted normal sum: `(n · ω)⁺ (−ω · N)⁺ / d²` (W/m², unoccluded, at most the
//! bound). Starting at the root, the node of largest bound is refined while that bound exceeds
//! [`EPSILON`] times the cut's total estimate (the Lightcuts rule, with unoccluded estimates,
//! so no ray is cast while cutting; `--light-error` sets the fraction). Then:
//!
//! * a node of the final cut whose bound exceeds that limit is a single emitter: it gets the
//!   exact, occluded evaluation ([`super::direct`]);
//! * every other node is *bounded*: its estimate times the visibility of one shadow ray to its
//!   representative's centre. Its error is at most its bound, below [`EPSILON`] of the total;
//!   the point's error is at most the sum of its bounded nodes' bounds. With the cosines the
//!   bounds are close to the contributions, so the error is of the order of [`EPSILON`]
//!   (bounds of `L A / d²` alone, without the cosines, are looser: the error is then about a
//!   hundred times smaller, at many more exact evaluations; a smaller `--light-error` buys the
//!   same accuracy).
//!
//! With one emitter, or where every emitter matters, every emitter is evaluated exactly.

use crate::geometry::box_corners;
use crate::light::{AreaEmitter, SurfacePoint};
use crate::visibility::Visibility;
use glam::DVec3;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// The default of [`super::SolveOptions::light_error`]: a node of the cut is refined while its
/// bound exceeds this fraction of the cut's estimated total irradiance (dimensionless).
pub const EPSILON: f64 = 0.02;

/// A node of the light tree.
#[derive(Clone, Debug)]
struct Node {
    /// Children, or `None` for a single emitter.
    kids: Option<[u32; 2]>,
    /// The emitter of a leaf, else the representative (brightest) emitter.
    emitter: u32,
    min: DVec3,
    max: DVec3,
    /// Summed radiance × area, W/sr per channel.
    power: DVec3,
    /// Mean of `power` over the channels.
    scalar: f64,
    /// `L A`-weighted centre of the emitters.
    center: DVec3,
    /// `Σ (L A)_scalar n`: the weighted normal sum (its length is at most `scalar`).
    normal: DVec3,
    /// The unit normal shared by all the node's emitters, if they share one.
    facing: Option<DVec3>,
}

/// The light tree of a scene's area emitters.
#[derive(Clone, Debug, Default)]
pub(crate) struct LightTree {
    nodes: Vec<Node>,
}

/// What the cut of one point decided.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Cut {
    /// Emitters (indices into the emitter list) to evaluate exactly.
    pub(crate) exact: Vec<u32>,
    /// The bounded nodes' contribution, W/m² per channel (with their shadow rays).
    pub(crate) bounded: DVec3,
    /// Its light vector ([`crate::light::LightVector`]), each node's light taken to come from
    /// its representative emitter's centre.
    pub(crate) bounded_light: crate::light::LightVector,
    /// Bounded nodes.
    pub(crate) bounded_nodes: u64,
    /// Shadow rays of the bounded nodes.
    pub(crate) rays: u64,
}

/// A node in the cut, ordered by its bound.
struct Entry {
    bound: f64,
    estimate: f64,
    node: u32,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        // Largest bound first; ties by node id, so the order never depends on the heap.
        self.bound
            .total_cmp(&other.bound)
            .then(other.node.cmp(&self.node))
    }
}

/// An upper bound of the cosine between `axis` (unit) and the direction from `p` to any point
/// of the box `[min, max]`, clamped to `[0, 1]`: the box's corners in a frame with `axis` as
/// `z`, their bounding box there, and `z / |(x, y, z)|` at its largest `z` and its smallest
/// `|x|` and `|y|` (Walter et al. 2005, section 4.1). `z / |(x, y, z)|` grows with `z` where
/// `z > 0` and falls with `|x|` and `|y|`, and the rotated box holds the box, so no point of it
/// has a larger cosine. Zero when the whole box is at or below the plane through `p` normal to
/// `axis`.
fn max_cosine(axis: DVec3, min: DVec3, max: DVec3, p: DVec3) -> f64 {
    let (t, b) = axis.any_orthonormal_pair();
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for q in box_corners(min, max) {
        let r = q - p;
        let v = DVec3::new(t.dot(r), b.dot(r), axis.dot(r));
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if hi.z <= 0.0 {
        return 0.0;
    }
    // The smallest square over `[lo, hi]`: zero when it holds 0.
    let least = |lo: f64, hi: f64| {
        if lo > 0.0 {
            lo * lo
        } else if hi < 0.0 {
            hi * hi
        } else {
            0.0
        }
    };
    let xy = least(lo.x, hi.x) + least(lo.y, hi.y);
    (hi.z / (xy + hi.z * hi.z).sqrt()).min(1.0)
}

impl LightTree {
    /// The tree over `emitters` (empty when there are none).
    pub(crate) fn new(emitters: &[AreaEmitter]) -> LightTree {
        let mut tree = LightTree { nodes: Vec::new() };
        if !emitters.is_empty() {
            let mut ids: Vec<u32> = (0..emitters.len() as u32).collect();
            tree.build(emitters, &mut ids);
        }
        tree
    }

    /// Number of nodes.
    pub(crate) fn len(&self) -> usize {
        self.nodes.len()
    }

    fn build(&mut self, emitters: &[AreaEmitter], ids: &mut [u32]) -> u32 {
        if let [only] = ids {
            let e = &emitters[*only as usize];
            let hull = e.shape.hull_world();
            let (min, max) = hull
                .iter()
                .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), q| {
                    (lo.min(*q), hi.max(*q))
                });
            let area: f64 = e.triangles.iter().map(crate::geometry::triangle_area).sum();
            let power = e.radiance * area;
            let scalar = power.element_sum() / 3.0;
            self.nodes.push(Node {
                kids: None,
                emitter: *only,
                min,
                max,
                power,
                scalar,
                center: e.center,
                normal: e.normal * scalar,
                facing: Some(e.normal),
            });
            return (self.nodes.len() - 1) as u32;
        }
        let (lo, hi) = ids
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), &i| {
                let c = emitters[i as usize].center;
                (lo.min(c), hi.max(c))
            });
        let ext = hi - lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        ids.sort_by(|&a, &b| {
            emitters[a as usize].center[axis]
                .total_cmp(&emitters[b as usize].center[axis])
                .then(a.cmp(&b))
        });
        let mid = ids.len() / 2;
        let (l, r) = ids.split_at_mut(mid);
        let a = self.build(emitters, l);
        let b = self.build(emitters, r);
        let (na, nb) = (&self.nodes[a as usize], &self.nodes[b as usize]);
        let scalar = na.scalar + nb.scalar;
        let w = if scalar > 0.0 {
            na.scalar / scalar
        } else {
            0.5
        };
        let node = Node {
            kids: Some([a, b]),
            emitter: if na.scalar >= nb.scalar {
                na.emitter
            } else {
                nb.emitter
            },
            min: na.min.min(nb.min),
            max: na.max.max(nb.max),
            power: na.power + nb.power,
            scalar,
            center: na.center * w + nb.center * (1.0 - w),
            normal: na.normal + nb.normal,
            facing: match (na.facing, nb.facing) {
                (Some(a), Some(b)) if a.dot(b) >= 1.0 - 1e-12 => Some(a),
                _ => None,
            },
        };
        self.nodes.push(node);
        (self.nodes.len() - 1) as u32
    }

    /// The bound and the unoccluded estimate of node `i` at `(p, n)` (W/m², channel mean).
    fn bound_and_estimate(&self, i: u32, p: DVec3, n: DVec3) -> (f64, f64) {
        let node = &self.nodes[i as usize];
        if node.scalar <= 0.0 {
            return (0.0, 0.0);
        }
        // The receiver cosine over the box (zero when it is all below the point's horizon),
        // times the emitter cosine when the emitters share a normal (zero when the point is
        // behind all of them).
        let cos_r = max_cosine(n, node.min, node.max, p);
        let cos = match node.facing {
            Some(f) if cos_r > 0.0 => cos_r * max_cosine(-f, node.min, node.max, p),
            _ => cos_r,
        };
        if cos <= 0.0 {
            return (0.0, 0.0);
        }
        let nearest = p.clamp(node.min, node.max);
        let d2 = p.distance_squared(nearest);
        let bound = if d2 > 0.0 {
            node.scalar * cos / d2
        } else {
            f64::INFINITY
        };
        let to = node.center - p;
        let l2 = to.length_squared();
        let estimate = if l2 > 0.0 {
            let w = to / l2.sqrt();
            (n.dot(w).max(0.0) * (-w.dot(node.normal)).max(0.0) / l2).min(bound)
        } else {
            0.0
        };
        (bound, estimate)
    }

    /// The cut of the point `at` (see the module doc): which emitters to evaluate exactly, and
    /// the bounded rest (one shadow ray each).
    /// `epsilon`: [`super::SolveOptions::light_error`].
    pub(crate) fn cut(
        &self,
        emitters: &[AreaEmitter],
        vis: &Visibility,
        at: &SurfacePoint,
        epsilon: f64,
    ) -> Cut {
        let mut out = Cut::default();
        let p = at.p;
        let done = self.traverse(at.p, at.n, epsilon, &mut out.exact);
        for e in done {
            let node = &self.nodes[e.node as usize];
            if e.estimate <= 0.0 {
                continue;
            }
            out.bounded_nodes += 1;
            out.rays += 1;
            let target = emitters[node.emitter as usize].center;
            if !vis.occluded(at.ray_origin, target) {
                let h = node.power * (e.estimate / node.scalar);
                out.bounded += h;
                let u = crate::light::slant((target - p).normalize_or_zero(), at.n);
                crate::light::add_light(&mut out.bounded_light, h, u);
            }
        }
        out.exact.sort_unstable();
        out
    }

    /// The unoccluded irradiance at `(p, n)` (W/m² per channel) as [`LightTree::cut`] divides
    /// it: the exact form factor of each emitter it evaluates, each bounded node's estimate.
    /// Where nothing occludes, the same as the cut's total with its exact evaluations.
    pub(crate) fn unoccluded(
        &self,
        emitters: &[AreaEmitter],
        p: DVec3,
        n: DVec3,
        epsilon: f64,
    ) -> DVec3 {
        let mut exact = Vec::new();
        let done = self.traverse(p, n, epsilon, &mut exact);
        exact.sort_unstable();
        let mut h: DVec3 = exact
            .iter()
            .map(|&e| emitters[e as usize].irradiance(p, n))
            .sum();
        for e in done.iter().filter(|e| e.estimate > 0.0) {
            let node = &self.nodes[e.node as usize];
            h += node.power * (e.estimate / node.scalar);
        }
        h
    }

    /// Whether any emitter's box (of its hull) meets the box `[lo, hi]`.
    pub(crate) fn any_in_box(&self, lo: DVec3, hi: DVec3) -> bool {
        self.in_box(lo, hi, &mut |_| true)
    }

    /// The emitters (indices into the emitter list) whose boxes meet the box `[lo, hi]`, in
    /// `out` (cleared first), ascending.
    pub(crate) fn emitters_in_box(&self, lo: DVec3, hi: DVec3, out: &mut Vec<u32>) {
        out.clear();
        self.in_box(lo, hi, &mut |e| {
            out.push(e);
            false
        });
        out.sort_unstable();
    }

    /// Calls `found` with each emitter whose box meets `[lo, hi]` until it returns true;
    /// returns whether it did.
    fn in_box(&self, lo: DVec3, hi: DVec3, found: &mut dyn FnMut(u32) -> bool) -> bool {
        let Some(root) = self.nodes.len().checked_sub(1) else {
            return false;
        };
        let mut stack = vec![root as u32];
        while let Some(i) = stack.pop() {
            let node = &self.nodes[i as usize];
            if node.min.cmpgt(hi).any() || node.max.cmplt(lo).any() {
                continue;
            }
            match node.kids {
                Some(kids) => stack.extend(kids),
                None if found(node.emitter) => return true,
                None => {}
            }
        }
        false
    }

    /// Refines the cut from the root (see the module doc): the single emitters to evaluate
    /// exactly go into `exact`; returns the bounded nodes.
    fn traverse(&self, p: DVec3, n: DVec3, epsilon: f64, exact: &mut Vec<u32>) -> Vec<Entry> {
        let Some(root) = self.nodes.len().checked_sub(1) else {
            return Vec::new();
        };
        let mut heap = BinaryHeap::new();
        let (bound, estimate) = self.bound_and_estimate(root as u32, p, n);
        let mut total = estimate;
        heap.push(Entry {
            bound,
            estimate,
            node: root as u32,
        });
        let mut done = Vec::new();
        while let Some(top) = heap.pop() {
            if top.bound <= epsilon * total {
                done.push(top);
                done.extend(heap.drain());
                break;
            }
            match self.nodes[top.node as usize].kids {
                Some(kids) => {
                    total -= top.estimate;
                    for k in kids {
                        let (bound, estimate) = self.bound_and_estimate(k, p, n);
                        if bound > 0.0 {
                            total += estimate;
                            heap.push(Entry {
                                bound,
                                estimate,
                                node: k,
                            });
                        }
                    }
                }
                None => exact.push(self.nodes[top.node as usize].emitter),
            }
        }
        done
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::EmitterShape;
    use std::f64::consts::PI;

    /// A square emitter of side `s` centred at `c`, emitting along `normal`.
    fn square(c: DVec3, normal: DVec3, s: f64, radiance: f64) -> AreaEmitter {
        let (u, v) = normal.any_orthonormal_pair();
        let h = 0.5 * s;
        // Counter-clockwise seen from the front (`u x v = normal`).
        let corners = [
            c - u * h - v * h,
            c + u * h - v * h,
            c + u * h + v * h,
            c - u * h + v * h,
        ];
        let e = AreaEmitter {
            polygon: 0,
            radiance: DVec3::splat(radiance),
            normal,
            triangles: vec![
                [corners[0], corners[1], corners[2]],
                [corners[0], corners[2], corners[3]],
            ],
            shape: EmitterShape::convex(&corners),
            samples: Vec::new(),
            center: c,
        };
        assert!(e.shape.frame.n.dot(normal) > 0.99);
        e
    }

    /// The emitters under node `i`.
    fn leaves(tree: &LightTree, i: u32, out: &mut Vec<u32>) {
        let node = &tree.nodes[i as usize];
        match node.kids {
            Some([a, b]) => {
                leaves(tree, a, out);
                leaves(tree, b, out);
            }
            None => out.push(node.emitter),
        }
    }

    /// A fixed spread of values in `[-1, 1)` (the golden ratio's multiples).
    fn spread(k: usize) -> f64 {
        2.0 * (k as f64 * 0.618_033_988_749_895).fract() - 1.0
    }

    /// The bound of every node, with its cosine factors, is at least the unoccluded irradiance
    /// of its emitters (`π L F`, channel mean) at points far from, near to and inside the
    /// nodes' boxes, with normals in every direction.
    #[test]
    fn bound_holds_every_emitter_near_and_far() {
        let mut emitters = Vec::new();
        // A ceiling of panels facing down (shared normal), a wall of panels facing +x, and
        // some tilted ones.
        for i in 0..4 {
            for j in 0..4 {
                let c = DVec3::new(i as f64, 3.0, j as f64);
                emitters.push(square(c, DVec3::NEG_Y, 0.5, 1.0 + i as f64));
            }
        }
        for j in 0..4 {
            let c = DVec3::new(-1.0, 1.0 + 0.5 * j as f64, 1.5);
            emitters.push(square(c, DVec3::X, 0.8, 2.0));
        }
        for k in 0..6 {
            let n = DVec3::new(spread(3 * k), spread(3 * k + 1), spread(3 * k + 2) + 0.1);
            let c = DVec3::new(1.5 + spread(5 * k), 1.5, 1.5 + spread(7 * k));
            emitters.push(square(c, n.normalize(), 0.3, 3.0));
        }
        let tree = LightTree::new(&emitters);
        let mut checked = 0;
        for k in 0..2000 {
            let p = DVec3::new(
                1.5 + 3.0 * spread(11 * k + 1),
                1.5 + 2.0 * spread(11 * k + 2),
                1.5 + 3.0 * spread(11 * k + 3),
            );
            let n = DVec3::new(spread(13 * k + 4), spread(13 * k + 5), spread(13 * k + 6));
            if n.length_squared() < 1e-4 {
                continue;
            }
            let n = n.normalize();
            for i in 0..tree.len() as u32 {
                let (bound, estimate) = tree.bound_and_estimate(i, p, n);
                assert!(estimate <= bound, "{estimate} > {bound}");
                let mut ids = Vec::new();
                leaves(&tree, i, &mut ids);
                let exact: f64 = ids
                    .iter()
                    .map(|&e| {
                        let e = &emitters[e as usize];
                        PI * e.form_factor(p, n) * e.radiance.element_sum() / 3.0
                    })
                    .sum();
                assert!(
                    exact <= bound * (1.0 + 1e-9),
                    "node {i} at {p} {n}: {exact} > {bound}"
                );
                checked += (exact > 0.0) as usize;
            }
        }
        assert!(checked > 10_000, "{checked}");
    }

    /// The cosine bound: exact on the axis, zero below the plane, and above every corner's.
    #[test]
    fn max_cosine_bounds_the_box() {
        let (min, max) = (DVec3::new(-1.0, 2.0, -1.0), DVec3::new(1.0, 3.0, 1.0));
        assert_eq!(max_cosine(DVec3::Y, min, max, DVec3::ZERO), 1.0);
        assert_eq!(max_cosine(DVec3::NEG_Y, min, max, DVec3::ZERO), 0.0);
        let side = max_cosine(DVec3::X, min, max, DVec3::ZERO);
        let corner = box_corners(min, max)
            .iter()
            .map(|q| q.normalize().x)
            .fold(0.0, f64::max);
        assert!(side >= corner && side < 1.0, "{side} {corner}");
    }
}
