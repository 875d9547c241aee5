//! The indirect light by hierarchical radiosity with clustering (`--solver hierarchical`).
//!
//! Papers: Hanrahan, Salzman, Aupperle, "A rapid hierarchical radiosity algorithm", SIGGRAPH
//! 1991 (links between nodes of a hierarchy, refined by a `B F A` oracle; gather, push-pull);
//! Lischinski, Tampieri, Greenberg, "Combining hierarchical radiosity and discontinuity
//! meshing", SIGGRAPH 1993 (the leaves are the discontinuity mesh's elements, so no link ever
//! averages across a shadow boundary or a contact); Smits, Arvo, Greenberg, "A clustering
//! algorithm for radiosity in complex environments", SIGGRAPH 1994, and Sillion, "A unified
//! hierarchical algorithm for global illumination with scattering volumes and object
//! clusters", IEEE TVCG 1995 (clusters of surfaces above the polygons, so the number of links
//! grows with the number of elements, not its square).
//!
//! One file per part: `tree.rs` (the hierarchy, its sample points and outlines),
//! `transfer.rs` (the estimate of one link, the visibility of its sample pairs, the geometric
//! bounds), `refine.rs` (the oracle and the refinement passes), `gather.rs` (gather,
//! push-pull, the sources' radiosity gradients), `vertex.rs` (the values at the vertices);
//! [`indirect_with_layers`] here runs the passes and the Jacobi iterations. What was tried and
//! measured on the way is in `docs/decisions.md` ("Indirect light"); the accuracy and speed as
//! they are, in `docs/accuracy.md` and `docs/performance.md`.
//!
//! # Why
//!
//! The progressive solver gathers every coarse patch at every mesh vertex: O(vertices ×
//! patches) rays, and a patch that straddles a contact averages its dark and lit parts. Here
//! light moves along *links* between nodes of a hierarchy, each link as coarse as the power it
//! carries allows: distant or dim exchanges use one link between two clusters, bright close
//! ones go down to single mesh elements. The leaves are the receiver mesh's triangles, which
//! never cross a discontinuity or contact line, so the finest links resolve exactly what the
//! mesher resolved.
//!
//! # Hierarchy
//!
//! * **Leaves**: the triangles of every [`ReceiverMesh`] (one *element* each), with their
//!   direct irradiance = the mean of their three vertices' exact direct values. An element
//!   that faces only the inside of closed geometry (the floor under a box standing on it: all
//!   of nine fixed rays from its centroid hit the back of a surface) is left out: no light
//!   reaches it and no one sees it, and as part of a coarse source it would dilute that
//!   source's mean radiosity.
//! * **Surface nodes**: per receiver polygon, a binary tree of its elements, split at the
//!   median element centroid along the longer axis of their bounding box in the polygon's 2D
//!   frame. A surface node lies in one plane and has that plane's normal.
//! * **Clusters**: above the polygons' roots, a top-down median split of the polygons' 3D
//!   bounding-box centres along the longest axis, up to one root.
//!
//! Every node stores its area (scene units²), area-weighted reflectance, bounding box, centre
//! (area-weighted centroid) and bounding radius about the centre. Nodes are numbered children
//! before parents, and each covers a contiguous range of elements.
//!
//! # Links and the transport coefficient
//!
//! A link `r ← s` carries a transport coefficient `K` (dimensionless): the mean irradiance it
//! adds over the receiver node `r` per unit radiosity of the source node `s`, i.e. the
//! area-averaged form factor `F(r→s)`, with visibility. So `H_r += K B_s` (W/m²), and the link
//! carries the power `K B_s A_r` (W).
//!
//! `K` is estimated from up to four fixed sample points per node (a leaf: the three points of
//! Cowper's rule, at barycentric (2/3, 1/6, 1/6) and its permutations, exact for quadratics
//! (G. R. Cowper, "Gaussian quadrature formulas for triangles", IJNME 1973); a larger node: the
//! centroids of the elements at the 1/8, 3/8, 5/8, 7/8 points of its area, each on an element
//! of its own):
//!
//! * **Surface to surface** (both nodes in one plane each): the exact unoccluded
//!   point-to-polygon form factor (Lambert's contour formula) from each receiver sample to the
//!   source (the disk formula below, about the source's centre, once the sample is more than
//!   [`FAR_FIELD`] bounding radii away), averaged over the receiver samples, times the visible
//!   fraction of the sample pairs (at most 4 × 4). When the source's bounding box is above the
//!   sample's horizon the contour sum runs over the source node's *outline* only (its element edges
//!   whose reverse is not in the node: interior edges cancel in the contour sum), so a large
//!   source costs its boundary, not its area (collinear runs of outline edges are merged into
//!   one: a straight edge's term is the sum of its pieces'); a source straddling the horizon
//!   with at most `CONTOUR_ELEMENTS` elements is summed per element, each clipped to the
//!   horizon ([`crate::geometry::point_polygon_form_factor`]); a larger straddling source
//!   falls to the disk estimate below. A sample behind the source's plane gets zero: a surface
//!   radiates from its front only.
//! * **Otherwise** (either end a cluster, or a large straddling source): per sample pair
//!   `(i, j)` the disk approximation `A_s cos_i cos_j / (π d_ij² + A_s / n_s)`, each of the
//!   `n_s` source samples standing for its share of the source's area (exact on the axis of a
//!   disk of that share), with `cos` taken at each end from that sample's own element normal
//!   and clamped at zero, times the pair's visibility, averaged over the pairs. At a cluster
//!   end this is a *sampled* orientation model rather than Sillion's isotropic one (the
//!   isotropic model replaces the cosine at a cluster end by 1/4, the mean of `max(cos, 0)`
//!   over the sphere): the samples are surfaces of the cluster, so a cluster whose surfaces
//!   face away from the other end neither sends nor receives. The irradiance a cluster
//!   receives is then pushed unchanged to all its surfaces (the cluster's mean irradiance),
//!   whichever way each faces: that is where a cluster link is coarse, and why the oracle
//!   below bounds the power such a link may carry and the irradiance it may bring to a
//!   cluster (see "Cluster receivers").
//!
//! Visibility: one shadow ray per sample pair with `cos > 0` at both ends
//! ([`Visibility::occluded_skipping`] between the two points' ray origins, each offset off its
//! surface like [`crate::light::SurfacePoint::new`], skipping the two points' own polygons), in
//! two stages: first the pairs `(k mod 4, k mod 4)`, one per sample; when at least two are
//! tested and all agree (all visible or all hidden), the other pairs are taken to agree too,
//! else every pair is cast (a surface-to-surface link whose first pairs disagree is settled by
//! them alone, see "Partial visibility" below). Most links are wholly visible, so this casts
//! about half the rays. Deterministic points, no randomness.
//!
//! Pairs that carry nothing are never linked: two nodes of one plane (a planar polygon does not
//! see itself), a source whose bounding box lies behind (or in) a surface receiver's plane, a
//! receiver whose box lies behind a surface source's plane, and sources of zero reflectance
//! (their indirect radiosity is always zero; their emission is in the direct light).
//!
//! # Refinement
//!
//! From the root-to-root link, a link `r ← s` is refined while any test of the oracle fails:
//!
//! * **Power** (Hanrahan et al.'s `B F A`): the bound `B_s K̂ A_r` on the power the link
//!   carries exceeds `hr_tolerance × P`, where `P` is the total reflected direct power (W, the
//!   power the indirect solve starts from). For surface-to-surface links `K̂` is the
//!   unoccluded `K` (a partially visible link has its shadow unresolved, so the whole
//!   unoccluded transfer is at stake; a wholly visible one has `K` = the unoccluded `K`). For
//!   links with a cluster end the four samples may miss the surfaces that matter, so the
//!   power is bounded geometrically: `K̂ = min(A_s / (π g² + A_s), (R_s / d)²)`, the point form
//!   factor with both cosines bounded by 1 (`g` the smallest possible distance between the
//!   nodes' bounding spheres, 0 when they overlap) and the projected solid angle of the
//!   source's bounding sphere (radius `R_s`, at least `d` away); and by reciprocity
//!   (`A_r F(r→s) = A_s F(s→r)`) the power is also at most `A_s` times the same bound seen
//!   from the source, so a large ground plane beside a small cluster is bounded by what the
//!   cluster sends. Where the spheres are apart, also by the nodes' orientations: every pair's
//!   direction lies in the cone between the two spheres, and each node stores its projected
//!   area along the six axis directions, so `A_r F(r→s) ≤ P_r P_s / (π g²)` with `P` the most
//!   projected area a node can show along the cone
//!   ([`projected_bound`](transfer::projected_bound)). So `--hr-tolerance` is the largest
//!   fraction of the reflected direct power one link may carry (dimensionless); the variation,
//!   source and visibility limits below scale with it from its default ([`Limits::of_bake`]:
//!   see "The tolerance as a dial"). The node of larger area that has children is split.
//! * **Variation** (the receiver-side test of Lischinski, Tampieri, Greenberg 1993 and
//!   Holzschuch, Sillion, "An exhaustive error-bounding algorithm for hierarchical radiosity",
//!   CGF 1998, with the sample spread in place of their analytic bounds): for a
//!   surface-to-surface link, `B_s (f_max − f_min)`, the spread of the unoccluded
//!   point-to-source form factors `f` at the receiver's sample points times the source
//!   radiosity (W/m²), exceeds [`VARIATION`] × `P / A` (the mean reflected direct radiosity,
//!   `A` the total area). The receiver is split: else a coarse receiver's `K` is pushed
//!   unchanged to elements whose true `K` differs. [`VARIATION`] is the largest at which the
//!   furnace holds to 1e-3 at every vertex. A receiver whose bounding box reaches across a
//!   surface source's plane while all its samples lie behind it (a floor node past the corner
//!   of a box, across the plane of the box's side face) is split too while `B_s` times the
//!   geometric bound on its form factor ([`point_bound`](transfer::point_bound)) is over the
//!   limit: its part in front still sees the source (with a sample in front, the variation
//!   test decides on the samples' own values). Four samples stand for a receiver only where
//!   none of its points sees the source much better than they do: where the receiver's point
//!   that sees it most (on its plane, nearest the point one radius in front of the source's
//!   centre) may be more than twice as near as the nearest sample (a floor node whose samples
//!   lie away from a box's face, which it reaches), the form factor there counts in the spread
//!   ([`nearest_factor`](Hierarchy::nearest_factor); without it, floor elements beside the
//!   Cornell box's boxes kept half their row sums at some budgets). The source's coarseness
//!   needs no such test: the contour formula is exact for the whole source from each receiver
//!   point.
//!   A large surface source straddling the receiver's horizon (estimated by the disk formula,
//!   crude at a contact) is split while `B_s K̂` exceeds the same limit.
//! * **Cluster receivers**: a cluster pushes the irradiance it gathers unchanged to all its
//!   surfaces, so across them the link's irradiance varies by up to `B_s K̂` (a sill's top
//!   and its bottom take the same light from the street, where the top sees none of it), `K̂`
//!   the geometric bound ([`point_bound`](transfer::point_bound)). The receiver is split while
//!   that is over the variation limit: the variation test, with the bound in place of the
//!   samples' spread (four samples cannot show a cluster's orientations). The power test alone
//!   would leave clusters of small surfaces receiving as a whole (their power is small), and
//!   each of their many small links under every limit.
//! * **Source uniformity**: a link gathers `K B̄_s`, the source's *mean* radiosity, so it
//!   misplaces up to `ΔB_s K̂`, with `ΔB_s` the spread of the source's element radiosities and
//!   `K̂` the largest point form factor at the receiver's samples (the geometric bound for a
//!   cluster end). The source is split while that exceeds [`SOURCE_VARIATION`] × `P / A`.
//!   This is not noise but a bias: the parts of a source that face a receiver most directly
//!   are usually its brightest too (the middle of a floor under a ceiling light), so the mean
//!   underestimates. The same bias has the other sign in shadow: a receiver that the direct
//!   light does not reach sees most the nearby parts of its sources, which share its shadow
//!   and are darker than the source's mean, and all its light is this indirect light. So the
//!   limit is scaled per receiver by its brightest element's direct irradiance against the
//!   elements' mean ([`Limits::source_at`]), down to [`SHADOWED_SOURCE`] where none arrives.
//! * **Partial visibility**: a surface-to-surface link whose tested sample pairs disagree
//!   (some see each other, some do not) is split at its larger node while `B_s K_unoccluded`,
//!   the irradiance its visible fraction decides, exceeds [`PARTIAL_VISIBILITY`] × `P / A`.
//!   Also a bias, not noise: the visible fraction weights the pairs alike, but the pairs
//!   that see past an occluder are usually the near ones, of the larger form factor. A link
//!   over the limit is split as soon as its first pairs (one per sample) disagree, without the
//!   other pairs' rays; one under the limit is kept with the visible fraction of those first
//!   pairs (the irradiance its visibility decides is within the limit anyway). Only a link of
//!   two leaves over the limit (it cannot be split) casts all its pairs.
//! * **Hidden, in doubt**: a link that the power, variation or source test would split but
//!   whose sample pairs are all hidden may still see past the occluder between them
//!   (a box's face and the wall behind the box). It is split like a partially visible link
//!   while `B_s K_unoccluded` exceeds the same limit, else kept as `K = 0` for a later pass
//!   to test again. And a receiver with children whose sample pairs are all hidden, with that
//!   nearest point's form factor at hand, is split while `B_s` times that factor exceeds the
//!   variation limit: its samples may all lie behind an occluder that the rest of it sees past.
//!
//! A self-link of a cluster becomes the four links between its two children; a link between
//! two leaves is kept as it is. Only the shadow rays the decision needs are cast: none for a
//! link the geometric bound splits, and for a surface-to-surface link that will be split, none
//! when `B_s K_unoccluded` is over the partial-visibility limit (split whether hidden or not),
//! else rays only until the first visible pair (a wholly hidden link is split only when in
//! doubt, above).
//!
//! `B_s` for the oracle: [`REFINE_PASSES`] passes. The first refines from the root with the
//! reflected direct light; the solution then gives every node its full radiosity (a node in
//! shadow has none at first), and the first pass's links are tested again with it (each link
//! stores its power and spread factors): those that now fail are refined further, the others
//! are kept without a new estimate; the system is then solved again from the start.
//!
//! # Solve
//!
//! Jacobi iterations (every receiver gathers from the previous iterate, in parallel with an
//! indexed collect, so the result does not depend on the thread count): gather along the links
//! into each node's irradiance, push it down to the leaves (a leaf's indirect irradiance is the
//! sum of what it and its ancestors gathered), `B_leaf = rho (H_direct + H_indirect)`, pull
//! back up (a node's radiosity is the area-weighted mean of its children's). Only the
//! *reflected* light moves: the emitters' direct light is already exact at the vertices.
//!
//! A link from a surface source gathers the source's radiosity where the receiver looks, not
//! its mean: every iteration fits each surface node a radiosity gradient (least squares over
//! its elements' centroids, [`Hierarchy::gradients`]), and the link, which stores where its
//! receiver looks (`toward`: the offset of the source samples' mean weighted by the
//! point-to-point kernel from the receiver's samples over the pairs that see each other,
//! [`seen_offset`](transfer::seen_offset)), gathers `B̄_s + ∇B_s · toward`, kept within 0 and
//! `2 B̄_s`. A first-order answer to the source-mean bias that the source-uniformity test
//! bounds: the part of the floor under the light, which the walls see most, is brighter than
//! the floor's mean. Uniform radiosity (the furnace) has no gradient, so the furnace and the
//! row sums are unchanged.
//!
//! Converged when the power the last iteration added, `sum A |ΔB|` (mean over RGB), is below
//! `tolerance` of `P` (the progressive solver's rule: its unshot power), or after `bounces`
//! iterations when given (iteration `n` adds the `n`-th bounce).
//!
//! # Values at the vertices
//!
//! The solve gives each element its mean indirect irradiance; the lightmap interpolates values
//! at the vertices linearly. The value at a vertex is that of the linear function fitted (area-
//! weighted least squares) to the elements of its own mesh that use it, an element's mean of a
//! linear function being its value at the centroid; where those elements' centroids leave the
//! gradient undetermined (two triangles at a polygon's corner, whose centroids lie along the
//! edge), the elements that share a vertex with them are fitted instead. The value is kept
//! within the elements' values widened by their spread on each side, and at least zero. Then
//! one correction step: each vertex moves by the area-weighted mean of its elements' residuals
//! (element mean minus the mean of its three vertex values), so that the interpolated light
//! keeps each element's mean where the light peaks, which a linear fit through element means
//! flattens. A vertex split along a contact (one copy per side) is used only by the elements
//! of its side, so the sides stay separate. The direct light stays the exact vertex value.
//!
//! Where the light falls steeply into a concave corner within one element (a box's wall base
//! under the sky, `tests/it/sky.rs`), linear interpolation between that element's vertices
//! cannot follow it.
//!
//! # The tolerance as a dial
//!
//! `--hr-tolerance` sets the power limit, and the variation, source and visibility limits
//! scale with it from its default 3e-5 ([`Limits::of_bake`]): one option trades speed for
//! accuracy (the table in `docs/accuracy.md`, "`--hr-tolerance`, the hierarchical solver's
//! dial"). The default is set by the Cornell box, whose indirect light is a large part of what
//! is seen: there it is no worse than the progressive solver in any region.
//!
//! Units: lengths in scene units; irradiance `H` and radiosity `B` in W/m² per linear RGB
//! channel; powers in W (mean over RGB); form factors and `K` dimensionless.

