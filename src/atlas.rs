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
//! # The xatlas-rs traps this module works around
//!
//! It uses the `xatlas-rs` 0.1.3 crate (xatlas of 2019, vendored C++), which has these problems:
//!
//! - **It does not link outside MSVC.** Its pre-generated bindings name the C++ functions by their
//!   MSVC decorated names (`?Create@xatlas@@YAPEAUAtlas@1@XZ`, ...), while gcc and clang export
//!   Itanium names (`_ZN6xatlas6CreateEv`, ...). This module exports, under the exact MSVC names,
//!   shim functions that forward to the Itanium symbols of the same functions. Only the four that
//!   xatlas-rs's safe API calls are shimmed (`Create`, `Destroy`, `AddMesh`, `Generate`); its other
//!   bindings (`ComputeCharts`, `PackCharts`, `SetPrint`, ...) are never called by it, so the
//!   linker never asks for them. This is for ELF targets (Linux): on MSVC xatlas's own symbols
//!   would collide with the shims (the module refuses to compile there), and on Mach-O the
//!   exported names would get a leading `_` that the bindings' `\u{1}`-prefixed imports lack
//!   (a `\u{1}` in `export_name` does not help: rustc then drops the symbol from executables).
//! - **`AddMesh`'s error code is dropped** by `Xatlas::add_mesh`. The `AddMesh` shim keeps the last
//!   result in a thread-local; [`pack`] checks it after each mesh. (Inputs are checked before they
//!   reach xatlas anyway: non-finite positions, indices out of range, an index count that is not a
//!   multiple of 3.)
//! - **The atlas size is hidden** (`Atlas::width`, `height`, `atlasCount`, `texelsPerUnit`): the
//!   `Generate` shim reads them from the `xatlas::Atlas` after forwarding and keeps them in a
//!   thread-local.
//! - **`padding` is ignored unless `conservative` is set**: [`pack`] always sets it.
//! - **Index format defaults to 16 bits** in `xatlas_rs::MeshDecl`: [`pack`] passes 32-bit indices.
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
//!   `xatlas::Destroy`). The repository's `.cargo/config.toml` builds xatlas with
//!   `-DXA_MULTITHREADED=0` (its single-threaded scheduler: no worker threads, the same
//!   output); a crate that depends on penumbra must set the same `CXXFLAGS`.
//!
//! Output is deterministic: xatlas's random generators are seeded with constants per atlas, and
//! it runs single-threaded (see above), so the same input gives the same bytes on every run, also
//! when several threads pack at once (each call has its own xatlas atlas; the shim stash is
//! thread-local, so calls need no lock).
//!
//! Triangle order is kept: xatlas writes output triangle `k` at `indexArray[3k..3k+3]` for input
//! face `k` (it maps faces back to their source face), and [`pack`] checks that output triangle
//! `k`'s vertices come from input triangle `k`'s vertices in the same order.

use std::cell::Cell;
use std::ffi::{c_int, c_void};
use std::ptr;

#[cfg(target_env = "msvc")]
compile_error!(
    "penumbra's atlas module shims xatlas-rs's MSVC symbol names onto the Itanium-ABI names that \
     gcc/clang export; on MSVC targets xatlas already exports the MSVC names and the shims would \
     collide"
);

/// A chart made of average-sized triangles has at most about this many triangles: [`pack`] sets
/// xatlas's `maxChartArea` to `total area / total triangles * TRIANGLES_PER_CHART`.
///
/// Measured on one connected 20k-triangle grid (charting + parameterization, 2 cores): no limit
/// 47 s flat / 157 s bumpy; 2000: 3.0 s / 9.5 s; 1000: 1.0 s / 4.5 s; 500: 0.6 s / 2.5 s.
pub const TRIANGLES_PER_CHART: f64 = 1000.0;

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
pub const MAX_RESOLUTION: u32 = 16384;

/// Atlas side used when neither `texels_per_unit` nor `resolution` is given.
pub const DEFAULT_RESOLUTION: u32 = 1024;

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

/// xatlas's `PackOptions::attempts` (its default): random placements tried per chart.
const PACK_ATTEMPTS_PER_CHART: i32 = 4096;

/// Random placements per chart in the sizing packing (see [`pack`]): a fixed page's first
/// packing, into one page that grows to hold every chart, which only measures how tightly the
/// charts pack. Placements are tried until a chart lands inside the packed extent, so few are
/// needed. Measured on the box grids, `Generate` (charting and this packing) took 0.34 s
/// instead of 0.79 s with 2 400 charts, and 1.24 s instead of 3.04 s with 9 600, where the
/// first packing used to overflow a fixed page. Its estimate is within 9% of the density
/// finally packed on the ladder's rungs (both sides).
const SIZING_PACK_ATTEMPTS: i32 = 256;

/// A packing that overflowed with no chart wider or taller than this (texels) has every chart
/// at the smallest bit image xatlas makes (it rounds a chart's extent up to whole texels, at
/// least one): lowering the density further cannot help, so the search stops
/// ([`AtlasError::DoesNotFit`]) instead of halving on to [`MAX_PACK_ATTEMPTS`].
const MIN_CHART_SIDE: f32 = 1.0;

