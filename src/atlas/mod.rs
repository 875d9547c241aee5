//! Lightmap UV atlas: charts every mesh with xatlas and packs all charts into one or more atlas
//! pages.
//!
//! [`pack`] takes world-space triangle meshes, splits them into charts (groups of connected
//! triangles that flatten with little distortion), parameterizes each chart and packs the charts
//! into pages of texels with a uniform texel density (`texels_per_unit` texels per scene unit)
//! and a padding between charts. With a fixed resolution everything goes on one page (the density
//! is lowered until it fits); with a fixed density the charts spill onto as many pages of
//! `page_size` texels as they need (each chart lies on one page; a mesh's charts may lie on
//! several, see [`AtlasMesh::page`]). Each output mesh carries, for every output vertex (input
//! vertices are split at chart seams), the input vertex it came from and its UV in texels.
//!
//! # xatlas, and the traps this module works around
//!
//! It uses xatlas of 2019 (Jonathan Young, MIT), the C++ that the `xatlas-rs` 0.1.3 crate
//! vendors, compiled by `build.rs` from `xatlas/` with a small C interface (`xatlas/shim.cpp`,
//! bound in `ffi.rs`). xatlas-rs's own Rust layer is not used:
//!
//! - **It does not link outside MSVC.** Its pre-generated bindings name the C++ functions by their
//!   MSVC decorated names (`?Create@xatlas@@YAPEAUAtlas@1@XZ`, ...), while gcc and clang export
//!   Itanium names (`_ZN6xatlas6CreateEv`, ...). The shim's functions have C names, which every
//!   platform links alike.
//! - **It drops `AddMesh`'s error code and hides the atlas size** (`Atlas::width`, `height`,
//!   `atlasCount`, `texelsPerUnit`) and `PackCharts`. The shim returns the code; `ffi.rs` reads
//!   the `xatlas::Atlas` fields through a `#[repr(C)]` mirror whose size a test checks against
//!   the C++ compiler's. (Inputs are checked before they reach xatlas anyway: non-finite
//!   positions, indices out of range, an index count that is not a multiple of 3.)
//! - **Its build takes xatlas's flags only from the environment** (`CXXFLAGS`), which a crate
//!   that depends on penumbra would have to repeat; `build.rs` sets them itself.
//!
//! xatlas itself:
//!
//! - **`padding` is ignored unless `conservative` is set**: [`pack`] always sets it.
//! - **Index format defaults to 16 bits** in `xatlas::MeshDecl`: [`pack`] passes 32-bit indices.
//! - **An `AddMesh` with no indices is taken as an unindexed triangle soup** (every 3 vertices a
//!   triangle): [`pack`] never adds a mesh without triangles; it outputs an empty [`AtlasMesh`].
//! - **Charts larger than `maxChartSize` (default 1024 texels) are silently scaled down**, which
//!   breaks the uniform texel density. [`pack`] sets `maxChartSize` to the largest chart that fits
//!   the page and treats a chart that reaches it as "does not fit" (see below).
//! - **With a fixed `resolution`, charts that don't fit spill onto more atlas pages**
//!   (`atlasCount > 1`), and a chart larger than the page gets UVs outside it, both silently.
//!   With [`AtlasOptions::resolution`] [`pack`] wants one page. Its first packing (inside
//!   `Generate`) is a cheap *sizing* packing at xatlas's own guess (the page at 75%
//!   utilization) into one page that grows to hold every chart, with few random placements per
//!   chart ([`SIZING_PACK_ATTEMPTS`]): it cannot overflow, and its utilization says how much
//!   chart area a page holds. Then it re-packs (xatlas `PackCharts` on the same atlas, charts
//!   are not recomputed) at the density that estimate gives ([`fitting_density`]; or at the
//!   guess, when the grown page was no larger than the page), lowers the density until
//!   everything fits (an overflowing packing gives the next estimate), and closes in on the
//!   densest packing that fits (5% denser at a time while nothing has overflowed: the sizing
//!   packing packs less tightly than a proper one). xatlas places charts at random, so
//!   whether a density fits is not monotonic: the density found can differ by a few per cent
//!   from one search order to another. Every packing counts (0.3 s for 2 400 charts, 0.9 s for
//!   9 600), one that overflows most: each chart that does not fit first tries every full page
//!   4 096 times. With a fixed density it uses
//!   the pages (each vertex's `atlasIndex`), refuses
//!   a chart that reached the page size ([`AtlasError::ChartTooLarge`]), and checks that every UV
//!   lies in `[0, width] x [0, height]` and that the three corners of every triangle are on one
//!   page.
//! - **One large connected chart is very slow**: xatlas's chart growing and its parameterization
//!   are both superlinear in the triangles of a chart (a flat 20k-triangle grid: 47 s; a bumpy one:
//!   157 s) unless `ChartOptions::maxChartArea` is set. [`pack`] sets it so that a chart of
//!   average-sized triangles has at most [`TRIANGLES_PER_CHART`] triangles (the flat grid then
//!   charts and packs in about 2 s). The price: a mesh whose triangles are much larger than the
//!   scene's average can be split into more charts than it needs (at worst one per triangle).
//! - **xatlas prints warnings with `printf` to stdout** (e.g. "Chart 3: doesn't have disk
//!   topology"). The module turns xatlas's printing off once (xatlas `SetPrint(nullptr, false)`),
//!   so stdout stays the program's own.
//! - **Its task scheduler can hang at `Destroy`.** xatlas's worker loop checks `m_running`, then
//!   registers itself as asleep and waits; `Scheduler::stop` clears `m_running` and wakes the
//!   registered sleepers. A worker between the two steps is missed and sleeps forever, so `stop`
//!   never joins it (seen once in a few thousand bakes, a test's child process stuck in
//!   `xatlas::Destroy`). `build.rs` builds xatlas with `XA_MULTITHREADED=0` (its
//!   single-threaded scheduler: no worker threads, the same output); a test checks the build.
//!
//! Output is deterministic: xatlas's random generators are seeded with constants per atlas, and
//! it runs single-threaded (see above), so the same input gives the same bytes on every run, also
//! when several threads pack at once (each call has its own xatlas atlas, so calls need no lock).
//!
//! Triangle order is kept: xatlas writes output triangle `k` at `indexArray[3k..3k+3]` for input
//! face `k` (it maps faces back to their source face), and [`pack`] checks that output triangle
//! `k`'s vertices come from input triangle `k`'s vertices in the same order.

