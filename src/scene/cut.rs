//! Cutting triangles that are too long for one lightmap page.
//!
//! With a fixed texel density, every chart must fit on one atlas page, and a chart is at least
//! one triangle: a town's ground, one quad 400 m wide, is 3 200 texels wide at 8 texels per
//! metre, wider than a 2048 page. [`cut_long_edges`] splits every edge longer than a length by
//! conforming longest-edge bisection (Rivara, "Algorithms for refining triangular grids suitable
//! for adaptive and multigrid techniques", 1984): an edge is marked when it is too long, a
//! triangle with a marked edge also marks its longest edge, and each triangle is split by its
//! marked edges (its longest first) at their midpoints; repeated until no edge is too long.
//!
//! Conforming: marks belong to edges by their welded positions, and an edge's midpoint is
//! `(p + q) / 2`, the same bits from either side, so two triangles sharing an edge split it at
//! the same point and no T-junction appears (also across attribute seams, where the glTF
//! vertices differ but the positions agree). Bisection keeps the angles bounded below by half
//! the smallest angle of the input (Rivara).
//!
//! The new vertices are recorded as [`Derived`] weights over the primitive's own glTF vertices,
//! so the writer can interpolate every attribute (normals, UVs, colours, tangents) onto them.

use super::{Derived, Instance, Scene, Side};
use glam::DVec3;
use std::collections::{BTreeMap, BTreeSet};

/// What [`cut_long_edges`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Cut {
    /// Input triangles that were split.
    pub triangles_cut: usize,
    /// Triangles the split ones became.
    pub pieces: usize,
    /// Vertices added.
    pub vertices_added: usize,
}

/// Splits every triangle edge of the scene longer than `max_edge` (scene units) by conforming
/// longest-edge bisection, then rebuilds the scene's triangles and polygons. Edges end up
/// between `max_edge / 2` and `max_edge` long. A scene with no edge that long is left untouched
/// (same triangles, same order). Degenerate triangles are split like any other when a
/// neighbour's edge asks for it.
pub(crate) fn cut_long_edges(scene: &mut Scene, max_edge: f64) -> Cut {
    let mut cut = Cut::default();
    if !(max_edge > 0.0 && max_edge.is_finite()) {
        return cut;
    }
    let too_long = |inst: &Instance| {
        inst.indices.chunks_exact(3).any(|t| {
            (0..3).any(|e| {
                let (a, b) = (t[e] as usize, t[(e + 1) % 3] as usize);
                inst.positions_world[a].distance(inst.positions_world[b]) > max_edge
            })
        })
    };
    if !scene.instances.iter().any(too_long) {
        return cut;
    }
    let mut instances = std::mem::take(&mut scene.instances);
    let materials: Vec<usize> = instances.iter().map(|inst| inst.material).collect();
    scene.triangles.clear();
    scene.polygons.clear();
    // Input triangles split, per instance.
    let mut split = vec![0; instances.len()];
    for i in 0..instances.len() {
        if !too_long(&instances[i]) {
            continue;
        }
        let before = instances[i].indices.len() / 3;
        let vertices = instances[i].positions_world.len();
        // The back side of a double-sided primitive is cut as its front was (right before
        // it), reversed: the two sides stay triangle-for-triangle twins.
        let (front, inst) = instances.split_at_mut(i);
        let inst = &mut inst[0];
        let twin = front.last().filter(|f| {
            inst.side == Side::Back
                && f.side == Side::Front
                && (f.node, f.mesh, f.primitive) == (inst.node, inst.mesh, inst.primitive)
        });
        split[i] = match twin {
            Some(f) => {
                *inst = f.back_side();
                split[i - 1]
            }
            None => bisect(inst, max_edge),
        };
        cut.triangles_cut += split[i];
        cut.pieces += inst.indices.len() / 3 - (before - split[i]);
        cut.vertices_added += inst.positions_world.len() - vertices;
    }
    for (inst, material) in instances.into_iter().zip(materials) {
        scene.add_instance(inst, material);
    }
    cut
}

/// About how many triangles [`cut_long_edges`] makes of the triangles it cuts: their area over
/// that of a piece (bisection leaves pieces with edges of `max_edge / 2` to `max_edge`, of
/// area at least about `max_edge² / 8`). Cheap: to refuse a cut before making it.
pub(crate) fn estimate_pieces(scene: &Scene, max_edge: f64) -> usize {
    let piece = max_edge * max_edge / 8.0;
    scene
        .triangles
        .iter()
        .filter(|t| (0..3).any(|e| t.p[e].distance(t.p[(e + 1) % 3]) > max_edge))
        .map(|t| (t.area() / piece).ceil().max(2.0))
        .sum::<f64>() as usize
}

/// A position's exact bits: edges are keyed by their welded end points.
type Key = [u64; 3];