mod gather;
mod refine;
mod transfer;
mod tree;
mod vertex;

pub use refine::{Limits, Link};
pub use tree::{Element, Hierarchy};

use super::{DEFAULT_HR_TOLERANCE, SolveOptions, SolveStats};
use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::visibility::Visibility;
use glam::{DMat3, DVec3};
use rayon::prelude::*;
use std::time::Instant;
use vertex::vertex_indirect;

/// Refinement passes: the first with the reflected direct light as the sources' radiosity, the
/// next ones with the previous pass's solution.
const REFINE_PASSES: usize = 2;

/// The refinement oracle's bound on how much one link's irradiance may vary across its
/// receiver's sample points, as a fraction of the mean reflected direct radiosity `P / A`
/// (dimensionless; see the module doc).
pub const VARIATION: f64 = 2e-3;

/// The refinement oracle's bound on the irradiance a source's non-uniformity may misplace, as a
/// fraction of the mean reflected direct radiosity `P / A` (dimensionless; see the module doc).
const SOURCE_VARIATION: f64 = 0.03;

/// The source limit of a receiver that gets no direct light, as a fraction of the limit
/// [`SOURCE_VARIATION`] sets for a lit one (dimensionless): a receiver's limit scales with its
/// brightest element's direct irradiance against the scene's mean, down to this (see the
/// module doc, "Source uniformity").
pub(crate) const SHADOWED_SOURCE: f64 = 0.3;

