//! Emissive textures: only the lit parts of a surface emit.
//!
//! An emitter of the solvers has one radiance over a planar polygon (the exact direct light and
//! the discontinuity wedges need that). So a primitive whose `emissiveTexture` varies is split:
//! each triangle into `n x n` similar pieces (the same `n` over the primitive, so that shared
//! edges split alike and no T-junction appears), each emitting the texture's mean over it
//! (about a lookup per texel). `n` starts where a piece spans about [`TEXELS_PER_PIECE`] texels (at most
//! [`MAX_SPLIT`], and at most [`MAX_PIECES`] pieces over the primitive) and is halved while every piece stays within [`MERGE`] of the finer pieces
//! inside it, so a texture of a few large regions makes a few pieces. Then the dimmest pieces
//! that carry together at most [`DROPPED_POWER`] of the primitive's power (the soft edge of a
//! filtered texture) are turned off, and edge-connected pieces within [`MERGE`] of each other
//! emit their mean (the same power): a lit region is one emitter and a dark background none. A
//! texture that is the same over every piece splits nothing. The new vertices are [`Derived`]
//! ones, which the writer interpolates every attribute onto, as for [`super::cut`].
//!
//! Splitting rather than integrating the texture per receiving point keeps every emitter a
//! uniform polygon, so shadows, penumbrae and discontinuities follow the emitting region with
//! the exact methods unchanged; the price is more, smaller emitters (light cuts bound the far
//! ones).

use super::texture::{Image, TextureRef};
use super::{Derived, Instance};
use crate::geometry::triangle_grid;
use glam::{DVec2, DVec3};
use std::collections::BTreeMap;

/// Texels of the emissive texture along a piece's edge that the split aims for.
pub(crate) const TEXELS_PER_PIECE: f64 = 4.0;

/// The most pieces along a triangle's edge (`MAX_SPLIT²` pieces per triangle).
pub(crate) const MAX_SPLIT: usize = 16;

/// The most triangles a primitive's split may make: `n² x triangles` stays within it. A
/// finely tessellated emitter (a sphere of a thousand triangles) is not split at all: each of
/// its triangles already emits its own mean, and pieces smaller still would multiply the
/// emitters that every shadow and wedge test goes through for light that only a receiver
/// within a triangle's size of the surface could tell apart.
pub(crate) const MAX_PIECES: usize = 1024;

/// How far (a fraction of the brightest piece's radiance, per channel) an edge-connected
/// piece's radiance may be from its group's first piece's to join it ([`merge_similar`]).
pub(crate) const MERGE: f64 = 0.125;

/// The most power (a fraction of the primitive's) that its dimmest pieces may lose
/// ([`drop_dimmest`]).
pub(crate) const DROPPED_POWER: f64 = 0.01;

/// Points per piece side of the mean over a piece ([`triangle_grid`]): about one per texel
/// along its longest edge, at least `SAMPLES` and at most `MAX_SAMPLES` (past it, the lookups
/// read the mip level of their spacing).
const SAMPLES: usize = 4;
const MAX_SAMPLES: usize = 64;

/// How to split a primitive's triangles ([`plan`]): `n` pieces along each edge, and each
/// piece's radiance (W/(m² sr)), triangle by triangle.
#[derive(Clone, Debug)]
pub(crate) struct Plan {
    n: usize,
    values: Vec<DVec3>,
}

/// Splits `inst`'s triangles as `plan` says, giving it a radiance per triangle
/// ([`Instance::emission`]). Returns the triangles added.
pub(crate) fn apply(inst: &mut Instance, plan: &Plan) -> usize {
    let before = inst.indices.len() / 3;
    subdivide(inst, plan.n, &grid_pieces(plan.n));
    inst.emission = Some(plan.values.clone());
    inst.indices.len() / 3 - before
}