mod ffi;
mod groups;
mod packed;

use ffi::{ADD_MESH_SUCCESS, Xatlas, add_mesh_error_text};
use groups::{merge_groups, page_groups};
use packed::{
    boxes_area, chart_boxes, collect_output, fitting_density, fixed_page_shrink, internal,
    largest_side,
};
use rayon::prelude::*;

/// A chart made of average-sized triangles has at most about this many triangles: [`pack`] sets
/// xatlas's `maxChartArea` to `total area / total triangles * TRIANGLES_PER_CHART`.
///
/// Measured on one connected 20k-triangle grid (charting + parameterization, 2 cores): no limit
/// 47 s flat / 157 s bumpy; 2000: 3.0 s / 9.5 s; 1000: 1.0 s / 4.5 s; 500: 0.6 s / 2.5 s.
pub(crate) const TRIANGLES_PER_CHART: f64 = 1000.0;

/// Triangles whose area is below this fraction of the whole input's are left out of the
/// charts, as degenerate ones are: at the largest density [`check_density`] allows, such a
/// triangle covers under half a texel. xatlas parameterizes some of these specks (a real city's
/// 0.1 mm needles left by its source triangulation) as a line and scales that line up to the
/// largest chart it allows, a whole page long, which failed a 39k-triangle city's atlas.
const SPECK_AREA: f64 = 1e-9;

/// With a fixed density, a chart's outline is at most `2 x BOUNDARY_MARGIN` page sides (xatlas
/// `maxBoundaryLength`), so that it fits on one page.
const BOUNDARY_MARGIN: f64 = 0.8;

/// Largest atlas side, in texels, that [`pack`] accepts or produces.
pub(crate) const MAX_RESOLUTION: u32 = 16384;

/// Atlas side used when neither `texels_per_unit` nor `resolution` is given.
pub(crate) const DEFAULT_RESOLUTION: u32 = 1024;

/// Page side, in texels, used with a fixed `texels_per_unit` when no `page_size` is given: 2048
/// is the largest size every WebGL2 / GLES3 device must support as a texture (4096 is common,
/// not guaranteed), and 2048² RGB8 is 12 MiB of texture memory per page.
pub const DEFAULT_PAGE_SIZE: u32 = 2048;

/// How many times [`pack`] re-packs with a smaller texel density before giving up.
const MAX_PACK_ATTEMPTS: u32 = 40;

/// With a fixed page, how many extra packings [`pack`] spends closing in on the densest
/// packing that fits, once one fit below xatlas's guess.
const REFINEMENTS: u32 = 4;

/// With a fixed page, the search for the densest packing that fits stops once the densest
/// packing that fit and the sparsest that did not are within this factor.
const BRACKET: f32 = 1.05;