/// The refinement oracle's bound on the irradiance a partially visible link may carry, as a
/// fraction of the mean reflected direct radiosity `P / A` (dimensionless; see the module doc).
/// At 0.01 the Cornell box's row sums came out 0.2% short of ray casting
/// (`the_links_a_bake_keeps_match_ray_casting`); at 0.005, 0.1%, for 5% more links.
pub const PARTIAL_VISIBILITY: f64 = 0.005;

/// Distance, in bounding radii of a surface source node, past which its form factor is the
/// disk formula instead of the exact contour sum (see [`Hierarchy::point_factor`]).
const FAR_FIELD: f64 = 6.0;

/// Most links a refinement may hold (the default of [`SolveOptions::hr_max_links`]: 1.4 GB
/// at 48 bytes a link); past it the refinement stops and is redone with a 4× larger
/// tolerance, up to 1 (a warning). A hierarchy that may reach it first predicts its link
/// count from coarse stages, and refines where it fits ([`Hierarchy::staged_link`]). The
/// links of zero `K` a pass keeps for the next one count.
pub const MAX_LINKS: usize = 30_000_000;

/// Links per element past which a refinement is taken to risk the link cap (the Cornell box
/// keeps 72 at the default tolerance): a hierarchy with more elements than the cap over this
/// is refined in stages ([`Hierarchy::staged_link`]).
const LINKS_PER_ELEMENT: usize = 100;

