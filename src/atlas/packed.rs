//! What a packing produced: the charts' boxes on their pages, the density estimate they give,
//! and the checked copy of xatlas's output into [`AtlasMesh`]es.

use super::ffi::{Mesh, PackInfo, UNCHARTED};
use super::{Atlas, AtlasError, AtlasInput, AtlasMesh};

/// With a fixed page: `None` if everything is on one page, inside it and unscaled; else the factor
/// to multiply the texel density by before packing again.
pub(super) fn fixed_page_shrink(
    meshes: &[Mesh<'_>],
    boxes: &[ChartBox],
    info: &PackInfo,
    max_chart_size: u32,
) -> Option<f32> {
    if info.atlas_count > 1 {
        // The charts need about `atlas_count` pages' worth of area; shrink the side to match.
        return Some((0.97 / (info.atlas_count as f32).sqrt()).min(0.9));
    }
    let (w, h) = (info.width as f32, info.height as f32);
    let misplaced = meshes.iter().flat_map(|m| m.vertices).any(|v| {
        v.atlas_index != UNCHARTED
            && (v.atlas_index != 0
                || !(0.0..=w).contains(&v.uv[0])
                || !(0.0..=h).contains(&v.uv[1]))
    });
    // A chart that reached `max_chart_size` may have been scaled down by xatlas on its own.
    if misplaced || largest_side(boxes) > max_chart_size as f32 - 0.5 {
        return Some(0.9);
    }
    None
}

/// The largest side, in texels, of any of `boxes`.
pub(super) fn largest_side(boxes: &[ChartBox]) -> f32 {
    boxes
        .iter()
        .fold(0.0f32, |m, b| m.max(b.width).max(b.height))
}

/// A packed chart's UV bounding box: its page and its sides in texels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct ChartBox {
    pub(super) page: u32,
    pub(super) width: f32,
    pub(super) height: f32,
}

/// The UV bounding box of every chart of `meshes`, in their order.
pub(super) fn chart_boxes(meshes: &[Mesh<'_>]) -> Vec<ChartBox> {
    let mut boxes = Vec::new();
    for mesh in meshes {
        for chart in &mesh.charts {
            let mut lo = [f32::INFINITY; 2];
            let mut hi = [f32::NEG_INFINITY; 2];
            for &i in chart.indices {
                if let Some(v) = mesh.vertices.get(i as usize) {
                    for k in 0..2 {
                        lo[k] = lo[k].min(v.uv[k]);
                        hi[k] = hi[k].max(v.uv[k]);
                    }
                }
            }
            if lo[0] <= hi[0] && lo[1] <= hi[1] {
                boxes.push(ChartBox {
                    page: chart.atlas_index,
                    width: hi[0] - lo[0],
                    height: hi[1] - lo[1],
                });
            }
        }
    }
    boxes
}

/// The texels² the bit images of `boxes` take (see [`fitting_density`]).
pub(super) fn boxes_area<'a>(boxes: impl Iterator<Item = &'a ChartBox>, padding: u32) -> f64 {
    let e = 1.5 + f64::from(padding);
    boxes
        .map(|b| (f64::from(b.width) + e) * (f64::from(b.height) + e))
        .sum()
}

/// After a packing at density `tried` that did not fit one page: an estimate of the density at
/// which every chart fits on one page, given `full`, the bit-image area (texels²) a full page
/// holds; `None` if the padding alone would not fit.
///
/// xatlas places each chart as a bit image `ceil(extent) + 1 + padding` texels a side, so at
/// `s` times the density a chart of box `w × h` (texels at `tried`) takes about
/// `(w s + e)(h s + e)` texels² with `e = 1.5 + padding` (1.5: the `+ 1` and half a texel of
/// `ceil` on average). The estimate is the `s` at which all boxes together take `full` (a
/// quadratic in `s`). `full` is read off a packing: the sizing packing's utilization (every
/// box's area over the grown page's) times the page, or an overflowing packing's first page's
/// boxes. The guess is usually within a few per cent, so one to three packings follow it
/// (measured on the box grids, the towns and the interior; halving a bracket from a
/// `1/sqrt(pages)` guess takes five or six).
pub(super) fn fitting_density(
    boxes: &[ChartBox],
    tried: f32,
    padding: u32,
    full: f64,
) -> Option<f32> {
    let e = 1.5 + f64::from(padding);
    // Sum over all boxes of (w s + e)(h s + e) = a s² + b s + c, set equal to `full`.
    let (mut a, mut b) = (0.0, 0.0);
    for x in boxes {
        let (w, h) = (f64::from(x.width), f64::from(x.height));
        a += w * h;
        b += e * (w + h);
    }
    let c = boxes.len() as f64 * e * e - full;
    if full.is_nan() || full <= 0.0 || c >= 0.0 || a <= 0.0 {
        return None;
    }
    let s = (-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a);
    (s.is_finite() && s > 0.0).then_some((f64::from(tried) * s) as f32)
}