/// The share of the estimated fitting density ([`fitting_density`]) tried first: the estimate
/// assumes the packer fills the page as well as it filled the first page of the overflowing
/// packing, which it does not quite once every chart has to fit (least with many small charts,
/// whose padding wastes more). Each estimate that still overflows doubles the margin
/// `1 - ESTIMATE_MARGIN`.
const ESTIMATE_MARGIN: f32 = 0.98;

/// xatlas's `PackOptions::attempts` (its default): random placements tried per chart, on a
/// fixed page (whose density search wants the tightest packing).
const PACK_ATTEMPTS_PER_CHART: i32 = 4096;

/// Random placements per chart and page with a fixed density. xatlas tries a chart on each open
/// page in turn, `attempts` times on a page it does not fit, so the packing's time grows with
/// the pages times the charts times this. Measured on town-100k at 8 texels/m (16 pages of
/// 2048², one atlas): 4 096 placements 67 s; 512, 22 s; 256, 13 s, all 16 pages; 128, 9 s
/// and 17 pages.
const PAGES_PACK_ATTEMPTS: i32 = 256;

/// Random placements per chart in the sizing packing (see [`pack`]): a fixed page's first
/// packing, into one page that grows to hold every chart, which only measures how tightly the
/// charts pack. Placements are tried until a chart lands inside the packed extent, so few are
/// needed: `Generate` (charting and this packing) takes 0.34 s with 2 400 charts and 1.24 s
/// with 9 600 on the box grids, against 0.79 s and 3.04 s for a first packing onto the fixed
/// page. Its estimate is within 9% of the density finally packed on the ladder's rungs (both
/// sides).
const SIZING_PACK_ATTEMPTS: i32 = 256;

/// A packing that overflowed with no chart wider or taller than this (texels) has every chart
/// at the smallest bit image xatlas makes (it rounds a chart's extent up to whole texels, at
/// least one): lowering the density further cannot help, so the search stops
/// ([`AtlasError::DoesNotFit`]) instead of halving on to [`MAX_PACK_ATTEMPTS`].
const MIN_CHART_SIDE: f32 = 1.0;

/// What can go wrong in packing the atlas ([`pack_estimating`]).
#[derive(Debug, thiserror::Error)]
pub enum AtlasError {
    /// An input mesh is malformed; `mesh` is its index in the inputs.
    #[error("mesh {mesh}: {reason}")]
    InvalidInput { mesh: usize, reason: String },
    /// An [`AtlasOptions`] value is out of range.
    #[error("invalid atlas option {option}: {reason}")]
    InvalidOptions {
        option: &'static str,
        reason: String,
    },
    /// xatlas's `AddMesh` rejected a mesh (its error code).
    #[error("mesh {mesh}: xatlas rejected it: {reason}")]
    AddMesh { mesh: usize, reason: String },
    /// There is no triangle to chart: no input, or every input mesh is empty or degenerate.
    #[error("no triangles to chart (every input mesh is empty or degenerate)")]
    Empty,
    /// With a fixed resolution, the charts did not fit on one page: their padding alone
    /// overflows it, or every chart was at its smallest, or 40 packings (`attempts`, the last
    /// at `texels_per_unit`) found no density that fits.
    #[error(
        "charts do not fit on one {resolution}x{resolution} page, even at {texels_per_unit} \
         texels per unit after {attempts} packing(s): raise the resolution or lower the padding"
    )]
    DoesNotFit {
        resolution: u32,
        texels_per_unit: f32,
        attempts: u32,
    },
    /// With a fixed texel density, the pages together would hold more texels than one
    /// [`MAX_RESOLUTION`]² page (`texels` is the side of a square of that many texels).
    #[error(
        "an atlas at {texels_per_unit} texels per unit would need about {texels}² texels, \
         more than {max}²; lower texels_per_unit or give a resolution"
    )]
    TooLarge {
        texels_per_unit: f32,
        texels: u64,
        max: u32,
    },
    /// With a fixed texel density, a chart is larger than one page (`texels` is its size at
    /// that density, about, when xatlas had to scale it down).
    #[error(
        "a chart is larger than one {page_size}x{page_size} page at {texels_per_unit} texels per \
         unit (at least {texels} texels a side): raise the page size or lower texels_per_unit"
    )]
    ChartTooLarge {
        page_size: u32,
        texels_per_unit: f32,
        texels: u32,
    },
    /// An output UV lies outside the atlas (checked after packing).
    #[error(
        "mesh {mesh}: output vertex {vertex} has UV ({u}, {v}) outside the {width}x{height} atlas"
    )]
    OutOfBounds {
        mesh: usize,
        vertex: usize,
        u: f32,
        v: f32,
        width: u32,
        height: u32,
    },
    /// An output vertex is on an atlas page beyond the ones the atlas keeps (with a fixed
    /// resolution: any page but the first; checked after packing).
    #[error(
        "mesh {mesh}: output vertex {vertex} is on atlas page {page}, beyond the atlas's pages"
    )]
    NotOnePage {
        mesh: usize,
        vertex: usize,
        page: u32,
    },
    /// xatlas's output does not match its input as documented (a bug in xatlas or this module).
    #[error("mesh {mesh}: unexpected xatlas output: {reason}")]
    Internal { mesh: usize, reason: String },
}