/// Where to split `inst`'s triangles so that each piece emits `texture`'s mean over it (times
/// `radiance`, W/(m² sr)); `None` when the texture's mean is the same over every piece or the
/// instance lacks the texture's UV set. It depends on the primitive's UVs alone (and, through
/// the pieces' areas, little on its placement): one plan serves every placement.
pub(crate) fn plan(
    inst: &Instance,
    radiance: DVec3,
    texture: &TextureRef,
    image: &Image,
) -> Option<Plan> {
    let uvs = inst.uvs.get(&texture.tex_coord)?;
    let uv = |v: u32| texture.apply(uvs[v as usize]);
    // Pieces per edge: the longest triangle edge in texels over the aim.
    let (w, h) = image.size();
    let texels = DVec2::new(w as f64, h as f64);
    let longest = inst
        .indices
        .chunks_exact(3)
        .flat_map(|t| (0..3).map(move |e| (t[e], t[(e + 1) % 3])))
        .map(|(a, b)| ((uv(a) - uv(b)) * texels).length())
        .fold(0.0, f64::max);
    let triangles = inst.indices.len() / 3;
    let most = ((MAX_PIECES / triangles.max(1)) as f64).sqrt() as usize;
    let finest =
        ((longest / TEXELS_PER_PIECE).ceil() as usize).clamp(1, MAX_SPLIT.min(most).max(1));
    // The texture's mean over every piece of every triangle, split n times.
    let means = |n: usize| -> Vec<DVec3> {
        let mean = |t: &[u32], piece: &[(usize, usize); 3]| -> DVec3 {
            let corners = piece.map(|(a, b)| {
                let (fa, fb) = (a as f64 / n as f64, b as f64 / n as f64);
                uv(t[0]) * (1.0 - fa - fb) + uv(t[1]) * fa + uv(t[2]) * fb
            });
            let area = 0.5
                * (corners[1] - corners[0])
                    .perp_dot(corners[2] - corners[0])
                    .abs();
            // About a point per texel along the longest edge (so the mean is the texture's
            // own, not blurred by a coarse mip level), within limits.
            let edge = (0..3)
                .map(|e| ((corners[e] - corners[(e + 1) % 3]) * texels).length())
                .fold(0.0, f64::max);
            let samples = (edge.ceil() as usize).clamp(SAMPLES, MAX_SAMPLES);
            let footprint = area.sqrt() / samples as f64;
            let points: Vec<DVec2> = triangle_grid(&corners, samples).collect();
            points
                .iter()
                .map(|&q| image.filtered(q, footprint, texture.wrap).0)
                .sum::<DVec3>()
                / points.len() as f64
                * radiance
        };
        let pieces = grid_pieces(n);
        inst.indices
            .chunks_exact(3)
            .flat_map(|t| pieces.iter().map(move |p| mean(t, p)))
            .collect()
    };
    let fine = means(finest);
    let top = fine.iter().map(|v| v.max_element()).fold(0.0, f64::max);
    if top <= 0.0 {
        return None;
    }
    // The coarsest split, halving from the finest, whose every piece is within MERGE of the
    // fine pieces inside it: a texture of a few large regions splits into a few pieces.
    let (mut n, mut values) = (finest, fine.clone());
    while n > 1 {
        let coarser = n / 2;
        let coarse = means(coarser);
        let parent = parents(finest, coarser);
        let (per_fine, per_coarse) = (finest * finest, coarser * coarser);
        let fits = fine.iter().enumerate().all(|(k, f)| {
            let (t, p) = (k / per_fine, k % per_fine);
            let c = coarse[t * per_coarse + parent[p]];
            (*f - c).abs().max_element() <= MERGE * top
        });
        if !fits {
            break;
        }
        (n, values) = (coarser, coarse);
    }
    let pieces = grid_pieces(n);
    drop_dimmest(
        &mut values,
        &inst.indices,
        &inst.positions_world,
        pieces.len(),
        n,
    );
    if values.iter().all(|v| *v == values[0]) {
        return None;
    }
    // Merged over the split triangles' edges (on a copy: the plan leaves `inst` as it is).
    let mut split = inst.clone();
    subdivide(&mut split, n, &pieces);
    merge_similar(&mut values, &split.indices, &split.positions_world, top);
    Some(Plan { n, values })
}