/// Copies xatlas's output meshes into [`AtlasMesh`]es in input order, checking them.
pub(super) fn collect_output(
    inputs: &[AtlasInput<'_>],
    added: &[usize],
    meshes: &[Mesh<'_>],
    info: &PackInfo,
    paged: bool,
) -> Result<Atlas, AtlasError> {
    let pages = if paged { info.atlas_count.max(1) } else { 1 };
    let mut out = vec![AtlasMesh::default(); inputs.len()];
    for (&m, mesh) in added.iter().zip(meshes) {
        let input = &inputs[m];
        let (width, height) = (info.width, info.height);
        for (vertex, v) in mesh.vertices.iter().enumerate() {
            if v.atlas_index != UNCHARTED && v.atlas_index >= pages {
                return Err(AtlasError::NotOnePage {
                    mesh: m,
                    vertex,
                    page: v.atlas_index,
                });
            }
            let [u, vv] = v.uv;
            if !(0.0..=width as f32).contains(&u) || !(0.0..=height as f32).contains(&vv) {
                return Err(AtlasError::OutOfBounds {
                    mesh: m,
                    vertex,
                    u,
                    v: vv,
                    width,
                    height,
                });
            }
            if v.xref as usize >= input.positions.len() {
                return Err(internal(
                    m,
                    format!("output vertex {vertex} refers to input vertex {}", v.xref),
                ));
            }
        }
        if mesh.indices.len() != input.indices.len() {
            return Err(internal(
                m,
                format!(
                    "{} output indices for {} input indices",
                    mesh.indices.len(),
                    input.indices.len()
                ),
            ));
        }
        for (k, (o, i)) in mesh
            .indices
            .chunks_exact(3)
            .zip(input.indices.chunks_exact(3))
            .enumerate()
        {
            let same = o
                .iter()
                .zip(i)
                .all(|(&o, &i)| mesh.vertices.get(o as usize).is_some_and(|v| v.xref == i));
            if !same {
                return Err(internal(
                    m,
                    format!(
                        "output triangle {k} {o:?} does not come from input triangle {k} {i:?}"
                    ),
                ));
            }
        }
        // Each triangle's page: its charted corners must agree.
        let mut page = Vec::with_capacity(mesh.indices.len() / 3);
        for (k, t) in mesh.indices.chunks_exact(3).enumerate() {
            let mut on: Option<u32> = None;
            for &i in t {
                let a = mesh.vertices[i as usize].atlas_index;
                if a == UNCHARTED {
                    continue;
                }
                if on.is_some_and(|p| p != a) {
                    return Err(internal(
                        m,
                        format!(
                            "output triangle {k} has corners on pages {} and {a}",
                            on.unwrap_or(a)
                        ),
                    ));
                }
                on = Some(a);
            }
            page.push(on.unwrap_or(UNCHARTED));
        }
        let first = page.iter().copied().find(|&p| p != UNCHARTED).unwrap_or(0);
        for p in &mut page {
            if *p == UNCHARTED {
                *p = first;
            }
        }
        out[m] = AtlasMesh {
            xref: mesh.vertices.iter().map(|v| v.xref).collect(),
            uv: mesh.vertices.iter().map(|v| v.uv).collect(),
            indices: mesh.indices.to_vec(),
            page,
        };
    }
    Ok(Atlas {
        width: info.width,
        height: info.height,
        pages,
        texels_per_unit: info.texels_per_unit,
        meshes: out,
    })
}

pub(super) fn internal(mesh: usize, reason: impl Into<String>) -> AtlasError {
    AtlasError::Internal {
        mesh,
        reason: reason.into(),
    }
}