/// One mesh to chart: world-space positions (so texel density is uniform in the scene's units) and
/// triangle indices.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AtlasInput<'a> {
    /// Vertex positions in scene units. All must be finite.
    pub(crate) positions: &'a [[f32; 3]],
    /// Triangle list: three indices into `positions` per triangle. An empty list is allowed (the
    /// output mesh is then empty).
    pub(crate) indices: &'a [u32],
}

/// How to size the atlas.
///
/// - `texels_per_unit` only: the density is kept. When the charts fit on one page of at most
///   `page_size` texels a side, the page is the packed extent (not a power of two); else they are
///   packed onto as many `page_size` x `page_size` pages as they need. A chart larger than a page
///   is an error ([`AtlasError::ChartTooLarge`]).
/// - `resolution` given (or neither, which means `resolution` = [`DEFAULT_RESOLUTION`]): the page
///   is exactly `resolution` x `resolution` texels. The density is `texels_per_unit` if given, else
///   estimated by xatlas from the surface area; if the charts do not fit on one page at that
///   density, [`pack`] retries with a smaller density until they do, and [`Atlas::texels_per_unit`]
///   reports the one used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct AtlasOptions {
    /// Texels per scene unit (metre). None: derived from `resolution`.
    pub(crate) texels_per_unit: Option<f32>,
    /// Target atlas width and height in texels. None with texels_per_unit None: 1024.
    pub(crate) resolution: Option<u32>,
    /// Texels of padding between charts (>= 2).
    pub(crate) padding: u32,
    /// Largest page side, in texels, with `texels_per_unit` given and `resolution` not; more
    /// pages are used when the charts need them. Ignored otherwise.
    pub(crate) page_size: u32,
}

impl Default for AtlasOptions {
    /// A 1024 x 1024 page, density estimated, 2 texels of padding.
    fn default() -> Self {
        Self {
            texels_per_unit: None,
            resolution: None,
            padding: 2,
            page_size: DEFAULT_PAGE_SIZE,
        }
    }
}

/// One output mesh, in the order of the inputs. Output vertices are split at chart seams.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AtlasMesh {
    /// For each output vertex, the index of the input vertex it comes from.
    pub(crate) xref: Vec<u32>,
    /// For each output vertex, its UV in texels (0..width, 0..height), texel centres at +0.5.
    ///
    /// Vertices of triangles that xatlas leaves out of every chart (degenerate ones: a repeated
    /// index, a zero-length edge, or an area <= `f32::EPSILON` in scene units²) have UV (0, 0),
    /// so those triangles cover no texel.
    pub uv: Vec<[f32; 2]>,
    /// Triangles over the output vertices; triangle k is input triangle k (same order, same
    /// count, and its corners come from input triangle k's corners in the same order).
    pub indices: Vec<u32>,
    /// For each triangle, the page it lies on (0..[`Atlas::pages`]). Triangles left out of
    /// every chart get the page of the mesh's first charted triangle.
    pub(crate) page: Vec<u32>,
}

/// The packed atlas: `pages` pages of `width` x `height` texels each.
#[derive(Debug, Clone, PartialEq)]
pub struct Atlas {
    /// Page width in texels.
    pub width: u32,
    /// Page height in texels.
    pub height: u32,
    /// Number of pages (at least 1).
    pub pages: u32,
    /// Texels per scene unit actually used (may be lower than requested, see [`AtlasOptions`]).
    pub texels_per_unit: f32,
    /// One output mesh per input, in input order.
    pub meshes: Vec<AtlasMesh>,
}