/// Gives each group of edge-connected emitting pieces whose radiance is within [`MERGE`] of
/// the brightest piece's from its first piece's the group's area-weighted mean radiance (the
/// same power), so that they become one emitter; dark pieces never join one. `indices` are
/// the split triangles, one per value.
fn merge_similar(values: &mut [DVec3], indices: &[u32], positions: &[DVec3], top: f64) {
    let mut edges: BTreeMap<(u32, u32), Vec<usize>> = BTreeMap::new();
    for (k, t) in indices.chunks_exact(3).enumerate() {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default().push(k);
        }
    }
    let area = |k: usize| {
        let p = [0, 1, 2].map(|e| positions[indices[3 * k + e] as usize]);
        crate::geometry::triangle_area(&p)
    };
    let close = |a: DVec3, b: DVec3| (a - b).abs().max_element() <= MERGE * top;
    let mut group = vec![usize::MAX; values.len()];
    for seed in 0..values.len() {
        if group[seed] != usize::MAX || values[seed] == DVec3::ZERO {
            continue;
        }
        let first = values[seed];
        let mut members = vec![seed];
        group[seed] = seed;
        let mut next = 0;
        while next < members.len() {
            let k = members[next];
            next += 1;
            let t = &indices[3 * k..3 * k + 3];
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                for &nb in &edges[&(a.min(b), a.max(b))] {
                    if group[nb] == usize::MAX
                        && values[nb] != DVec3::ZERO
                        && close(values[nb], first)
                    {
                        group[nb] = seed;
                        members.push(nb);
                    }
                }
            }
        }
        let (mut power, mut total) = (DVec3::ZERO, 0.0);
        for &k in &members {
            let a = area(k);
            power += values[k] * a;
            total += a;
        }
        if total > 0.0 {
            for &k in &members {
                values[k] = power / total;
            }
        }
    }
}

/// Turns off the dimmest pieces (by radiance, then in order) whose power together is at most
/// [`DROPPED_POWER`] of the primitive's: a filtered texture's soft edge would otherwise make a
/// row of tiny, faint emitters along every bright region, each with its own wedges.
fn drop_dimmest(
    values: &mut [DVec3],
    indices: &[u32],
    positions: &[DVec3],
    per_triangle: usize,
    n: usize,
) {
    // Every piece of a triangle has its area over n².
    let area = |k: usize| {
        let t = &indices[3 * (k / per_triangle)..];
        let p = [t[0], t[1], t[2]].map(|v| positions[v as usize]);
        crate::geometry::triangle_area(&p) / (n * n) as f64
    };
    let power: Vec<f64> = (0..values.len())
        .map(|k| values[k].element_sum() * area(k))
        .collect();
    let total: f64 = power.iter().sum();
    let mut order: Vec<usize> = (0..values.len()).filter(|&k| power[k] > 0.0).collect();
    order.sort_by(|&a, &b| {
        values[a]
            .element_sum()
            .total_cmp(&values[b].element_sum())
            .then(a.cmp(&b))
    });
    let mut dropped = 0.0;
    for k in order {
        dropped += power[k];
        if dropped > DROPPED_POWER * total {
            break;
        }
        values[k] = DVec3::ZERO;
    }
}

/// For each piece of a triangle split `fine` times, the index of the piece of its split
/// `coarse` times (`coarse <= fine`) that holds its centroid.
fn parents(fine: usize, coarse: usize) -> Vec<usize> {
    let index: BTreeMap<((usize, usize), bool), usize> = grid_pieces(coarse)
        .iter()
        .enumerate()
        .map(|(i, p)| ((p[0], p[1] == (p[0].0 + 1, p[0].1)), i))
        .collect();
    grid_pieces(fine)
        .iter()
        .map(|p| {
            let scale = coarse as f64 / fine as f64 / 3.0;
            let a = (p[0].0 + p[1].0 + p[2].0) as f64 * scale;
            let b = (p[0].1 + p[1].1 + p[2].1) as f64 * scale;
            let (a0, b0) = (a.floor(), b.floor());
            let up = (a - a0) + (b - b0) < 1.0;
            let corner = if up {
                (a0 as usize, b0 as usize)
            } else {
                (a0 as usize + 1, b0 as usize)
            };
            index[&(corner, up)]
        })
        .collect()
}

