//! Emissive textures: only the lit parts of a surface emit.
//!
//! An emitter of the solvers has one radiance over a planar polygon (the exact direct light and
//! the discontinuity wedges need that). So a primitive whose `emissiveTexture` varies is split:
//! each triangle into `n x n` similar pieces (the same `n` over the primitive, so that shared
//! edges split alike and no T-junction appears), `n` chosen so a piece spans about
//! [`TEXELS_PER_PIECE`] texels (at most [`MAX_SPLIT`]). Each piece emits the texture's mean over
//! it (filtered lookups), rounded to [`LEVELS`] steps of the primitive's brightest piece, so
//! that neighbouring pieces of one level merge back into one polygon and a sign's dark
//! background does not emit at all. A texture that is the same over every piece splits
//! nothing. The new vertices are [`Derived`] ones, which the writer interpolates every
//! attribute onto, as for [`super::cut`].
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
pub const TEXELS_PER_PIECE: f64 = 4.0;

/// The most pieces along a triangle's edge (`MAX_SPLIT²` pieces per triangle).
pub const MAX_SPLIT: usize = 16;

/// Steps between no emission and the brightest piece's.
pub const LEVELS: f64 = 64.0;

/// Points per piece side of the mean over a piece ([`triangle_grid`]).
const SAMPLES: usize = 4;

/// Splits `inst`'s triangles where `texture` (times `radiance`, W/(m² sr)) changes, giving it a
/// radiance per triangle ([`Instance::emission`]); leaves it as it is when the texture's mean
/// is the same over every piece or the instance lacks the texture's UV set. Returns the
/// triangles added.
pub(crate) fn split(
    inst: &mut Instance,
    radiance: DVec3,
    texture: &TextureRef,
    image: &Image,
) -> usize {
    let Some(uvs) = inst.uvs.get(&texture.tex_coord) else {
        return 0;
    };
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
    let n = ((longest / TEXELS_PER_PIECE).ceil() as usize).clamp(1, MAX_SPLIT);
    // The pieces of every triangle, as barycentric grid points (a, b) of it.
    let pieces = grid_pieces(n);
    let mean = |t: &[u32], piece: &[(usize, usize); 3]| -> DVec3 {
        let corners = piece.map(|(a, b)| {
            let (fa, fb) = (a as f64 / n as f64, b as f64 / n as f64);
            uv(t[0]) * (1.0 - fa - fb) + uv(t[1]) * fa + uv(t[2]) * fb
        });
        let area = 0.5
            * (corners[1] - corners[0])
                .perp_dot(corners[2] - corners[0])
                .abs();
        let footprint = area.sqrt() / SAMPLES as f64;
        let points: Vec<DVec2> = triangle_grid(&corners, SAMPLES).collect();
        points
            .iter()
            .map(|&q| image.filtered(q, footprint, texture.wrap).0)
            .sum::<DVec3>()
            / points.len() as f64
            * radiance
    };
    let values: Vec<DVec3> = inst
        .indices
        .chunks_exact(3)
        .flat_map(|t| pieces.iter().map(move |p| (t, p)))
        .map(|(t, p)| mean(t, p))
        .collect();
    let top = values.iter().map(|v| v.max_element()).fold(0.0, f64::max);
    if top <= 0.0 {
        return 0;
    }
    let level = |v: DVec3| (v / top * LEVELS).round() / LEVELS * top;
    let values: Vec<DVec3> = values.into_iter().map(level).collect();
    if values.iter().all(|v| *v == values[0]) {
        return 0;
    }
    let before = inst.indices.len() / 3;
    subdivide(inst, n, &pieces);
    inst.emission = Some(values);
    inst.indices.len() / 3 - before
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
}