/// Charts and packs all meshes into one or more atlas pages.
///
/// Checks the inputs first (finite positions, indices in range, index count a multiple of 3;
/// meshes with no triangles give an empty [`AtlasMesh`]) and the output after (one page, UVs
/// inside it, triangle order kept). See the module documentation for what it works around in
/// xatlas, and [`AtlasOptions`] for how the pages are sized (with a fixed resolution it lowers
/// the texel density until all charts fit on one page; with a fixed density it adds pages).
#[cfg(test)]
pub(crate) fn pack(inputs: &[AtlasInput<'_>], options: &AtlasOptions) -> Result<Atlas, AtlasError> {
    pack_estimating(inputs, options, &mut |_| {})
}

/// [`pack`], calling `estimate` once, as early as it is known, with the density the packing
/// starts from (texels per unit of the inputs): the caller's density with pages, else the
/// density the sizing packing estimates fills the fixed page (the final density is within a
/// few percent of it, after some seconds more of packing on large scenes). Not called when
/// packing fails before that.
pub(crate) fn pack_estimating(
    inputs: &[AtlasInput<'_>],
    options: &AtlasOptions,
    estimate: &mut dyn FnMut(f32),
) -> Result<Atlas, AtlasError> {
    let sizing = Sizing::from_options(options)?;
    let stats = check_inputs(inputs)?;
    if stats.triangles == 0 || stats.area <= 0.0 {
        return Err(AtlasError::Empty);
    }
    if let Sizing::Pages {
        texels_per_unit,
        page_size,
    } = sizing
    {
        let groups = page_groups(inputs, texels_per_unit, page_size);
        if groups.len() > 1 {
            check_density(stats.area, texels_per_unit)?;
            estimate(texels_per_unit);
            let parts: Vec<Result<Atlas, AtlasError>> = groups
                .par_iter()
                .map(|g| pack_group(&inputs[g.clone()], options, sizing, &stats, &mut |_| {}))
                .collect();
            return merge_groups(&groups, parts);
        }
    }
    pack_group(inputs, options, sizing, &stats, estimate)
}

/// Charts and packs `inputs` (checked) into one xatlas atlas: [`pack_estimating`] for all of
/// them or for one group of [`page_groups`]. `whole` is the totals of all inputs, from which
/// the charts' size limits and the specks left out are set, so that a mesh is charted alike
/// in any group.
fn pack_group(
    inputs: &[AtlasInput<'_>],
    options: &AtlasOptions,
    sizing: Sizing,
    whole: &InputStats,
    estimate: &mut dyn FnMut(f32),
) -> Result<Atlas, AtlasError> {
    let own_area: f64 = inputs.iter().map(|i| triangle_areas(i).sum::<f64>()).sum();
    if own_area <= 0.0 {
        return Err(AtlasError::Empty);
    }
    let stats = whole;
    let max_chart_size = match sizing {
        Sizing::Fixed { resolution, .. } => {
            // A chart's bit image is ceil(extent) + 1 + padding texels wide; it must fit the page.
            let size = resolution.saturating_sub(options.padding + 1);
            if size < 1 {
                return Err(AtlasError::InvalidOptions {
                    option: "padding",
                    reason: format!(
                        "{} texels of padding leave no room on a {resolution}-texel page",
                        options.padding
                    ),
                });
            }
            size
        }
        Sizing::Pages {
            texels_per_unit,
            page_size,
        } => {
            check_density(stats.area, texels_per_unit)?;
            let size = page_size.saturating_sub(options.padding + 1);
            if size < 1 {
                return Err(AtlasError::InvalidOptions {
                    option: "page_size",
                    reason: format!(
                        "{} texels of padding leave no room on a {page_size}-texel page",
                        options.padding
                    ),
                });
            }
            estimate(texels_per_unit);
            size
        }
    };

    let mut xatlas = Xatlas::new().ok_or_else(|| internal(0, "xatlas Create returned no atlas"))?;

    // Add the meshes that have triangles; `added[i]` is the input index of xatlas mesh i.
    let mut added = Vec::new();
    for (m, input) in inputs.iter().enumerate() {
        if input.indices.is_empty() {
            continue;
        }
        // Specks below a texel at any density are left out of the charts (UV (0, 0), as the
        // degenerate ones): see `SPECK_AREA`.
        let ignore: Vec<bool> = triangle_areas(input)
            .map(|a| a < SPECK_AREA * stats.area)
            .collect();
        let ignore: &[bool] = if ignore.contains(&true) { &ignore } else { &[] };
        let code = xatlas.add_mesh(input.positions, input.indices, ignore);
        if code != ADD_MESH_SUCCESS {
            return Err(AtlasError::AddMesh {
                mesh: m,
                reason: add_mesh_error_text(code),
            });
        }
        added.push(m);
    }

    let chart_options = ffi::ChartOptions {
        max_chart_area: (stats.area / stats.triangles as f64 * TRIANGLES_PER_CHART) as f32,
        // With a fixed density a chart must fit on one page: a chart whose outline is at most
        // twice the page side is at most a page side across (two points split the outline
        // into two paths, each at least their distance), in any rotation. A margin covers the
        // parameterization's stretch of non-flat charts. (A single triangle is a chart however
        // long its outline: the caller cuts long ones, see `scene::cut`.)
        max_boundary_length: match sizing {
            Sizing::Pages {
                texels_per_unit, ..
            } => {
                (2.0 * BOUNDARY_MARGIN * max_chart_size as f64 / f64::from(texels_per_unit)) as f32
            }
            Sizing::Fixed { .. } => 0.0,
        },
        ..Default::default()
    };
    let mut pack_options = ffi::PackOptions {
        attempts: match sizing {
            Sizing::Fixed { .. } => SIZING_PACK_ATTEMPTS,
            Sizing::Pages { .. } => PAGES_PACK_ATTEMPTS,
        },
        texels_per_unit: match sizing {
            // xatlas's own guess: the page at 75% utilization.
            Sizing::Fixed {
                texels_per_unit,
                resolution,
            } => texels_per_unit
                .unwrap_or((0.75 * f64::from(resolution).powi(2) / own_area).sqrt() as f32),
            Sizing::Pages {
                texels_per_unit, ..
            } => texels_per_unit,
        },
        resolution: match sizing {
            // The sizing packing: one page that grows.
            Sizing::Fixed { .. } => 0,
            // First try one page that grows to the packed extent, when it will likely fit.
            Sizing::Pages { page_size, .. }
                if (own_area / 0.75).sqrt() * f64::from(pack_options_tpu(&sizing))
                    > f64::from(page_size) =>
            {
                page_size
            }
            Sizing::Pages { .. } => 0,
        },
        max_chart_size,
        block_align: false,
        conservative: true,
        padding: options.padding,
    };
    let mut info = xatlas.generate(&chart_options, &pack_options);
    if info.chart_count == 0 {
        return Err(AtlasError::Empty);
    }

    let resolution = match sizing {
        Sizing::Pages {
            texels_per_unit,
            page_size,
        } => {
            let grown = pack_options.resolution == 0;
            let too_big = {
                let meshes = output_meshes(&xatlas, added.len())?;
                // A chart that reached `max_chart_size` may have been scaled down by xatlas.
                let largest = largest_side(&chart_boxes(&meshes));
                if largest > max_chart_size as f32 - 0.5 {
                    return Err(AtlasError::ChartTooLarge {
                        page_size,
                        texels_per_unit,
                        texels: largest.ceil() as u32,
                    });
                }
                info.width.max(info.height) > page_size
            };
            if grown && too_big {
                // The grown page is too large: pack the same charts onto fixed pages.
                pack_options.resolution = page_size;
                info = xatlas.pack_charts(&pack_options);
            }
            let meshes = output_meshes(&xatlas, added.len())?;
            if info.width.max(info.height) > page_size {
                return Err(internal(
                    0,
                    format!(
                        "a {}x{} page for a page size of {page_size}",
                        info.width, info.height
                    ),
                ));
            }
            return collect_output(inputs, &added, &meshes, &info, true);
        }
        Sizing::Fixed { resolution, .. } => resolution,
    };

    // Fixed page: the first packing, into a page that grew to hold every chart, sizes them. Then
    // lower the density until everything fits on one page (to the estimate of
    // `fitting_density` when a packing overflowed), and, if it had to be lowered, close in
    // on the densest packing that fits from the densest that fit and the sparsest that did not.
    let mut attempts = 1;
    let mut fitting: Option<f32> = None;
    let mut failing: Option<f32> = None;
    let mut refinements = 0;
    // Estimates of the fitting density that overflowed still.
    let mut misses = 0u32;
    // The output of the densest packing that fit, kept so that it need not be packed again.
    let mut best_output: Option<Atlas> = None;
    let user_density = match sizing {
        Sizing::Fixed {
            texels_per_unit, ..
        } => texels_per_unit,
        Sizing::Pages { .. } => None,
    };
    loop {
        let tried = info.texels_per_unit;
        let next = 'next: {
            if pack_options.resolution == 0 {
                // The sizing packing: pack onto the page at its density if the grown page is no
                // larger, else at the density at which the charts, packed as tightly, fill it.
                let next = {
                    let meshes = output_meshes(&xatlas, added.len())?;
                    let boxes = chart_boxes(&meshes);
                    // Every chart's bit image is at least `1 + padding` texels a side at any
                    // density: when those alone overflow the page, no density fits.
                    let least = boxes.len() as f64 * f64::from(options.padding + 1).powi(2);
                    if least > f64::from(resolution).powi(2) {
                        return Err(AtlasError::DoesNotFit {
                            resolution,
                            texels_per_unit: tried,
                            attempts,
                        });
                    }
                    let side = info.width.max(info.height);
                    if side <= resolution && largest_side(&boxes) <= max_chart_size as f32 - 0.5 {
                        tried
                    } else {
                        let page = f64::from(resolution).powi(2);
                        let grown = f64::from(info.width) * f64::from(info.height);
                        let held = boxes_area(boxes.iter(), options.padding) * page / grown;
                        match fitting_density(&boxes, tried, options.padding, held) {
                            Some(e) => (e * ESTIMATE_MARGIN).min(tried * 0.99),
                            None => tried * 0.9 * resolution as f32 / side as f32,
                        }
                    }
                };
                pack_options.resolution = resolution;
                pack_options.attempts = PACK_ATTEMPTS_PER_CHART;
                estimate(next);
                break 'next next;
            }
            let (shrink, estimate, smallest) = {
                let meshes = output_meshes(&xatlas, added.len())?;
                let boxes = chart_boxes(&meshes);
                // Every chart at the smallest size xatlas rasterizes: a lower density cannot
                // make the charts take less room (their padding does not shrink).
                let smallest = largest_side(&boxes) <= MIN_CHART_SIDE;
                let shrink = fixed_page_shrink(&meshes, &boxes, &info, max_chart_size);
                if shrink.is_none() && fitting.is_none_or(|f| tried > f) {
                    best_output = Some(collect_output(inputs, &added, &meshes, &info, false)?);
                }
                let estimate = match shrink {
                    Some(_) if info.atlas_count > 1 => {
                        let full =
                            boxes_area(boxes.iter().filter(|b| b.page == 0), options.padding);
                        fitting_density(&boxes, tried, options.padding, full)
                    }
                    _ => None,
                };
                (shrink, estimate, smallest)
            };
            // Once a packing fit, the next density closes the bracket from the side of the last
            // packing by at most `BRACKET`, or halves it: when the estimate was good, one more
            // packing settles it.
            let next = match shrink {
                None => {
                    fitting = Some(fitting.map_or(tried, |f| f.max(tried)));
                    match failing {
                        Some(hi) if refinements < REFINEMENTS && hi > tried * BRACKET => {
                            refinements += 1;
                            Some((0.5 * (tried + hi)).min(tried * BRACKET))
                        }
                        // Nothing overflowed yet: the density came from the sizing packing's
                        // estimate, which packs less tightly than a proper packing (its few
                        // placements), so try denser, up to a density the caller gave.
                        None if refinements < REFINEMENTS
                            && user_density.is_none_or(|c| tried * BRACKET <= c) =>
                        {
                            refinements += 1;
                            Some(tried * BRACKET)
                        }
                        _ => None,
                    }
                }
                Some(factor) => {
                    failing = Some(failing.map_or(tried, |f| f.min(tried)));
                    match fitting {
                        None if smallest => None,
                        None => Some(match estimate {
                            Some(e) => {
                                let margin = (1.0 - ESTIMATE_MARGIN) * (1 << misses.min(4)) as f32;
                                misses += 1;
                                (e * (1.0 - margin)).min(tried * 0.99)
                            }
                            None => tried * factor,
                        }),
                        Some(lo) if refinements < REFINEMENTS && tried > lo * BRACKET => {
                            refinements += 1;
                            Some((0.5 * (lo + tried)).max(tried / BRACKET))
                        }
                        Some(_) => None,
                    }
                }
            };
            match (next, best_output.take()) {
                (Some(next), best) if attempts < MAX_PACK_ATTEMPTS => {
                    best_output = best;
                    next
                }
                // Done: the densest packing that fit.
                (_, Some(best)) => return Ok(best),
                (_, None) => {
                    return Err(AtlasError::DoesNotFit {
                        resolution,
                        texels_per_unit: tried,
                        attempts,
                    });
                }
            }
        };
        attempts += 1;
        pack_options.texels_per_unit = next;
        info = xatlas.pack_charts(&pack_options);
    }
}

/// Refuses a density at which `area` (scene units²) would need more texels than one
/// [`MAX_RESOLUTION`]² page holds ([`AtlasError::TooLarge`]): xatlas packs at about 75%
/// utilization, and this is checked before it allocates huge pages.
pub(crate) fn check_density(area: f64, texels_per_unit: f32) -> Result<(), AtlasError> {
    let side = (area / 0.75).sqrt() * f64::from(texels_per_unit);
    if side > f64::from(MAX_RESOLUTION) {
        return Err(AtlasError::TooLarge {
            texels_per_unit,
            texels: side.ceil() as u64,
            max: MAX_RESOLUTION,
        });
    }
    Ok(())
}

/// The views of the output meshes, checked to be one per added mesh. They borrow memory that
/// the next packing or the drop of `xatlas` frees.
fn output_meshes(xatlas: &Xatlas, expected: usize) -> Result<Vec<ffi::Mesh<'_>>, AtlasError> {
    let meshes = xatlas.meshes();
    if meshes.len() != expected {
        return Err(internal(
            0,
            format!("{} output meshes for {expected} inputs", meshes.len()),
        ));
    }
    Ok(meshes)
}

/// How the page is sized, from [`AtlasOptions`].
#[derive(Debug, Clone, Copy)]
enum Sizing {
    /// A `resolution` x `resolution` page.
    Fixed {
        resolution: u32,
        texels_per_unit: Option<f32>,
    },
    /// This density, on one page that grows up to `page_size`, else on `page_size` pages.
    Pages {
        texels_per_unit: f32,
        page_size: u32,
    },
}

/// The density a [`Sizing`] asks xatlas for (0: xatlas estimates one).
fn pack_options_tpu(sizing: &Sizing) -> f32 {
    match *sizing {
        Sizing::Fixed {
            texels_per_unit, ..
        } => texels_per_unit.unwrap_or(0.0),
        Sizing::Pages {
            texels_per_unit, ..
        } => texels_per_unit,
    }
}

impl Sizing {
    fn from_options(options: &AtlasOptions) -> Result<Self, AtlasError> {
        if options.padding < 2 {
            return Err(AtlasError::InvalidOptions {
                option: "padding",
                reason: format!("{} is below the minimum of 2 texels", options.padding),
            });
        }
        if let Some(tpu) = options.texels_per_unit
            && !(tpu.is_finite() && tpu > 0.0)
        {
            return Err(AtlasError::InvalidOptions {
                option: "texels_per_unit",
                reason: format!("{tpu} is not a positive number"),
            });
        }
        if let Some(resolution) = options.resolution
            && !(1..=MAX_RESOLUTION).contains(&resolution)
        {
            return Err(AtlasError::InvalidOptions {
                option: "resolution",
                reason: format!("{resolution} is not in 1..={MAX_RESOLUTION}"),
            });
        }
        Ok(match (options.resolution, options.texels_per_unit) {
            (Some(resolution), texels_per_unit) => Sizing::Fixed {
                resolution,
                texels_per_unit,
            },
            (None, Some(texels_per_unit)) => {
                if !(1..=MAX_RESOLUTION).contains(&options.page_size) {
                    return Err(AtlasError::InvalidOptions {
                        option: "page_size",
                        reason: format!("{} is not in 1..={MAX_RESOLUTION}", options.page_size),
                    });
                }
                Sizing::Pages {
                    texels_per_unit,
                    page_size: options.page_size,
                }
            }
            (None, None) => Sizing::Fixed {
                resolution: DEFAULT_RESOLUTION,
                texels_per_unit: None,
            },
        })
    }
}

/// Totals over the valid inputs.
struct InputStats {
    /// Triangles in all meshes.
    triangles: usize,
    /// Total surface area, in scene units².
    area: f64,
}

/// The area of each triangle of `input`, in its units².
fn triangle_areas<'a>(input: &'a AtlasInput<'_>) -> impl Iterator<Item = f64> + 'a {
    input.indices.chunks_exact(3).map(|tri| {
        let [a, b, c] = [0, 1, 2].map(|k| input.positions[tri[k] as usize].map(f64::from));
        let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let n = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
    })
}

/// Checks every input mesh, and sums their triangles and surface area.
fn check_inputs(inputs: &[AtlasInput<'_>]) -> Result<InputStats, AtlasError> {
    let mut stats = InputStats {
        triangles: 0,
        area: 0.0,
    };
    for (mesh, input) in inputs.iter().enumerate() {
        let invalid = |reason: String| AtlasError::InvalidInput { mesh, reason };
        if input.positions.len() > u32::MAX as usize {
            return Err(invalid(format!(
                "{} vertices, more than xatlas's limit of {}",
                input.positions.len(),
                u32::MAX
            )));
        }
        if input.indices.len() > u32::MAX as usize {
            return Err(invalid(format!(
                "{} indices, more than xatlas's limit of {}",
                input.indices.len(),
                u32::MAX
            )));
        }
        if input.indices.len() % 3 != 0 {
            return Err(invalid(format!(
                "{} indices, not a multiple of 3 (a triangle list is expected)",
                input.indices.len()
            )));
        }
        if let Some((v, p)) = input
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(invalid(format!(
                "vertex {v} has a non-finite position {p:?}"
            )));
        }
        let vertex_count = input.positions.len();
        if let Some((i, &index)) = input
            .indices
            .iter()
            .enumerate()
            .find(|&(_, &index)| index as usize >= vertex_count)
        {
            return Err(invalid(format!(
                "index {i} (triangle {}) is {index}, out of range for {vertex_count} vertices",
                i / 3
            )));
        }
        stats.area += triangle_areas(input).sum::<f64>();
        stats.triangles += input.indices.len() / 3;
    }
    Ok(stats)
}

#[cfg(test)]
mod tests;