/// The tolerance of a staged refinement's first coarse stage, as a multiple of the one asked
/// for; the second is [`STAGE`] times finer.
const FIRST_STAGE: f64 = 64.0;

/// The ratio of the first coarse stage's tolerance to the second's.
const STAGE: f64 = 4.0;

/// The links' growth exponent a staged refinement assumes when its coarse stages do not show
/// one (`links ∝ tolerance^-a`; measured 0.85 on the Cornell box, 0.4-0.45 on the cities).
const FIRST_GROWTH: f64 = 0.5;

/// The share of the link cap a staged refinement's predicted links may take: the second pass,
/// with the full radiosity, refines further (1.4x the links on the Cornell box). Florence's
/// 17.7 million predicted at the default tolerance fit.
const STAGE_ROOM: f64 = 0.6;

/// The Tikhonov term of the radiosity-gradient fit ([`Hierarchy::inverse_moments`]), as a fraction of
/// the second moment's trace: it keeps the fit from amplifying noise across a nearly
/// degenerate node, and shrinks a well-spread node's gradient by about 0.2%.
const REGULARIZATION: f64 = 1e-3;

/// Most Jacobi iterations when iterating to convergence (a warning when reached).
const MAX_ITERATIONS: usize = 1000;

/// Counters of the hierarchical solve (`--stats`: `solve.hierarchical`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct HierStats {
    /// Nodes of the hierarchy (leaves, surface nodes, clusters).
    pub nodes: usize,
    /// Leaves: mesh elements.
    pub elements: usize,
    /// Cluster nodes (spanning more than one polygon).
    pub clusters: usize,
    /// Links of the last refinement pass.
    pub links: usize,
    /// Links refined (split), summed over the passes.
    pub refinements: u64,
    /// Jacobi iterations, summed over the passes.
    pub iterations: usize,
    /// Shadow rays of the link estimates.
    pub rays: u64,
    /// The refinement tolerance in effect (after any cap), fraction of the reflected direct
    /// power.
    pub tolerance: f64,
    /// Seconds building the hierarchy.
    pub build_seconds: f64,
    /// Seconds refining links (all passes).
    pub link_seconds: f64,
    /// Seconds iterating (all passes).
    pub solve_seconds: f64,
    /// Seconds computing the vertex values.
    pub vertex_seconds: f64,
}

