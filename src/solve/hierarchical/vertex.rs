//! The indirect irradiance at the mesh vertices from the elements' means.

use super::REGULARIZATION;
use crate::mesh::ReceiverMesh;
use glam::{DVec2, DVec3};

/// The indirect irradiance at every vertex of mesh `m` from its elements' `(triangle, area,
/// indirect irradiance)` (`None` at a vertex no element uses): the value at the vertex of the
/// linear function fitted, by area-weighted least squares, to the elements around it (an
/// element's mean of a linear function is its value at the centroid), kept within their values
/// widened by their spread on each side, and at least zero. The elements around a vertex are
/// those that use it, or, when their centroids leave the gradient's direction undetermined
/// (two triangles at a polygon's corner or edge, whose centroids lie along the edge), those
/// that share a vertex with them. See the `hierarchical` module doc.
pub(super) fn vertex_indirect(m: &ReceiverMesh, items: &[(u32, f64, DVec3)]) -> Vec<Option<DVec3>> {
    let nv = m.vertices.len();
    // Vertex -> its elements (indices into `items`), compressed rows.
    let mut start = vec![0u32; nv + 1];
    for &(t, _, _) in items {
        for &v in &m.triangles[t as usize] {
            start[v as usize + 1] += 1;
        }
    }
    for v in 0..nv {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut ring = vec![0u32; start[nv] as usize];
    for (i, &(t, _, _)) in items.iter().enumerate() {
        for &v in &m.triangles[t as usize] {
            ring[fill[v as usize] as usize] = i as u32;
            fill[v as usize] += 1;
        }
    }
    let ring = |v: u32| &ring[start[v as usize] as usize..start[v as usize + 1] as usize];
    let centroids: Vec<DVec2> = items
        .iter()
        .map(|&(t, _, _)| {
            let [a, b, c] = m.triangles[t as usize].map(|v| m.vertices[v as usize]);
            (a + b + c) / 3.0
        })
        .collect();
    let centroid = |i: u32| centroids[i as usize];
    // The fit over the elements `set` at `at`, and how well their centroids determine the
    // gradient (the second moment's smaller eigenvalue over its larger).
    let fit = |set: &[u32], at: DVec2| {
        let (mut w, mut c, mut mean) = (0.0, DVec2::ZERO, DVec3::ZERO);
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for &i in set {
            let (_, a, h) = items[i as usize];
            (lo, hi) = (lo.min(h), hi.max(h));
            w += a;
            c += centroid(i) * a;
            mean += h * a;
        }
        (c, mean) = (c / w, mean / w);
        let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
        let (mut bx, mut by) = (DVec3::ZERO, DVec3::ZERO);
        for &i in set {
            let (_, a, h) = items[i as usize];
            let d = centroid(i) - c;
            (sxx, sxy, syy) = (
                sxx + a * d.x * d.x,
                sxy + a * d.x * d.y,
                syy + a * d.y * d.y,
            );
            bx += (h - mean) * (a * d.x);
            by += (h - mean) * (a * d.y);
        }
        let (trace, det) = (sxx + syy, sxx * syy - sxy * sxy);
        let gap = (trace * trace - 4.0 * det).max(0.0).sqrt();
        let isotropy = if trace > 0.0 {
            (trace - gap) / (trace + gap)
        } else {
            0.0
        };
        // With the fit's Tikhonov term.
        let reg = REGULARIZATION * trace;
        let (sxx, syy) = (sxx + reg, syy + reg);
        let det = sxx * syy - sxy * sxy;
        if det.is_nan() || det <= 0.0 {
            return (mean, 0.0);
        }
        let d = at - c;
        let value =
            mean + (bx * syy - by * sxy) * (d.x / det) + (by * sxx - bx * sxy) * (d.y / det);
        let spread = hi - lo;
        (
            value.clamp(lo - spread, hi + spread).max(DVec3::ZERO),
            isotropy,
        )
    };
    let mut stamp = vec![u32::MAX; items.len()];
    let mut wide = Vec::new();
    let values = (0..nv as u32)
        .map(|v| {
            let near = ring(v);
            if near.is_empty() {
                return None;
            }
            let at = m.vertices[v as usize];
            let (value, isotropy) = fit(near, at);
            if isotropy >= WELL_SPREAD {
                return Some(value);
            }
            wide.clear();
            for &i in near {
                for &u in &m.triangles[items[i as usize].0 as usize] {
                    for &j in ring(u) {
                        if stamp[j as usize] != v {
                            stamp[j as usize] = v;
                            wide.push(j);
                        }
                    }
                }
            }
            Some(fit(&wide, at).0)
        })
        .collect::<Vec<_>>();
    // One correction step towards vertex values whose linear interpolation has each element's
    // mean: every vertex moves by the area-weighted mean of its elements' residuals.
    let residual: Vec<DVec3> = items
        .iter()
        .map(|&(t, _, h)| {
            let corners = m.triangles[t as usize].map(|v| values[v as usize].unwrap_or_default());
            h - (corners[0] + corners[1] + corners[2]) / 3.0
        })
        .collect();
    (0..nv as u32)
        .map(|v| {
            let near = ring(v);
            let (s, w) = near.iter().fold((DVec3::ZERO, 0.0), |(s, w), &i| {
                let a = items[i as usize].1;
                (s + residual[i as usize] * a, w + a)
            });
            values[v as usize].map(|x| (x + s / w).max(DVec3::ZERO))
        })
        .collect()
}

/// The least ratio of the smaller to the larger eigenvalue of the second moment of the
/// centroids around a vertex at which they determine the gradient for its value (see
/// `vertex_indirect`; dimensionless).
const WELL_SPREAD: f64 = 0.1;