/// What can go wrong in [`pack`].
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
    /// xatlas's `AddMesh` rejected a mesh (its error code, which xatlas-rs drops).
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
pub struct AtlasInput<'a> {
    /// Vertex positions in scene units. All must be finite.
    pub positions: &'a [[f32; 3]],
    /// Triangle list: three indices into `positions` per triangle. An empty list is allowed (the
    /// output mesh is then empty).
    pub indices: &'a [u32],
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
pub struct AtlasOptions {
    /// Texels per scene unit (metre). None: derived from `resolution`.
    pub texels_per_unit: Option<f32>,
    /// Target atlas width and height in texels. None with texels_per_unit None: 1024.
    pub resolution: Option<u32>,
    /// Texels of padding between charts (>= 2).
    pub padding: u32,
    /// Largest page side, in texels, with `texels_per_unit` given and `resolution` not; more
    /// pages are used when the charts need them. Ignored otherwise.
    pub page_size: u32,
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
    pub xref: Vec<u32>,
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
    pub page: Vec<u32>,
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
/// xatlas-rs, and [`AtlasOptions`] for how the pages are sized (with a fixed resolution it lowers
/// the texel density until all charts fit on one page; with a fixed density it adds pages).
pub fn pack(inputs: &[AtlasInput<'_>], options: &AtlasOptions) -> Result<Atlas, AtlasError> {
    pack_estimating(inputs, options, &mut |_| {})
}

/// [`pack`], calling `estimate` once, as early as it is known, with the density the packing
/// starts from (texels per unit of the inputs): the caller's density with pages, else the
/// density the sizing packing estimates fills the fixed page (the final density is within a
/// few percent of it, after some seconds more of packing on large scenes). Not called when
/// packing fails before that.
pub fn pack_estimating(
    inputs: &[AtlasInput<'_>],
    options: &AtlasOptions,
    estimate: &mut dyn FnMut(f32),
) -> Result<Atlas, AtlasError> {
    let sizing = Sizing::from_options(options)?;
    let stats = check_inputs(inputs)?;
    if stats.triangles == 0 || stats.area <= 0.0 {
        return Err(AtlasError::Empty);
    }
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

    silence_xatlas();
    let mut xatlas = xatlas_rs::Xatlas::new();
    let handle = LAST_HANDLE.with(|h| h.replace(ptr::null_mut()));
    if handle.is_null() {
        return Err(internal(0, "xatlas Create returned no atlas"));
    }

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
        let decl = xatlas_rs::MeshDecl {
            face_ignore_data: if ignore.contains(&true) { &ignore } else { &[] },
            vertex_count: input.positions.len() as u32,
            vertex_position_data: positions_as_bytes(input.positions),
            vertex_position_stride: 12,
            index_count: input.indices.len() as u32,
            index_data: indices_as_bytes(input.indices),
            index_format: xatlas_rs::IndexFormat::Uint32,
            ..Default::default()
        };
        LAST_ADD_MESH.with(|r| r.set(None));
        xatlas.add_mesh(&decl);
        match LAST_ADD_MESH.with(|r| r.take()) {
            Some(ADD_MESH_SUCCESS) => {}
            Some(code) => {
                return Err(AtlasError::AddMesh {
                    mesh: m,
                    reason: add_mesh_error_text(code),
                });
            }
            None => return Err(internal(m, "the AddMesh shim was not called")),
        }
        added.push(m);
    }

    let chart_options = xatlas_rs::ChartOptions {
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
            Sizing::Pages { .. } => PACK_ATTEMPTS_PER_CHART,
        },
        texels_per_unit: match sizing {
            // xatlas's own guess: the page at 75% utilization.
            Sizing::Fixed {
                texels_per_unit,
                resolution,
            } => texels_per_unit
                .unwrap_or((0.75 * f64::from(resolution).powi(2) / stats.area).sqrt() as f32),
            Sizing::Pages {
                texels_per_unit, ..
            } => texels_per_unit,
        },
        resolution: match sizing {
            // The sizing packing: one page that grows.
            Sizing::Fixed { .. } => 0,
            // First try one page that grows to the packed extent, when it will likely fit.
            Sizing::Pages { page_size, .. }
                if (stats.area / 0.75).sqrt() * f64::from(pack_options_tpu(&sizing))
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
    LAST_GENERATE.with(|g| g.set(None));
    xatlas.generate_simple(chart_options, pack_options.to_xatlas_rs());
    let mut info = LAST_GENERATE
        .with(|g| g.take())
        .ok_or_else(|| internal(0, "the Generate shim was not called"))?;
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
                let meshes = output_meshes(&mut xatlas, added.len())?;
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
                // SAFETY: as for the re-packing below.
                unsafe {
                    ffi::pack_charts(handle, pack_options, None, ptr::null_mut());
                    info = PackInfo::read(handle);
                }
            }
            let meshes = output_meshes(&mut xatlas, added.len())?;
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
                    let meshes = output_meshes(&mut xatlas, added.len())?;
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
                let meshes = output_meshes(&mut xatlas, added.len())?;
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
        // SAFETY: `handle` is the atlas owned by `xatlas`, alive until it drops; charts were
        // computed and parameterized by Generate, and PackCharts may be called again (it restores
        // the original chart UVs first). It frees the output meshes, whose views were dropped.
        unsafe {
            ffi::pack_charts(handle, pack_options, None, ptr::null_mut());
            info = PackInfo::read(handle);
        }
    }
}

/// Refuses a density at which `area` (scene units²) would need more texels than one
/// [`MAX_RESOLUTION`]² page holds ([`AtlasError::TooLarge`]): xatlas packs at about 75%
/// utilization, and this is checked before it allocates huge pages.
pub fn check_density(area: f64, texels_per_unit: f32) -> Result<(), AtlasError> {
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

/// xatlas-rs's views of the output meshes, checked to be one per added mesh. The views borrow
/// memory that the next `PackCharts` or the drop of `xatlas` frees.
fn output_meshes<'a>(
    xatlas: &mut xatlas_rs::Xatlas,
    expected: usize,
) -> Result<Vec<xatlas_rs::Mesh<'a>>, AtlasError> {
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

/// With a fixed page: `None` if everything is on one page, inside it and unscaled; else the factor
/// to multiply the texel density by before packing again.
fn fixed_page_shrink(
    meshes: &[xatlas_rs::Mesh<'_>],
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
fn largest_side(boxes: &[ChartBox]) -> f32 {
    boxes
        .iter()
        .fold(0.0f32, |m, b| m.max(b.width).max(b.height))
}

/// A packed chart's UV bounding box: its page and its sides in texels.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ChartBox {
    page: u32,
    width: f32,
    height: f32,
}

/// The UV bounding box of every chart of `meshes`, in their order.
fn chart_boxes(meshes: &[xatlas_rs::Mesh<'_>]) -> Vec<ChartBox> {
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
fn boxes_area<'a>(boxes: impl Iterator<Item = &'a ChartBox>, padding: u32) -> f64 {
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
/// boxes. Where the search used to halve a bracket five or six times from a `1/sqrt(pages)`
/// guess, this guess is usually within a few per cent, so one to three packings follow it
/// (measured on the box grids, the towns and the interior).
fn fitting_density(boxes: &[ChartBox], tried: f32, padding: u32, full: f64) -> Option<f32> {
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
fn collect_output(
    inputs: &[AtlasInput<'_>],
    added: &[usize],
    meshes: &[xatlas_rs::Mesh<'_>],
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

fn internal(mesh: usize, reason: impl Into<String>) -> AtlasError {
    AtlasError::Internal {
        mesh,
        reason: reason.into(),
    }
}

/// `atlasIndex` -1 (as xatlas-rs's `u32`): a vertex of a triangle xatlas left out of every chart.
const UNCHARTED: u32 = u32::MAX;

/// `xatlas::AddMeshError::Success`.
const ADD_MESH_SUCCESS: c_int = 0;

/// The text of an `xatlas::AddMeshError` code.
fn add_mesh_error_text(code: c_int) -> String {
    match code {
        1 => "IndexOutOfRange: an index is >= the vertex count".to_owned(),
        2 => "InvalidIndexCount: the index count is not a multiple of 3".to_owned(),
        other => format!("unknown AddMesh error {other}"),
    }
}

fn positions_as_bytes(positions: &[[f32; 3]]) -> &[u8] {
    // SAFETY: [f32; 3] has no padding and any initialized bytes are valid u8s; same extent.
    unsafe { std::slice::from_raw_parts(positions.as_ptr().cast(), size_of_val(positions)) }
}

fn indices_as_bytes(indices: &[u32]) -> &[u8] {
    // SAFETY: u32 has no padding and any initialized bytes are valid u8s; same extent.
    unsafe { std::slice::from_raw_parts(indices.as_ptr().cast(), size_of_val(indices)) }
}

/// Turns off xatlas's `printf` to stdout, once per process, before any atlas is made.
fn silence_xatlas() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    // SAFETY: SetPrint only stores the function pointer and flag in globals; Once makes this
    // happen before any xatlas call of this module, on any thread.
    ONCE.call_once(|| unsafe { ffi::set_print(ptr::null(), false) });
}

/// What xatlas reports after packing: fields of `xatlas::Atlas` that xatlas-rs hides.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PackInfo {
    width: u32,
    height: u32,
    atlas_count: u32,
    chart_count: u32,
    texels_per_unit: f32,
}

impl PackInfo {
    /// Reads the packing results from an atlas.
    ///
    /// # Safety
    /// `atlas` must be a live atlas from `xatlas::Create`.
    unsafe fn read(atlas: *const ffi::Atlas) -> Self {
        // SAFETY: by the caller's contract.
        let a = unsafe { &*atlas };
        Self {
            width: a.width,
            height: a.height,
            atlas_count: a.atlas_count,
            chart_count: a.chart_count,
            texels_per_unit: a.texels_per_unit,
        }
    }
}

thread_local! {
    /// The atlas the `Create` shim last returned on this thread.
    static LAST_HANDLE: Cell<*mut ffi::Atlas> = const { Cell::new(ptr::null_mut()) };
    /// The code the `AddMesh` shim last returned on this thread.
    static LAST_ADD_MESH: Cell<Option<c_int>> = const { Cell::new(None) };
    /// What the `Generate` shim last read from its atlas on this thread.
    static LAST_GENERATE: Cell<Option<PackInfo>> = const { Cell::new(None) };
}

/// The xatlas C++ API, by its Itanium (gcc/clang) symbol names, and `#[repr(C)]` mirrors of the
/// structs it takes by value or that we read, in the field order of `vendor/xatlas.h`.
mod ffi {
    use std::ffi::{c_int, c_void};

    /// `struct xatlas::Atlas`.
    #[repr(C)]
    pub struct Atlas {
        pub width: u32,
        pub height: u32,
        pub atlas_count: u32,
        pub chart_count: u32,
        pub mesh_count: u32,
        pub meshes: *mut c_void,
        pub utilization: *mut f32,
        pub texels_per_unit: f32,
    }

    /// `struct xatlas::ChartOptions`, passed by value. xatlas-rs's bindings have the same field
    /// order as the header, and its `convert()` fills them by name.
    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct ChartOptions {
        pub max_chart_area: f32,
        pub max_boundary_length: f32,
        pub proxy_fit_metric_weight: f32,
        pub roundness_metric_weight: f32,
        pub straightness_metric_weight: f32,
        pub normal_seam_metric_weight: f32,
        pub texture_seam_metric_weight: f32,
        pub max_threshold: f32,
        pub grow_face_count: u32,
        pub max_iterations: u32,
    }

    /// `struct xatlas::PackOptions`, passed by value. Same field order in xatlas-rs's bindings.
    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct PackOptions {
        pub attempts: c_int,
        pub texels_per_unit: f32,
        pub resolution: u32,
        pub max_chart_size: u32,
        pub block_align: bool,
        pub conservative: bool,
        pub padding: u32,
    }

    impl PackOptions {
        pub fn to_xatlas_rs(self) -> xatlas_rs::PackOptions {
            xatlas_rs::PackOptions {
                attempts: self.attempts,
                texels_per_unit: self.texels_per_unit,
                resolution: self.resolution,
                max_chart_size: self.max_chart_size,
                block_align: self.block_align,
                conservative: self.conservative,
                padding: self.padding,
            }
        }
    }

    /// `xatlas::ParameterizeFunc`.
    pub type ParameterizeFunc = Option<
        unsafe extern "C" fn(
            positions: *const f32,
            texcoords: *mut f32,
            vertex_count: u32,
            indices: *const u32,
            index_count: u32,
            is_planar: bool,
        ),
    >;

    /// `xatlas::ProgressFunc`.
    pub type ProgressFunc =
        Option<unsafe extern "C" fn(category: c_int, progress: c_int, user_data: *mut c_void)>;

    unsafe extern "C" {
        /// `xatlas::Create()`.
        #[link_name = "_ZN6xatlas6CreateEv"]
        pub fn create() -> *mut Atlas;
        /// `xatlas::Destroy(Atlas*)`.
        #[link_name = "_ZN6xatlas7DestroyEPNS_5AtlasE"]
        pub fn destroy(atlas: *mut Atlas);
        /// `xatlas::AddMesh(Atlas*, const MeshDecl&)`; the `MeshDecl` is xatlas-rs's.
        #[link_name = "_ZN6xatlas7AddMeshEPNS_5AtlasERKNS_8MeshDeclE"]
        pub fn add_mesh(atlas: *mut Atlas, mesh_decl: *const c_void) -> c_int;
        /// `xatlas::Generate(Atlas*, ChartOptions, ParameterizeFunc, PackOptions, ProgressFunc,
        /// void*)`.
        #[link_name = "_ZN6xatlas8GenerateEPNS_5AtlasENS_12ChartOptionsEPFvPKfPfjPKjjbENS_11PackOptionsEPFvNS_16ProgressCategory4EnumEiPvESD_"]
        pub fn generate(
            atlas: *mut Atlas,
            chart_options: ChartOptions,
            param_func: ParameterizeFunc,
            pack_options: PackOptions,
            progress_func: ProgressFunc,
            progress_user_data: *mut c_void,
        );
        /// `xatlas::PackCharts(Atlas*, PackOptions, ProgressFunc, void*)`.
        #[link_name = "_ZN6xatlas10PackChartsEPNS_5AtlasENS_11PackOptionsEPFvNS_16ProgressCategory4EnumEiPvES5_"]
        pub fn pack_charts(
            atlas: *mut Atlas,
            pack_options: PackOptions,
            progress_func: ProgressFunc,
            progress_user_data: *mut c_void,
        );
        /// `xatlas::SetPrint(PrintFunc, bool)`; `print` is an `int (*)(const char*, ...)` or null.
        #[link_name = "_ZN6xatlas8SetPrintEPFiPKczEb"]
        pub fn set_print(print: *const c_void, verbose: bool);
    }
}

// The shims: xatlas-rs's bindings import these MSVC names (as `\u{1}?Create@...`: the name as is,
// which on ELF is the same symbol as `?Create@...`); each forwards to the Itanium symbol with the
// same signature, and keeps what xatlas-rs would drop in this thread's stash.

#[unsafe(export_name = "?Create@xatlas@@YAPEAUAtlas@1@XZ")]
unsafe extern "C" fn xatlas_create_shim() -> *mut ffi::Atlas {
    // SAFETY: forwards the call xatlas-rs made, with the same signature.
    let atlas = unsafe { ffi::create() };
    let _ = LAST_HANDLE.try_with(|h| h.set(atlas));
    atlas
}

#[unsafe(export_name = "?Destroy@xatlas@@YAXPEAUAtlas@1@@Z")]
unsafe extern "C" fn xatlas_destroy_shim(atlas: *mut ffi::Atlas) {
    let _ = LAST_HANDLE.try_with(|h| {
        if h.get() == atlas {
            h.set(ptr::null_mut());
        }
    });
    // SAFETY: forwards the call xatlas-rs made, with the same signature.
    unsafe { ffi::destroy(atlas) }
}

#[unsafe(export_name = "?AddMesh@xatlas@@YA?AW4Enum@AddMeshError@1@PEAUAtlas@1@AEBUMeshDecl@1@@Z")]
unsafe extern "C" fn xatlas_add_mesh_shim(
    atlas: *mut ffi::Atlas,
    mesh_decl: *const c_void,
) -> c_int {
    // SAFETY: forwards the call xatlas-rs made, with the same signature.
    let result = unsafe { ffi::add_mesh(atlas, mesh_decl) };
    let _ = LAST_ADD_MESH.try_with(|r| r.set(Some(result)));
    result
}

#[unsafe(export_name = "?Generate@xatlas@@YAXPEAUAtlas@1@UChartOptions@1@P6AXPEBMPEAMIPEBII_N@ZUPackOptions@1@P6AXW4Enum@ProgressCategory@1@HPEAX@Z9@Z")]
unsafe extern "C" fn xatlas_generate_shim(
    atlas: *mut ffi::Atlas,
    chart_options: ffi::ChartOptions,
    param_func: ffi::ParameterizeFunc,
    pack_options: ffi::PackOptions,
    progress_func: ffi::ProgressFunc,
    progress_user_data: *mut c_void,
) {
    // SAFETY: forwards the call xatlas-rs made, with the same signature; `atlas` is then live.
    unsafe {
        ffi::generate(
            atlas,
            chart_options,
            param_func,
            pack_options,
            progress_func,
            progress_user_data,
        );
        if !atlas.is_null() {
            let info = PackInfo::read(atlas);
            let _ = LAST_GENERATE.try_with(|g| g.set(Some(info)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    /// An owned test mesh.
    #[derive(Debug, Clone, Default)]
    struct TestMesh {
        positions: Vec<[f32; 3]>,
        indices: Vec<u32>,
    }

    impl TestMesh {
        fn input(&self) -> AtlasInput<'_> {
            AtlasInput {
                positions: &self.positions,
                indices: &self.indices,
            }
        }
    }

    fn inputs(meshes: &[TestMesh]) -> Vec<AtlasInput<'_>> {
        meshes.iter().map(TestMesh::input).collect()
    }

    /// A `w` x `h` quad in the plane z = `z`, lower corner at (`x`, `y`): two triangles.
    fn quad(x: f32, y: f32, z: f32, w: f32, h: f32) -> TestMesh {
        TestMesh {
            positions: vec![[x, y, z], [x + w, y, z], [x + w, y + h, z], [x, y + h, z]],
            indices: vec![0, 1, 2, 0, 2, 3],
        }
    }

    /// A cube of side `size` at `origin`, 8 shared corners, 12 outward triangles.
    fn cube(origin: [f32; 3], size: f32) -> TestMesh {
        let positions = (0..8)
            .map(|i| [0, 1, 2].map(|axis| origin[axis] + size * ((i >> axis) & 1) as f32))
            .collect();
        // Corner i has x = bit 0, y = bit 1, z = bit 2, as `BOX_FACES` numbers them.
        let indices = crate::geometry::BOX_FACES
            .iter()
            .flat_map(|q| [q[0], q[1], q[2], q[0], q[2], q[3]])
            .collect();
        TestMesh { positions, indices }
    }

    /// A connected `n` x `n` grid of quads (2n² triangles) over `size` x `size`, with a height
    /// bump of amplitude `bump`.
    fn grid(n: u32, size: f32, bump: f32) -> TestMesh {
        let mut positions = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let x = i as f32 / n as f32 * size;
                let y = j as f32 / n as f32 * size;
                positions.push([x, y, bump * (x * 3.0).sin() * (y * 2.0).cos()]);
            }
        }
        let w = n + 1;
        let mut indices = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = j * w + i;
                indices.extend_from_slice(&[a, a + 1, a + w + 1, a, a + w + 1, a + w]);
            }
        }
        TestMesh { positions, indices }
    }

    fn options(
        texels_per_unit: Option<f32>,
        resolution: Option<u32>,
        padding: u32,
    ) -> AtlasOptions {
        AtlasOptions {
            texels_per_unit,
            resolution,
            padding,
            page_size: DEFAULT_PAGE_SIZE,
        }
    }

    /// Checks the mapping back to the inputs and the bounds: output triangle k comes from input
    /// triangle k, corner by corner; every UV is inside the page.
    fn check_mapping(inputs: &[AtlasInput<'_>], atlas: &Atlas) {
        assert_eq!(atlas.meshes.len(), inputs.len());
        for (m, (input, mesh)) in inputs.iter().zip(&atlas.meshes).enumerate() {
            assert_eq!(mesh.xref.len(), mesh.uv.len(), "mesh {m}");
            assert_eq!(mesh.indices.len(), input.indices.len(), "mesh {m}");
            for (k, (o, i)) in mesh.indices.iter().zip(input.indices).enumerate() {
                assert_eq!(mesh.xref[*o as usize], *i, "mesh {m} index {k}");
            }
            for uv in &mesh.uv {
                assert!(
                    (0.0..=atlas.width as f32).contains(&uv[0])
                        && (0.0..=atlas.height as f32).contains(&uv[1]),
                    "mesh {m}: UV {uv:?} outside {}x{}",
                    atlas.width,
                    atlas.height
                );
            }
        }
    }

    type Uv = [f32; 2];

    fn cross(o: Uv, a: Uv, b: Uv) -> f32 {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    }

    fn tri_area(t: &[Uv; 3]) -> f32 {
        0.5 * cross(t[0], t[1], t[2])
    }

    fn point_segment_distance(p: Uv, a: Uv, b: Uv) -> f32 {
        let ab = [b[0] - a[0], b[1] - a[1]];
        let ap = [p[0] - a[0], p[1] - a[1]];
        let len2 = ab[0] * ab[0] + ab[1] * ab[1];
        let t = if len2 > 0.0 {
            ((ap[0] * ab[0] + ap[1] * ab[1]) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = [ap[0] - t * ab[0], ap[1] - t * ab[1]];
        (d[0] * d[0] + d[1] * d[1]).sqrt()
    }

    fn segment_distance(p: [Uv; 2], q: [Uv; 2]) -> f32 {
        let d1 = cross(q[0], q[1], p[0]);
        let d2 = cross(q[0], q[1], p[1]);
        let d3 = cross(p[0], p[1], q[0]);
        let d4 = cross(p[0], p[1], q[1]);
        if d1 * d2 < 0.0 && d3 * d4 < 0.0 {
            return 0.0;
        }
        point_segment_distance(p[0], q[0], q[1])
            .min(point_segment_distance(p[1], q[0], q[1]))
            .min(point_segment_distance(q[0], p[0], p[1]))
            .min(point_segment_distance(q[1], p[0], p[1]))
    }

    fn inside(p: Uv, t: &[Uv; 3]) -> bool {
        let s = [0, 1, 2].map(|k| cross(t[k], t[(k + 1) % 3], p));
        s.iter().all(|&c| c >= 0.0) || s.iter().all(|&c| c <= 0.0)
    }

    /// Distance between two UV triangles: 0 if they overlap.
    fn triangle_distance(a: &[Uv; 3], b: &[Uv; 3]) -> f32 {
        if a.iter().any(|&p| inside(p, b)) || b.iter().any(|&p| inside(p, a)) {
            return 0.0;
        }
        let mut d = f32::INFINITY;
        for i in 0..3 {
            for j in 0..3 {
                d = d.min(segment_distance(
                    [a[i], a[(i + 1) % 3]],
                    [b[j], b[(j + 1) % 3]],
                ));
            }
        }
        d
    }

    /// The UV triangles of the atlas that cover area, each with its chart (charts are the
    /// connected components of output vertices; output vertices are never shared across charts).
    fn charted_triangles(atlas: &Atlas) -> Vec<(usize, [Uv; 3])> {
        let mut out = Vec::new();
        let mut chart_base = 0;
        for mesh in &atlas.meshes {
            let n = mesh.uv.len();
            let mut parent: Vec<usize> = (0..n).collect();
            fn find(parent: &mut [usize], mut i: usize) -> usize {
                while parent[i] != i {
                    parent[i] = parent[parent[i]];
                    i = parent[i];
                }
                i
            }
            for t in mesh.indices.chunks_exact(3) {
                let r0 = find(&mut parent, t[0] as usize);
                for &v in &t[1..] {
                    let r = find(&mut parent, v as usize);
                    parent[r] = r0;
                }
            }
            for t in mesh.indices.chunks_exact(3) {
                let uv = [0, 1, 2].map(|k| mesh.uv[t[k] as usize]);
                if tri_area(&uv).abs() > 1e-6 {
                    out.push((chart_base + find(&mut parent, t[0] as usize), uv));
                }
            }
            chart_base += n;
        }
        out
    }

    /// Checks that no two charts overlap and that triangles within a chart keep one winding (no
    /// flipped triangles); returns the smallest UV distance between triangles of different
    /// charts, in texels, and the number of charts.
    fn check_charts(atlas: &Atlas) -> (f32, usize) {
        let tris = charted_triangles(atlas);
        let mut winding = std::collections::HashMap::new();
        for (chart, t) in &tris {
            let sign = tri_area(t) > 0.0;
            assert_eq!(
                *winding.entry(*chart).or_insert(sign),
                sign,
                "flipped triangle in chart"
            );
        }
        let mut min = f32::INFINITY;
        for (i, (ca, a)) in tris.iter().enumerate() {
            for (cb, b) in &tris[i + 1..] {
                if ca != cb {
                    min = min.min(triangle_distance(a, b));
                }
            }
        }
        assert!(min > 0.0, "charts overlap");
        (min, winding.len())
    }

    /// The UV area, in texels², of one output mesh.
    fn uv_area(mesh: &AtlasMesh) -> f32 {
        mesh.indices
            .chunks_exact(3)
            .map(|t| tri_area(&[0, 1, 2].map(|k| mesh.uv[t[k] as usize])).abs())
            .sum()
    }

    #[test]
    fn quads_and_cube_are_charted_without_overlap_and_with_padding() {
        let meshes = [
            quad(0.0, 0.0, 0.0, 1.0, 1.0),
            quad(5.0, 0.0, 1.0, 1.0, 1.0),
            cube([2.0, 2.0, 2.0], 1.0),
        ];
        let inputs = inputs(&meshes);
        for padding in [2, 4] {
            let atlas = pack(&inputs, &options(Some(16.0), None, padding)).unwrap();
            check_mapping(&inputs, &atlas);
            let (min, charts) = check_charts(&atlas);
            println!(
                "padding {padding}: {}x{} texels, {charts} charts, smallest gap between charts \
                 {min:.3} texels",
                atlas.width, atlas.height
            );
            // Observed: exactly padding + 1 texels (xatlas dilates each chart by `padding`).
            assert!(min >= padding as f32, "gap {min} for padding {padding}");
            assert_eq!(atlas.texels_per_unit, 16.0);
            // Every input vertex is used by some output vertex; seams only add vertices.
            for (mesh, input) in atlas.meshes.iter().zip(&inputs) {
                assert!(mesh.xref.len() >= input.positions.len());
            }
        }
    }

    #[test]
    fn fitting_density_solves_for_the_box_area_a_full_page_held() {
        // 100 charts of 10 x 10 texels, half of them on the first page: with 2 texels of
        // padding each takes (10 s + 3.5)² texels² at s times the density, and all of them
        // must take what 50 took at s = 1: 100 (10 s + 3.5)² = 50 × 13.5², s = 0.6046.
        let boxes: Vec<ChartBox> = (0..100)
            .map(|i| ChartBox {
                page: i / 50,
                width: 10.0,
                height: 10.0,
            })
            .collect();
        let full = boxes_area(boxes.iter().filter(|b| b.page == 0), 2);
        let s = fitting_density(&boxes, 20.0, 2, full).unwrap() / 20.0;
        let expected = ((50.0f64 * 13.5 * 13.5 / 100.0).sqrt() - 3.5) / 10.0;
        assert!(
            (f64::from(s) - expected).abs() < 1e-5,
            "{s} against {expected}"
        );
        // Charts so small that their padding alone overflows: no estimate.
        let specks: Vec<ChartBox> = (0..100)
            .map(|i| ChartBox {
                page: u32::from(i >= 30),
                width: 0.1,
                height: 0.1,
            })
            .collect();
        let full = boxes_area(specks.iter().filter(|b| b.page == 0), 2);
        assert_eq!(fitting_density(&specks, 20.0, 2, full), None);
    }

    #[test]
    fn unit_quad_at_32_texels_per_unit_covers_about_32_by_32_texels() {
        let meshes = [quad(0.0, 0.0, 0.0, 1.0, 1.0)];
        let atlas = pack(&inputs(&meshes), &options(Some(32.0), None, 2)).unwrap();
        let area = uv_area(&atlas.meshes[0]);
        println!(
            "unit quad: {area} texels², atlas {}x{}",
            atlas.width, atlas.height
        );
        assert!((area - 1024.0).abs() <= 102.4, "{area}");
        assert_eq!(atlas.texels_per_unit, 32.0);
    }

    #[test]
    fn a_chart_longer_than_1024_texels_keeps_its_density() {
        // xatlas's default maxChartSize (1024) would silently scale this 1280-texel wall down.
        let meshes = [quad(0.0, 0.0, 0.0, 40.0, 1.0)];
        let atlas = pack(&inputs(&meshes), &options(Some(32.0), None, 2)).unwrap();
        check_mapping(&inputs(&meshes), &atlas);
        let area = uv_area(&atlas.meshes[0]);
        assert!(
            atlas.width.max(atlas.height) >= 1280,
            "{}x{}",
            atlas.width,
            atlas.height
        );
        assert!((area / (40.0 * 1024.0) - 1.0).abs() < 0.05, "{area}");
    }

    #[test]
    fn default_options_give_one_1024_page() {
        let meshes = [quad(0.0, 0.0, 0.0, 1.0, 1.0), cube([3.0, 0.0, 0.0], 2.0)];
        let inputs = inputs(&meshes);
        let atlas = pack(&inputs, &AtlasOptions::default()).unwrap();
        assert_eq!((atlas.width, atlas.height), (1024, 1024));
        check_mapping(&inputs, &atlas);
        check_charts(&atlas);
        println!("default options: {} texels per unit", atlas.texels_per_unit);
    }

    #[test]
    fn too_many_charts_for_the_page_lower_the_density_until_one_page_holds_them() {
        let meshes: Vec<_> = (0..10)
            .map(|i| quad(2.0 * i as f32, 0.0, 0.0, 1.0, 1.0))
            .collect();
        let inputs = inputs(&meshes);
        let atlas = pack(&inputs, &options(Some(64.0), Some(128), 2)).unwrap();
        println!(
            "10 unit quads on 128²: {} texels per unit",
            atlas.texels_per_unit
        );
        assert_eq!((atlas.width, atlas.height), (128, 128));
        assert!(atlas.texels_per_unit < 64.0);
        check_mapping(&inputs, &atlas);
        check_charts(&atlas);
        // Density stays uniform: xatlas only rounds each chart up to whole texels.
        let tpu = atlas.texels_per_unit;
        for mesh in &atlas.meshes {
            let area = uv_area(mesh);
            assert!(
                area >= tpu * tpu * 0.999 && area <= (tpu + 1.0) * (tpu + 1.0),
                "{area}"
            );
        }
    }

    #[test]
    fn with_a_fixed_density_charts_spill_onto_more_pages() {
        let meshes: Vec<_> = (0..10)
            .map(|i| quad(2.0 * i as f32, 0.0, 0.0, 1.0, 1.0))
            .collect();
        let inputs = inputs(&meshes);
        let opts = AtlasOptions {
            page_size: 128,
            ..options(Some(64.0), None, 2)
        };
        let atlas = pack(&inputs, &opts).unwrap();
        println!(
            "10 unit quads at 64 texels per unit on 128² pages: {} pages of {}x{}",
            atlas.pages, atlas.width, atlas.height
        );
        assert!(atlas.pages > 1);
        assert!(atlas.width <= 128 && atlas.height <= 128);
        assert_eq!(atlas.texels_per_unit, 64.0);
        check_mapping(&inputs, &atlas);
        let mut used = std::collections::BTreeSet::new();
        for mesh in &atlas.meshes {
            assert_eq!(mesh.page.len(), mesh.indices.len() / 3);
            assert!(mesh.page.iter().all(|&p| p < atlas.pages));
            used.extend(mesh.page.iter().copied());
            // Density kept: each unit quad covers about 64² texels.
            let area = uv_area(mesh);
            assert!((area / 4096.0 - 1.0).abs() < 0.05, "{area}");
        }
        assert_eq!(used.len(), atlas.pages as usize, "every page is used");
        // The same charts with a large page: one page.
        let one = pack(&inputs, &options(Some(64.0), None, 2)).unwrap();
        assert_eq!(one.pages, 1);
    }

    /// Charts that cannot fit a page at any density fail fast: at once when their padding
    /// alone overflows it, else once every chart is at its smallest (not after halving the
    /// density [`MAX_PACK_ATTEMPTS`] times).
    #[test]
    fn charts_that_fit_at_no_density_fail_within_a_few_packings() {
        // `n` separate 1 x 1 quads on a 32² page with 2 texels of padding: each takes at least
        // 3² texels² (200: 1 800, more than the page's 1 024), and at its smallest 4² (80:
        // 1 280, also more, though 80 x 3² = 720 is not).
        for (n, most) in [(200, 1), (80, 12)] {
            let meshes: Vec<TestMesh> = (0..n)
                .map(|i| quad(3.0 * (i % 20) as f32, 3.0 * (i / 20) as f32, 0.0, 1.0, 1.0))
                .collect();
            let err = pack(&inputs(&meshes), &options(None, Some(32), 2)).unwrap_err();
            println!("{n} quads: {err}");
            match err {
                AtlasError::DoesNotFit {
                    resolution: 32,
                    attempts,
                    ..
                } => assert!(attempts <= most, "{attempts} packings for {n} quads"),
                err => panic!("{err}"),
            }
        }
        // 50 of them take 4² texels² each at their smallest (800 of the page's 1 024): they
        // fit, though not with 2-texel-wide charts (5² each, 1 250).
        let meshes: Vec<TestMesh> = (0..50)
            .map(|i| quad(3.0 * (i % 20) as f32, 3.0 * (i / 20) as f32, 0.0, 1.0, 1.0))
            .collect();
        let atlas = pack(&inputs(&meshes), &options(None, Some(32), 2)).unwrap();
        println!("50 quads: {} texels per unit", atlas.texels_per_unit);
    }

    #[test]
    fn with_a_fixed_density_a_chart_larger_than_the_page_is_an_error() {
        let meshes = [quad(0.0, 0.0, 0.0, 4.0, 1.0)];
        let opts = AtlasOptions {
            page_size: 64,
            ..options(Some(32.0), None, 2)
        };
        let err = pack(&inputs(&meshes), &opts).unwrap_err();
        println!("{err}");
        assert!(
            matches!(err, AtlasError::ChartTooLarge { page_size: 64, .. }),
            "{err}"
        );
        assert!(err.to_string().contains("64x64"), "{err}");
    }

    #[test]
    fn a_chart_larger_than_the_page_lowers_the_density() {
        let meshes = [quad(0.0, 0.0, 0.0, 4.0, 1.0)];
        let inputs = inputs(&meshes);
        let atlas = pack(&inputs, &options(Some(32.0), Some(64), 2)).unwrap();
        let tpu = atlas.texels_per_unit;
        println!("4x1 quad on 64²: {tpu} texels per unit");
        assert_eq!((atlas.width, atlas.height), (64, 64));
        assert!(4.0 * tpu <= 64.0);
        check_mapping(&inputs, &atlas);
        let area = uv_area(&atlas.meshes[0]);
        assert!(area >= 4.0 * tpu * tpu * 0.999 && area <= (4.0 * tpu + 1.0) * (tpu + 1.0));
    }

    #[test]
    fn bad_inputs_are_errors() {
        let good = quad(0.0, 0.0, 0.0, 1.0, 1.0);
        let opts = AtlasOptions::default();

        let mut nan = good.clone();
        nan.positions[2][1] = f32::NAN;
        let err = pack(&[good.input(), nan.input()], &opts).unwrap_err();
        assert!(
            matches!(err, AtlasError::InvalidInput { mesh: 1, .. }),
            "{err}"
        );
        println!("{err}");

        let mut inf = good.clone();
        inf.positions[0][0] = f32::INFINITY;
        let err = pack(&[inf.input()], &opts).unwrap_err();
        assert!(
            matches!(err, AtlasError::InvalidInput { mesh: 0, .. }),
            "{err}"
        );

        let mut out_of_range = good.clone();
        out_of_range.indices[4] = 4;
        let err = pack(&[out_of_range.input()], &opts).unwrap_err();
        assert!(
            matches!(err, AtlasError::InvalidInput { mesh: 0, .. }),
            "{err}"
        );
        println!("{err}");

        let mut not_triangles = good.clone();
        not_triangles.indices.pop();
        let err = pack(&[not_triangles.input()], &opts).unwrap_err();
        assert!(
            matches!(err, AtlasError::InvalidInput { mesh: 0, .. }),
            "{err}"
        );
        println!("{err}");

        assert!(matches!(pack(&[], &opts), Err(AtlasError::Empty)));
        let empty = TestMesh::default();
        assert!(matches!(
            pack(&[empty.input()], &opts),
            Err(AtlasError::Empty)
        ));
        let degenerate = TestMesh {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
            indices: vec![0, 1, 2, 0, 0, 1],
        };
        assert!(matches!(
            pack(&[degenerate.input()], &opts),
            Err(AtlasError::Empty)
        ));

        for bad in [
            options(None, None, 1),
            options(Some(f32::NAN), None, 2),
            options(Some(0.0), None, 2),
            options(Some(-1.0), None, 2),
            options(None, Some(0), 2),
            options(None, Some(MAX_RESOLUTION + 1), 2),
            options(None, Some(4), 3),
        ] {
            let err = pack(&[good.input()], &bad).unwrap_err();
            assert!(
                matches!(err, AtlasError::InvalidOptions { .. }),
                "{bad:?}: {err}"
            );
        }
        let err = pack(&[good.input()], &options(Some(1e5), None, 2)).unwrap_err();
        assert!(matches!(err, AtlasError::TooLarge { .. }), "{err}");
        println!("{err}");
    }

    #[test]
    fn empty_and_degenerate_parts_are_kept_in_place() {
        let empty = TestMesh {
            positions: vec![[0.0; 3]],
            indices: vec![],
        };
        let mut with_degenerate = quad(0.0, 0.0, 0.0, 1.0, 1.0);
        with_degenerate.indices.extend_from_slice(&[0, 1, 1]);
        let only_degenerate = TestMesh {
            positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
            indices: vec![0, 1, 2, 2, 2, 0],
        };
        let meshes = [
            empty,
            with_degenerate,
            quad(3.0, 0.0, 0.0, 1.0, 1.0),
            only_degenerate,
        ];
        let inputs = inputs(&meshes);
        let atlas = pack(&inputs, &options(Some(16.0), None, 2)).unwrap();
        assert_eq!(atlas.meshes[0], AtlasMesh::default());
        check_mapping(&inputs, &atlas);
        check_charts(&atlas);
        let mesh = &atlas.meshes[1];
        let degenerate = &mesh.indices[6..9];
        assert!(
            degenerate
                .iter()
                .all(|&v| mesh.uv[v as usize] == [0.0, 0.0])
        );
        assert!(atlas.meshes[3].uv.iter().all(|&uv| uv == [0.0, 0.0]));
        assert_eq!(atlas.meshes[3].indices.len(), 6);
    }

    /// A speck (here one of a real city's 0.1 mm needles, in the units the bake hands the atlas:
    /// the scene scaled to 1000 units²) is left out of the charts with UV (0, 0); charted,
    /// xatlas drew it as a line a page long and the atlas refused the scene.
    #[test]
    fn specks_are_left_out_of_the_charts() {
        let mut meshes = vec![quad(-15.0, 0.0, -15.0, 31.6, 31.6)];
        meshes.push(TestMesh {
            positions: vec![
                [2.6446366, -0.43683144, 1.4284033],
                [2.6437597, -0.4320338, 1.4275247],
                [2.6436608, -0.4320338, 1.4276116],
            ],
            indices: vec![0, 1, 2],
        });
        let inputs = inputs(&meshes);
        let speck = triangle_areas(&inputs[1]).sum::<f64>();
        let total = check_inputs(&inputs).unwrap().area;
        assert!(speck > f64::from(f32::EPSILON) && speck < SPECK_AREA * total);
        let atlas = pack(&inputs, &options(Some(10.0), None, 4)).unwrap();
        check_mapping(&inputs, &atlas);
        check_charts(&atlas);
        assert!(atlas.meshes[1].uv.iter().all(|&uv| uv == [0.0, 0.0]));
        assert!(atlas.meshes[0].uv.iter().any(|&uv| uv != [0.0, 0.0]));
    }

    #[test]
    fn add_mesh_errors_are_caught_by_the_shim() {
        let positions = [[0.0f32; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let xatlas = xatlas_rs::Xatlas::new();
        for (indices, expected) in [
            (vec![0u32, 1, 3], 1),
            (vec![0, 1, 2, 0], 2),
            (vec![0, 1, 2], 0),
        ] {
            LAST_ADD_MESH.with(|r| r.set(None));
            xatlas.add_mesh(&xatlas_rs::MeshDecl {
                vertex_count: 3,
                vertex_position_data: positions_as_bytes(&positions),
                vertex_position_stride: 12,
                index_count: indices.len() as u32,
                index_data: indices_as_bytes(&indices),
                index_format: xatlas_rs::IndexFormat::Uint32,
                ..Default::default()
            });
            assert_eq!(
                LAST_ADD_MESH.with(|r| r.take()),
                Some(expected),
                "{indices:?}"
            );
        }
        assert!(add_mesh_error_text(1).starts_with("IndexOutOfRange"));
    }

    /// Every bit of an atlas, for exact comparison.
    fn bits(atlas: &Atlas) -> Vec<u32> {
        let mut out = vec![
            atlas.width,
            atlas.height,
            atlas.pages,
            atlas.texels_per_unit.to_bits(),
        ];
        for mesh in &atlas.meshes {
            out.push(mesh.xref.len() as u32);
            out.extend(&mesh.xref);
            out.extend(&mesh.page);
            out.extend(mesh.uv.iter().flat_map(|uv| uv.map(f32::to_bits)));
            out.extend(&mesh.indices);
        }
        out
    }

    #[test]
    fn output_is_deterministic_also_across_threads() {
        let meshes = [
            quad(0.0, 0.0, 0.0, 1.0, 1.0),
            cube([2.0, 0.0, 0.0], 1.0),
            grid(24, 2.0, 0.3),
            quad(0.0, 3.0, 1.0, 2.0, 0.5),
        ];
        let inputs = inputs(&meshes);
        let opts = options(None, Some(256), 2);
        let first = bits(&pack(&inputs, &opts).unwrap());
        let second = bits(&pack(&inputs, &opts).unwrap());
        assert!(first == second, "two runs differ");
        let (a, b) = std::thread::scope(|s| {
            let a = s.spawn(|| pack(&inputs, &opts).map(|atlas| bits(&atlas)));
            let b = s.spawn(|| pack(&inputs, &opts).map(|atlas| bits(&atlas)));
            (a.join().unwrap(), b.join().unwrap())
        });
        assert!(a.unwrap() == first, "thread 1 differs");
        assert!(b.unwrap() == first, "thread 2 differs");
    }

    #[test]
    fn a_20k_triangle_connected_grid_packs_into_a_valid_mapping() {
        let meshes = [grid(100, 10.0, 0.0)];
        let inputs = inputs(&meshes);
        let start = Instant::now();
        let atlas = pack(&inputs, &AtlasOptions::default()).unwrap();
        println!(
            "20k-triangle grid: {:.2} s, {} output vertices, {} texels per unit",
            start.elapsed().as_secs_f64(),
            atlas.meshes[0].xref.len(),
            atlas.texels_per_unit
        );
        check_mapping(&inputs, &atlas);
    }
}