fn key(p: DVec3) -> Key {
    [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
}

fn edge_key(p: DVec3, q: DVec3) -> (Key, Key) {
    let (a, b) = (key(p), key(q));
    if a <= b { (a, b) } else { (b, a) }
}

/// Bisects `inst`'s triangles until no edge is longer than `max_edge`; returns how many of the
/// input triangles were split. Triangle `k`'s pieces replace it in place (order kept otherwise).
fn bisect(inst: &mut Instance, max_edge: f64) -> usize {
    let source_vertices = inst.positions_world.len() - inst.derived.len();
    // Per input triangle, its current pieces.
    let mut pieces: Vec<Vec<[u32; 3]>> = inst
        .indices
        .chunks_exact(3)
        .map(|t| vec![[t[0], t[1], t[2]]])
        .collect();
    // Midpoint vertex of each (index, index) edge already split.
    let mut midpoints: BTreeMap<(u32, u32), u32> = BTreeMap::new();
    loop {
        let pos = &inst.positions_world;
        let len = |a: u32, b: u32| pos[a as usize].distance(pos[b as usize]);
        // Longest edge of a triangle: 0 = (t0, t1), 1 = (t1, t2), 2 = (t2, t0); ties to the
        // lowest, so the choice is deterministic.
        let longest = |t: &[u32; 3]| {
            let l = [len(t[0], t[1]), len(t[1], t[2]), len(t[2], t[0])];
            let mut e = 0;
            for i in 1..3 {
                if l[i] > l[e] {
                    e = i;
                }
            }
            e
        };
        let mut marked: BTreeSet<(Key, Key)> = BTreeSet::new();
        for t in pieces.iter().flatten() {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                if len(a, b) > max_edge {
                    marked.insert(edge_key(pos[a as usize], pos[b as usize]));
                }
            }
        }
        if marked.is_empty() {
            break;
        }
        // Closure: a triangle with a marked edge marks its longest edge too.
        let is_marked = |marked: &BTreeSet<(Key, Key)>, t: &[u32; 3], e: usize| {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            marked.contains(&edge_key(pos[a as usize], pos[b as usize]))
        };
        loop {
            let mut added = false;
            for t in pieces.iter().flatten() {
                if (0..3).any(|e| is_marked(&marked, t, e)) {
                    let e = longest(t);
                    let (a, b) = (t[e], t[(e + 1) % 3]);
                    added |= marked.insert(edge_key(pos[a as usize], pos[b as usize]));
                }
            }
            if !added {
                break;
            }
        }
        // Split every triangle by its marked edges, the longest first.
        // Per piece: its corners, its longest edge, which of its edges are marked.
        type Plan = ([u32; 3], usize, [bool; 3]);
        let plan: Vec<Vec<Plan>> = pieces
            .iter()
            .map(|ts| {
                ts.iter()
                    .map(|t| (*t, longest(t), [0, 1, 2].map(|e| is_marked(&marked, t, e))))
                    .collect()
            })
            .collect();
        for (k, ts) in plan.into_iter().enumerate() {
            let mut out = Vec::with_capacity(ts.len() * 2);
            for (t, e, m) in ts {
                if !m[e] {
                    out.push(t);
                    continue;
                }
                // Rotate so the longest edge is (a, b), opposite c.
                let (a, b, c) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
                let (m_bc, m_ca) = (m[(e + 1) % 3], m[(e + 2) % 3]);
                let mid = |x: u32, y: u32, inst: &mut Instance, mids: &mut BTreeMap<_, _>| {
                    midpoint(inst, mids, source_vertices, x, y)
                };
                let ab = mid(a, b, inst, &mut midpoints);
                match m_ca {
                    false => out.push([a, ab, c]),
                    true => {
                        let ca = mid(c, a, inst, &mut midpoints);
                        out.push([a, ab, ca]);
                        out.push([ca, ab, c]);
                    }
                }
                match m_bc {
                    false => out.push([ab, b, c]),
                    true => {
                        let bc = mid(b, c, inst, &mut midpoints);
                        out.push([ab, b, bc]);
                        out.push([ab, bc, c]);
                    }
                }
            }
            pieces[k] = out;
        }
    }
    let split = pieces.iter().filter(|p| p.len() > 1).count();
    if let Some(emission) = &mut inst.emission {
        // Each piece emits as the triangle it came from.
        *emission = pieces
            .iter()
            .zip(emission.iter())
            .flat_map(|(p, &r)| std::iter::repeat_n(r, p.len()))
            .collect();
    }
    inst.indices = pieces.into_iter().flatten().flatten().collect();
    split
}

