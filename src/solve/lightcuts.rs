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
//! `Σ L A · cos_r · cos_e / d²` with both cosines at most 1, `cos_r` zero when the whole box is
//! below the point's horizon, `cos_e` zero when the node's emitters share one normal and the
//! point is behind all of them, and `d` the distance from `p` to the box. Its *estimate* treats
//! the node as one small Lambertian source at its `L A`-weighted centre with the weighted normal
//! sum: `(n · ω)⁺ (−ω · N)⁺ / d²` (W/m², unoccluded). Starting at the root, the node of largest
//! bound is refined while that bound exceeds [`EPSILON`] times the cut's total estimate (the
//! Lightcuts rule, with unoccluded estimates, so no ray is cast while cutting; `--light-error`
//! sets the fraction). Then:
//!
//! * a node of the final cut whose bound exceeds that limit is a single emitter: it gets the
//!   exact, occluded evaluation ([`super::direct`]);
//! * every other node is *bounded*: its estimate times the visibility of one shadow ray to its
//!   representative's centre. Its error is at most its bound, below [`EPSILON`] of the total.
//!
//! With one emitter, or where every emitter matters, everything is exact as before.

use crate::geometry::box_corners;
use crate::light::{AreaEmitter, SurfacePoint};
use crate::visibility::Visibility;
use glam::DVec3;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// The default of [`super::SolveOptions::light_error`]: a node of the cut is refined while its
/// bound exceeds this fraction of the cut's estimated total irradiance (dimensionless).
pub const EPSILON: f64 = 0.05;

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
pub struct LightTree {
    nodes: Vec<Node>,
}

/// What the cut of one point decided.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Cut {
    /// Emitters (indices into the emitter list) to evaluate exactly.
    pub exact: Vec<u32>,
    /// The bounded nodes' contribution, W/m² per channel (with their shadow rays).
    pub bounded: DVec3,
    /// Bounded nodes.
    pub bounded_nodes: u64,
    /// Shadow rays of the bounded nodes.
    pub rays: u64,
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

impl LightTree {
    /// The tree over `emitters` (empty when there are none).
    pub fn new(emitters: &[AreaEmitter]) -> LightTree {
        let mut tree = LightTree { nodes: Vec::new() };
        if !emitters.is_empty() {
            let mut ids: Vec<u32> = (0..emitters.len() as u32).collect();
            tree.build(emitters, &mut ids);
        }
        tree
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// True when there is no emitter.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
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
        let corners = box_corners(node.min, node.max);
        // Some of the box above the point's horizon, and the point in front of some emitter.
        let above = corners.iter().any(|q| n.dot(*q - p) > 0.0);
        let in_front = node
            .facing
            .is_none_or(|f| corners.iter().any(|q| f.dot(p - *q) > 0.0));
        if !above || !in_front || node.scalar <= 0.0 {
            return (0.0, 0.0);
        }
        let nearest = p.clamp(node.min, node.max);
        let d2 = p.distance_squared(nearest);
        let bound = if d2 > 0.0 {
            node.scalar / d2
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
    pub fn cut(
        &self,
        emitters: &[AreaEmitter],
        vis: &Visibility,
        at: &SurfacePoint,
        epsilon: f64,
    ) -> Cut {
        let mut out = Cut::default();
        let Some(root) = self.nodes.len().checked_sub(1) else {
            return out;
        };
        let (p, n) = (at.p, at.n);
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
                None => out.exact.push(self.nodes[top.node as usize].emitter),
            }
        }
        for e in done {
            let node = &self.nodes[e.node as usize];
            if e.estimate <= 0.0 {
                continue;
            }
            out.bounded_nodes += 1;
            out.rays += 1;
            let target = emitters[node.emitter as usize].center;
            if !vis.occluded(at.ray_origin, target) {
                out.bounded += node.power * (e.estimate / node.scalar);
            }
        }
        out.exact.sort_unstable();
        out
    }
}
