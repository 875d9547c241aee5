//! A scene of many pages packed in groups of consecutive meshes, one xatlas atlas each, in
//! parallel; their pages one after the other.

use super::{Atlas, AtlasError, AtlasInput, AtlasMesh, triangle_areas};

/// With a fixed density, the surface of about this many pages is charted and packed by one
/// xatlas atlas; a larger scene is packed in groups of consecutive meshes, in parallel
/// ([`page_groups`]). xatlas tries each chart on every page it has open, so one atlas of
/// `n` pages packs in time about `n x charts`: groups make it linear in the scene, and use
/// every core. The price is the groups' last pages, each partly filled: town-100k at 8
/// texels/m took 22 pages in groups of 4 pages' worth, 18 in groups of 8, 16 in one atlas
/// (5.3 s in groups of 8 against 13.3 s in one, at [`super::PAGES_PACK_ATTEMPTS`]).
pub(super) const GROUP_PAGES: f64 = 16.0;

/// The inputs, cut into runs of consecutive meshes of about [`GROUP_PAGES`] pages' worth of
/// surface each at `texels_per_unit` (xatlas fills about 75% of a page). One run when the
/// whole is under one and a half groups; a last run under half a group joins the one before.
pub(super) fn page_groups(
    inputs: &[AtlasInput<'_>],
    texels_per_unit: f32,
    page_size: u32,
) -> Vec<std::ops::Range<usize>> {
    let page = 0.75 * (f64::from(page_size) / f64::from(texels_per_unit)).powi(2);
    let target = GROUP_PAGES * page;
    let areas: Vec<f64> = inputs.iter().map(|i| triangle_areas(i).sum()).collect();
    let total: f64 = areas.iter().sum();
    if total.is_nan() || total <= 1.5 * target {
        #[allow(clippy::single_range_in_vec_init, reason = "one group: all the inputs")]
        return vec![0..inputs.len()];
    }
    let mut groups = Vec::new();
    let (mut start, mut held) = (0, 0.0);
    for (m, a) in areas.iter().enumerate() {
        held += a;
        if held >= target {
            groups.push(start..m + 1);
            (start, held) = (m + 1, 0.0);
        }
    }
    if start < inputs.len() {
        match groups.last_mut() {
            Some(last) if held < 0.5 * target => last.end = inputs.len(),
            _ => groups.push(start..inputs.len()),
        }
    }
    groups
}

/// The atlases of [`page_groups`]'s runs as one: their pages one after the other (each group's
/// page numbers offset by the pages before it), the page size the largest of theirs (a page a
/// group packed smaller keeps its UVs, in texels from the page's corner). The first error, in
/// group order, with its mesh index in the whole input; a group whose meshes xatlas charted
/// nothing of (all degenerate) takes no page.
pub(super) fn merge_groups(
    groups: &[std::ops::Range<usize>],
    parts: Vec<Result<Atlas, AtlasError>>,
) -> Result<Atlas, AtlasError> {
    let mut merged = Atlas {
        width: 0,
        height: 0,
        pages: 0,
        texels_per_unit: 0.0,
        meshes: Vec::new(),
    };
    for (group, part) in groups.iter().zip(parts) {
        match part {
            Ok(atlas) => {
                merged.width = merged.width.max(atlas.width);
                merged.height = merged.height.max(atlas.height);
                merged.texels_per_unit = atlas.texels_per_unit;
                let offset = merged.pages;
                merged.pages += atlas.pages;
                merged.meshes.extend(atlas.meshes.into_iter().map(|mut m| {
                    m.page.iter_mut().for_each(|p| *p += offset);
                    m
                }));
            }
            Err(AtlasError::Empty) => merged.meshes.extend(group.clone().map(|_| AtlasMesh {
                page: Vec::new(),
                ..AtlasMesh::default()
            })),
            Err(error) => return Err(error.offset_mesh(group.start)),
        }
    }
    if merged.pages == 0 {
        return Err(AtlasError::Empty);
    }
    Ok(merged)
}

impl AtlasError {
    /// The error with its mesh index moved by `by` (an error of a group of the inputs).
    pub(super) fn offset_mesh(self, by: usize) -> AtlasError {
        match self {
            AtlasError::InvalidInput { mesh, reason } => AtlasError::InvalidInput {
                mesh: mesh + by,
                reason,
            },
            AtlasError::AddMesh { mesh, reason } => AtlasError::AddMesh {
                mesh: mesh + by,
                reason,
            },
            AtlasError::OutOfBounds {
                mesh,
                vertex,
                u,
                v,
                width,
                height,
            } => AtlasError::OutOfBounds {
                mesh: mesh + by,
                vertex,
                u,
                v,
                width,
                height,
            },
            AtlasError::NotOnePage { mesh, vertex, page } => AtlasError::NotOnePage {
                mesh: mesh + by,
                vertex,
                page,
            },
            AtlasError::Internal { mesh, reason } => AtlasError::Internal {
                mesh: mesh + by,
                reason,
            },
            other => other,
        }
    }
}