/// The `n²` pieces of a triangle split `n` times along each edge, as grid points `(a, b)`
/// (barycentric `(1 - a/n - b/n, a/n, b/n)`), counter-clockwise as the triangle is.
fn grid_pieces(n: usize) -> Vec<[(usize, usize); 3]> {
    let mut out = Vec::with_capacity(n * n);
    for a in 0..n {
        for b in 0..n - a {
            out.push([(a, b), (a + 1, b), (a, b + 1)]);
            if a + b + 1 < n {
                out.push([(a + 1, b), (a + 1, b + 1), (a, b + 1)]);
            }
        }
    }
    out
}

/// Replaces each triangle of `inst` by its `pieces` (of an `n`-fold split), in order, adding
/// the grid points as derived vertices: a point on an edge is shared by the two triangles of
/// the edge (found by the edge's glTF vertices), with the same position bits from either side.
fn subdivide(inst: &mut Instance, n: usize, pieces: &[[(usize, usize); 3]]) {
    debug_assert!(inst.derived.is_empty(), "split before any cut");
    let mut on_edge: BTreeMap<(u32, u32, usize), u32> = BTreeMap::new();
    let mut indices = Vec::with_capacity(inst.indices.len() * n * n);
    for k in 0..inst.indices.len() / 3 {
        let t = [
            inst.indices[3 * k],
            inst.indices[3 * k + 1],
            inst.indices[3 * k + 2],
        ];
        let mut interior: BTreeMap<(usize, usize), u32> = BTreeMap::new();
        let mut vertex = |(a, b): (usize, usize), inst: &mut Instance| -> u32 {
            let c = n - a - b;
            // Corners, then edge points (by the edge's two vertices, low first, and the step
            // from the low one), then interior points.
            let weights = [(t[0], c), (t[1], a), (t[2], b)];
            let nonzero: Vec<(u32, usize)> = weights.into_iter().filter(|w| w.1 > 0).collect();
            match nonzero.as_slice() {
                [(v, _)] => *v,
                [(v0, s0), (v1, s1)] => {
                    let (lo, hi, step) = if v0 < v1 {
                        (*v0, *v1, *s1)
                    } else {
                        (*v1, *v0, *s0)
                    };
                    *on_edge
                        .entry((lo, hi, step))
                        .or_insert_with(|| add(inst, &[(lo, n - step), (hi, step)], n))
                }
                _ => *interior
                    .entry((a, b))
                    .or_insert_with(|| add(inst, &nonzero, n)),
            }
        };
        for piece in pieces {
            for &p in piece {
                let v = vertex(p, inst);
                indices.push(v);
            }
        }
    }
    inst.indices = indices;
}