/// The indirect light at every vertex of `meshes`, added to their direct light `direct_h`, by
/// hierarchical radiosity. Fills the powers, `unshot_fraction`, `hierarchical` and `warnings`
/// of `stats` and adds the rays cast. The same for each of `layers` (direct irradiance at the
/// vertices, as `direct_h`: the light of a group of lights alone, [`crate::scene::mixed`]) with
/// the links refined for `direct_h`, so that the layers' light is linear in their direct light:
/// layers whose direct light adds up to `direct_h` add up to its result, up to the iterations'
/// tolerance and the clamp of the sources' gradients ([`Hierarchy::gather_linear`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn indirect_with_layers(
    scene: &Scene,
    vis: &Visibility,
    meshes: &[ReceiverMesh],
    direct_h: &[Vec<DVec3>],
    layers: &[Vec<Vec<DVec3>>],
    options: &SolveOptions,
    stats: &mut SolveStats,
    progress: &crate::progress::Progress<'_>,
) -> (Vec<Vec<DVec3>>, Vec<Vec<Vec<DVec3>>>) {
    let mut hs = HierStats {
        tolerance: options.hr_tolerance,
        ..Default::default()
    };
    let start = Instant::now();
    let Some(h) = Hierarchy::build(scene, vis, meshes, direct_h) else {
        stats.hierarchical = Some(hs);
        return (direct_h.to_vec(), layers.to_vec());
    };
    hs.nodes = h.nodes.len();
    hs.elements = h.elements.len();
    hs.clusters = h.clusters();
    let moments = h.inverse_moments();
    hs.build_seconds = start.elapsed().as_secs_f64();
    let mean = |c: DVec3| c.element_sum() / 3.0;
    let els = &h.elements;
    let (reflected_direct, initial) = h.reflected_direct();
    let total_area: f64 = els.iter().map(|e| e.area).sum();
    // Receivers count as lit from the mean direct irradiance (see `Limits::source_at`).
    let lit = h.mean_direct();
    stats.direct_power = lit * total_area;
    let mut indirect = vec![DVec3::ZERO; els.len()];
    let mut b_el = reflected_direct;
    let mut left = 0.0;
    let parts_direct: Vec<Vec<DVec3>> = layers.iter().map(|l| h.element_values(l)).collect();
    let mut layer_indirect = vec![vec![DVec3::ZERO; els.len()]; layers.len()];
    if initial > 0.0 {
        let mut tolerance = options.hr_tolerance;
        let mut previous: Option<Vec<Link>> = None;
        // The oracle's limits at a tolerance. At the loosest the links are what the hierarchy's
        // shape asks for (a cluster's self-link is always split): no cap then.
        let limits_at = |t: f64| Limits {
            max_links: if t < 1.0 {
                options.hr_max_links
            } else {
                usize::MAX
            },
            ..Limits::of_bake(t, initial, total_area, lit)
        };
        for pass in 0..REFINE_PASSES {
            progress("indirect light", pass as u64, REFINE_PASSES as u64);
            let t = Instant::now();
            let last = pass + 1 == REFINE_PASSES;
            let sources = h.sources(&b_el);
            let links = loop {
                let limits = limits_at(tolerance);
                let r = match &previous {
                    Some(p) => h.relink(vis, p, &sources, limits, last),
                    None if h.elements.len().saturating_mul(LINKS_PER_ELEMENT)
                        > limits.max_links =>
                    {
                        let (r, t) =
                            h.staged_link(vis, &sources, tolerance, limits_at, &mut stats.warnings);
                        tolerance = t;
                        r
                    }
                    None => h.link(vis, &sources, limits),
                };
                hs.refinements += r.refinements;
                hs.rays += r.rays;
                if !r.overflow {
                    break r.links;
                }
                let looser = (tolerance * 4.0).min(1.0);
                stats.warnings.push(format!(
                    "hierarchical radiosity: more than {} links at --hr-tolerance {tolerance:e}; \
                     refined again at {looser:e}",
                    options.hr_max_links
                ));
                tolerance = looser;
                previous = None;
            };
            hs.tolerance = tolerance;
            // Links of zero `K` stay only for the next pass's oracle (the last pass's relink
            // drops them as it goes: on box-grid-40 they are four in five).
            let (links, all) = if last {
                let mut links = links;
                links.retain(|l| l.k > 0.0);
                (links, Vec::new())
            } else {
                (links.iter().filter(|l| l.k > 0.0).copied().collect(), links)
            };
            hs.links = links.len();
            hs.link_seconds += t.elapsed().as_secs_f64();
            let t = Instant::now();
            // Each pass restarts from the reflected direct light: the links changed.
            let direct_el: Vec<DVec3> = els.iter().map(|e| e.direct).collect();
            // The layers only in the last pass, with its links.
            let parts = if last { &parts_direct[..] } else { &[] };
            let it = iterate(
                &h,
                &links,
                &moments,
                &direct_el,
                initial,
                options,
                parts,
                &mut stats.warnings,
            );
            (indirect, b_el, left) = (it.indirect, it.b, it.left);
            if last {
                layer_indirect = it.parts;
            }
            hs.iterations += it.iterations;
            hs.solve_seconds += t.elapsed().as_secs_f64();
            previous = Some(all);
        }
    }
    let t = Instant::now();
    stats.absorbed_power = els
        .iter()
        .zip(&indirect)
        .map(|(e, hi)| e.area * mean((DVec3::ONE - e.rho) * (e.direct + *hi)))
        .sum();
    stats.unshot_fraction = if initial > 0.0 { left / initial } else { 0.0 };
    let out = at_vertices(&h, meshes, direct_h, &indirect);
    let layers = layers
        .iter()
        .zip(&layer_indirect)
        .map(|(d, i)| at_vertices(&h, meshes, d, i))
        .collect();
    hs.vertex_seconds = t.elapsed().as_secs_f64();
    stats.rays += hs.rays;
    stats.hierarchical = Some(hs);
    (out, layers)
}