/// The vertex at the middle of edge (`a`, `b`), added on first use. Its position is
/// `(p_a + p_b) / 2` (the same bits for (`b`, `a`)); its weights are the mean of its ends'.
fn midpoint(
    inst: &mut Instance,
    mids: &mut BTreeMap<(u32, u32), u32>,
    source_vertices: usize,
    a: u32,
    b: u32,
) -> u32 {
    let edge = (a.min(b), a.max(b));
    if let Some(&m) = mids.get(&edge) {
        return m;
    }
    let weights = |v: u32| -> Vec<(u32, f64)> {
        if (v as usize) < source_vertices {
            vec![(v, 1.0)]
        } else {
            inst.derived[v as usize - source_vertices].weights.clone()
        }
    };
    let mut w: BTreeMap<u32, f64> = BTreeMap::new();
    for (v, x) in weights(a).into_iter().chain(weights(b)) {
        *w.entry(v).or_default() += 0.5 * x;
    }
    let p = (inst.positions_world[a as usize] + inst.positions_world[b as usize]) * 0.5;
    let m = inst.positions_world.len() as u32;
    inst.positions_world.push(p);
    inst.derived.push(Derived {
        weights: w.into_iter().collect(),
    });
    mids.insert(edge, m);
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// A `w` x `d` rectangle at y = 0 as two triangles, plus a small triangle sharing the long
    /// diagonal's end, in one instance; vertex 4 duplicates vertex 2's position (an attribute
    /// seam) and is used by the second triangle.
    fn scene(w: f64, d: f64) -> Scene {
        let mut s = Scene::default();
        s.materials.push(crate::scene::Material {
            name: "m".into(),
            rho: DVec3::splat(0.5),
            radiance: DVec3::ZERO,
            base: None,
        });
        let p = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(0.0, 0.0, d),
            DVec3::new(w, 0.0, d),
            DVec3::new(w, 0.0, 0.0),
            DVec3::new(w, 0.0, d),
        ];
        s.add_instance(Instance::new(p, vec![0, 1, 2, 0, 4, 3]), 0);
        s
    }

    fn edges_of(s: &Scene) -> BTreeMap<(Key, Key), usize> {
        let mut e = BTreeMap::new();
        for t in &s.triangles {
            for i in 0..3 {
                *e.entry(edge_key(t.p[i], t.p[(i + 1) % 3])).or_default() += 1;
            }
        }
        e
    }

    #[test]
    fn nothing_long_is_untouched() {
        let mut s = scene(4.0, 3.0);
        let before = s.triangles.len();
        assert_eq!(cut_long_edges(&mut s, 5.0), Cut::default());
        assert_eq!(s.triangles.len(), before);
        assert!(s.instances[0].derived.is_empty());
    }

    #[test]
    fn long_edges_are_cut_conforming_and_the_area_kept() {
        let mut s = scene(40.0, 30.0);
        let area: f64 = s.triangles.iter().map(|t| t.area()).sum();
        let cut = cut_long_edges(&mut s, 7.0);
        assert_eq!(cut.triangles_cut, 2);
        assert!(cut.pieces > 16, "{cut:?}");
        let after: f64 = s.triangles.iter().map(|t| t.area()).sum();
        assert!((after - area).abs() < 1e-9 * area);
        for t in &s.triangles {
            assert!(t.area() > 0.0);
            assert!(t.normal.dot(DVec3::Y) > 0.999_999, "winding kept");
            for i in 0..3 {
                let l = t.p[i].distance(t.p[(i + 1) % 3]);
                assert!(l <= 7.0 + 1e-12, "edge {l}");
            }
        }
        // Conforming: every edge is used twice (inside) or once (on the rectangle's outline),
        // so no vertex lies inside another triangle's edge.
        let outline = |e: &(Key, Key)| {
            let (p, q) = (e.0.map(f64::from_bits), e.1.map(f64::from_bits));
            (0..3)
                .step_by(2)
                .any(|c| p[c] == q[c] && (p[c] == 0.0 || p[c] == if c == 0 { 40.0 } else { 30.0 }))
        };
        for (e, n) in edges_of(&s) {
            assert_eq!(n, if outline(&e) { 1 } else { 2 }, "{e:?}");
        }
        // One polygon still: the pieces are welded across the attribute seam.
        assert_eq!(s.polygons.len(), 1);
        assert!((s.polygons[0].area - area).abs() < 1e-9 * area);
    }

    #[test]
    fn new_vertices_are_weighted_means_of_the_source_vertices() {
        let mut s = scene(40.0, 30.0);
        cut_long_edges(&mut s, 7.0);
        let inst = &s.instances[0];
        let source = inst.positions_world.len() - inst.derived.len();
        assert_eq!(source, 5);
        for (i, d) in inst.derived.iter().enumerate() {
            let sum: f64 = d.weights.iter().map(|w| w.1).sum();
            assert!((sum - 1.0).abs() < 1e-12);
            assert!(d.weights.len() <= 3 && d.weights.iter().all(|w| w.1 > 0.0));
            let p: DVec3 = d
                .weights
                .iter()
                .map(|&(v, w)| inst.positions_world[v as usize] * w)
                .sum();
            assert!(p.distance(inst.positions_world[source + i]) < 1e-9);
        }
        // The two sides of the attribute seam (vertices 2 and 4) weight their own vertex.
        let on = |v: u32| {
            inst.derived
                .iter()
                .any(|d| d.weights.iter().any(|w| w.0 == v))
        };
        assert!(on(2) && on(4));
    }
}