/// Adds the derived vertex with glTF-vertex weights `steps / n`; returns its index.
fn add(inst: &mut Instance, steps: &[(u32, usize)], n: usize) -> u32 {
    let mut weights: Vec<(u32, f64)> = steps
        .iter()
        .map(|&(v, s)| (v, s as f64 / n as f64))
        .collect();
    weights.sort_by_key(|w| w.0);
    let p = weights
        .iter()
        .map(|&(v, w)| inst.positions_world[v as usize] * w)
        .sum();
    inst.positions_world.push(p);
    inst.derived.push(Derived { weights });
    (inst.positions_world.len() - 1) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fine_piece_lies_in_its_coarse_parent() {
        let grid = |p: &[(usize, usize); 3], n: usize| {
            p.map(|(a, b)| DVec2::new(a as f64 / n as f64, b as f64 / n as f64))
        };
        for (fine, coarse) in [(16, 8), (8, 4), (9, 4), (5, 1), (7, 3)] {
            let coarse_pieces = grid_pieces(coarse);
            for (p, &parent) in grid_pieces(fine).iter().zip(&parents(fine, coarse)) {
                let t = grid(p, fine);
                let centroid = (t[0] + t[1] + t[2]) / 3.0;
                let c = grid(&coarse_pieces[parent], coarse);
                let b = crate::geometry::barycentric_2d(&c, centroid);
                assert!(b.iter().all(|&x| x > -1e-12), "{fine}->{coarse}: {p:?}");
            }
        }
    }

    #[test]
    fn a_split_triangle_is_covered_by_its_pieces_without_t_junctions() {
        for n in 1..=5 {
            let pieces = grid_pieces(n);
            assert_eq!(pieces.len(), n * n);
            // Twice the signed areas in grid units: each piece 1, all of them n².
            let area = |p: &[(usize, usize); 3]| {
                let q = p.map(|(a, b)| DVec2::new(a as f64, b as f64));
                (q[1] - q[0]).perp_dot(q[2] - q[0])
            };
            assert!(pieces.iter().all(|p| area(p) == 1.0));
        }
        // Two triangles sharing an edge (1, 2): its points are shared.
        let mut inst = Instance::new(
            vec![DVec3::ZERO, DVec3::X, DVec3::Z, DVec3::new(1.0, 0.0, 1.0)],
            vec![0, 2, 1, 1, 2, 3],
        );
        subdivide(&mut inst, 3, &grid_pieces(3));
        // 4 corners, 5 edges x 2 points, 1 interior point in each triangle.
        assert_eq!(inst.positions_world.len(), 4 + 10 + 2);
        assert_eq!(inst.indices.len(), 2 * 9 * 3);
        for d in &inst.derived {
            assert!((d.weights.iter().map(|w| w.1).sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    /// A 128x128 texture of random texels over the unit square: the 2-triangle quad splits to
    /// the finest level; the same square tessellated into 512 triangles, each spanning 8x8
    /// texels, is not split (each triangle emits its own mean): a split would exceed
    /// [`MAX_PIECES`].
    #[test]
    fn a_finely_tessellated_emitter_is_not_split_further() {
        let mut rng = crate::rng::SplitMix64(7);
        let texels = (0..128 * 128)
            .map(|_| {
                let v = (rng.next_u64() >> 56) as u8;
                [v, v, v, 255]
            })
            .collect();
        let image = Image::new(128, 128, texels).unwrap();
        let texture = TextureRef {
            image: 0,
            tex_coord: 0,
            wrap: [super::super::texture::Wrap::ClampToEdge; 2],
            transform: TextureRef::IDENTITY,
        };
        let square = |cells: usize| {
            let side = cells + 1;
            let at = |i: usize, j: usize| DVec2::new(i as f64, j as f64) / cells as f64;
            let positions = (0..side * side)
                .map(|k| at(k % side, k / side).extend(0.0))
                .collect();
            let mut indices = Vec::new();
            for j in 0..cells as u32 {
                for i in 0..cells as u32 {
                    let v = j * side as u32 + i;
                    let up = v + side as u32;
                    indices.extend([v, v + 1, up + 1, v, up + 1, up]);
                }
            }
            let mut inst = Instance::new(positions, indices);
            let uvs = (0..side * side).map(|k| at(k % side, k / side)).collect();
            inst.uvs.insert(0, uvs);
            inst
        };
        let quad = plan(&square(1), DVec3::ONE, &texture, &image).unwrap();
        assert_eq!(quad.n, MAX_SPLIT);
        let fine = square(16);
        let plan = plan(&fine, DVec3::ONE, &texture, &image).unwrap();
        assert_eq!(plan.n, 1);
        assert_eq!(plan.values.len(), fine.indices.len() / 3);
        assert!(plan.values.len() * plan.n * plan.n <= MAX_PIECES.max(fine.indices.len() / 3));
    }
}