/// The vertices' irradiance: `direct_h` plus the elements' `indirect`, by a linear fit over
/// the elements using each vertex copy.
fn at_vertices(
    h: &Hierarchy,
    meshes: &[ReceiverMesh],
    direct_h: &[Vec<DVec3>],
    indirect: &[DVec3],
) -> Vec<Vec<DVec3>> {
    let mut per_mesh: Vec<Vec<(u32, f64, DVec3)>> = vec![Vec::new(); meshes.len()];
    for (e, hi) in h.elements.iter().zip(indirect) {
        per_mesh[e.mesh].push((e.triangle as u32, e.area, *hi));
    }
    meshes
        .par_iter()
        .zip(direct_h)
        .zip(&per_mesh)
        .map(|((m, dh), items)| {
            let h = vertex_indirect(m, items);
            dh.iter()
                .zip(&h)
                .map(|(&d, hi)| d + hi.unwrap_or(DVec3::ZERO))
                .collect()
        })
        .collect()
}

/// Jacobi iterations of `B = rho (direct + K B)` over fixed `links`, from the elements' direct
/// irradiance `direct` (W/m²): until the change in reflected power is at most
/// `options.tolerance` of `initial` (W, the reflected direct power), `options.bounces` bounces,
/// or [`MAX_ITERATIONS`]; or when the change grows past twice `initial` (diverging). Each of
/// `parts` (the elements' direct light of a part of the light, [`crate::scene::mixed`]) is
/// iterated in step: from zero, the same iterations are a linear map of the direct light, each
/// link's gradient term clamped as the whole's ([`Hierarchy::gather_clamped_as`]), so the parts
/// add up to the whole. Returns the elements' indirect irradiance, their radiosity, the last
/// change (W), the iterations, and each part's indirect irradiance.
#[allow(clippy::too_many_arguments)]
fn iterate(
    h: &Hierarchy,
    links: &[Link],
    moments: &[DMat3],
    direct: &[DVec3],
    initial: f64,
    options: &SolveOptions,
    parts: &[Vec<DVec3>],
    warnings: &mut Vec<String>,
) -> Iterated {
    let mean = |c: DVec3| c.element_sum() / 3.0;
    let els = &h.elements;
    let reflect = |d: &[DVec3], hi: &[DVec3]| -> Vec<DVec3> {
        els.iter()
            .zip(d.iter().zip(hi))
            .map(|(e, (d, hi))| e.rho * (*d + *hi))
            .collect()
    };
    let zero = vec![DVec3::ZERO; els.len()];
    let mut b_el = reflect(direct, &zero);
    let mut b_parts: Vec<Vec<DVec3>> = parts.iter().map(|d| reflect(d, &zero)).collect();
    let mut parts_indirect = vec![zero; parts.len()];
    let mut indirect: Vec<DVec3>;
    let mut left: f64;
    let mut iterations = 0usize;
    loop {
        let b_nodes = h.pull(&b_el);
        let grads = h.gradients(&b_nodes, moments);
        let whole = Some((&b_nodes[..], &grads[..]));
        for ((b, ind), d) in b_parts.iter_mut().zip(&mut parts_indirect).zip(parts) {
            let nodes = h.pull(b);
            let g = h.gradients(&nodes, moments);
            *ind = h.push(&h.gather_clamped_as(links, &nodes, &g, whole));
            *b = reflect(d, ind);
        }
        let gathered = h.gather_linear(links, &b_nodes, &grads);
        indirect = h.push(&gathered);
        let next = reflect(direct, &indirect);
        left = els
            .iter()
            .zip(next.iter().zip(&b_el))
            .map(|(e, (n, o))| e.area * mean((*n - *o).abs()))
            .sum();
        b_el = next;
        iterations += 1;
        // Each bounce carries at most rho (< 1) of the previous one, so the change
        // shrinks; where it grows (surfaces counted twice, as with duplicated
        // geometry) the solve diverges: stop, and `unshot_fraction` > 1 says so.
        if left.is_nan() || left > 2.0 * initial {
            break;
        }
        match options.bounces {
            Some(n) if iterations >= n as usize => break,
            Some(_) => {}
            None if left <= options.tolerance * initial => break,
            None if iterations >= MAX_ITERATIONS => {
                warnings.push(format!(
                    "hierarchical radiosity: not converged after {MAX_ITERATIONS} \
                     iterations (change {:e} of the reflected direct power)",
                    left / initial
                ));
                break;
            }
            None => {}
        }
    }
    Iterated {
        indirect,
        b: b_el,
        left,
        iterations,
        parts: parts_indirect,
    }
}

/// What [`iterate`] returns.
struct Iterated {
    indirect: Vec<DVec3>,
    b: Vec<DVec3>,
    left: f64,
    iterations: usize,
    parts: Vec<Vec<DVec3>>,
}

#[cfg(test)]
mod tests;
