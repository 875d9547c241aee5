//! The budget search: one area cap for the whole scene, found by meshing it at a few caps, and
//! the elements the geometry and its lines take at the coarsest cap (the floors the default
//! budget and the discontinuity mesher's line selection read).

use super::cdt::triangulate_with;
use super::{Lines, ReceiverMesh};
use crate::discontinuity::Segment;
use crate::scene::{Polygon, Scene};
use rayon::prelude::*;

/// The element count may exceed the budget by this fraction.
pub(crate) const BUDGET_SLACK: f64 = 0.05;

/// The coarsest area cap the budget search uses, as a multiple of the average element area
/// (elements 8x the side of a uniform mesh's): coarser meshes cost no fewer elements on
/// real scenes, only quality (at 16x, box-grid-40's 9 600 polygons alone overran its budget).
pub(super) const COARSEST: f64 = 64.0;

/// Most meshings of the whole scene [`to_budget`] tries while looking for its area cap.
pub(super) const BUDGET_PASSES: usize = 10;

/// The elements of a set of meshes.
pub(crate) fn element_count(meshes: &[ReceiverMesh]) -> usize {
    meshes.iter().map(|m| m.triangles.len()).sum()
}

/// Meshes every polygon with `mesh_one(polygon, max_area, vertex_cap)` at one area cap (scene
/// units²), chosen so that the whole scene has at most `most` triangles (usually
/// [`with_slack`]`(budget)`) and not many fewer than `budget`.
///
/// The count falls with the cap, but not as `1/cap`: constraints and the angle bound grade the
/// mesh, so part of it does not scale. The search starts at area/budget and brackets the
/// budget between a cap that gives too many and one that gives too few, then interpolates in
/// log(cap), log(count) within the bracket (bisecting when that stalls). The cap stays within
/// [`COARSEST`] times area/budget; when even that gives too many, that meshing is returned and
/// the caller decides what to drop.
pub(super) fn to_budget<F>(
    scene: &Scene,
    budget: usize,
    most: usize,
    mesh_one: F,
) -> (Vec<ReceiverMesh>, f64)
where
    F: Fn(usize, f64, usize) -> ReceiverMesh + Sync,
{
    let budget = budget.max(1) as f64;
    let most = most as f64;
    let mesh_all = |max_area: f64| -> (Vec<ReceiverMesh>, f64) {
        let meshes = mesh_at(scene, max_area, &mesh_one);
        let count = element_count(&meshes) as f64;
        (meshes, count)
    };
    let first = element_area(scene, budget as usize);
    // Past COARSEST only when even that is over the budget: then as coarse as it gets.
    let total_area: f64 = scene.polygons.iter().map(|p| p.area).sum();
    let (lowest, highest) = (first * 1e-3, total_area.max(first * COARSEST));
    let mut cap = first;
    let (mut best, mut best_count) = mesh_all(cap);
    let mut best_cap = cap;
    // Bracket: (cap, count) with too many elements, and with too few.
    let mut over: Option<(f64, f64)> = None;
    let mut under: Option<(f64, f64)> = None;
    let mut last = (cap, best_count);
    let mut previous: Option<(f64, f64)> = None;
    for _ in 1..BUDGET_PASSES {
        let (c, n) = last;
        if n == 0.0 || (n <= most && n >= budget * 0.9) {
            break;
        }
        if n > most {
            over = Some(last);
        } else {
            under = Some(last);
        }
        // Aim a little under the budget (and under `most`, when that is the tighter bound):
        // the interpolation is not exact.
        let target = (budget * (1.0 - BUDGET_SLACK / 2.0)).min(most * (1.0 - BUDGET_SLACK / 4.0));
        let next = match (over, under) {
            (Some((c0, n0)), Some((c1, n1))) => {
                let slope = (n1.max(1.0) / n0).ln() / (c1 / c0).ln();
                let t = (target / n0).ln() / slope;
                let guess = c0 * t.exp();
                // Stay well inside the bracket, else bisect.
                let (a, b) = (c0.ln(), c1.ln());
                let g = guess.ln();
                if slope < 0.0
                    && g.is_finite()
                    && (g - a) / (b - a) > 0.1
                    && (g - a) / (b - a) < 0.9
                {
                    guess
                } else {
                    ((a + b) / 2.0).exp()
                }
            }
            // Not bracketed yet: extrapolate the last step in log-log (at first assume count
            // ∝ 1/cap), stepping 2x to 64x.
            _ => {
                let slope = match previous {
                    Some((c0, n0)) if c0 != c && n0 > 0.0 && n > 0.0 => {
                        ((n / n0).ln() / (c / c0).ln()).min(-1.0 / 64.0)
                    }
                    _ => -1.0,
                };
                let step = ((target / n).ln() / slope).exp();
                if n > most {
                    c * step.clamp(2.0, 64.0)
                } else {
                    c * step.clamp(1.0 / 64.0, 0.5)
                }
            }
        }
        .clamp(lowest, highest);
        if next == c {
            break;
        }
        cap = next;
        let (meshes, count) = mesh_all(cap);
        previous = Some(last);
        last = (cap, count);
        // Keep the fullest meshing within the budget, else the smallest.
        let better = if count <= most {
            best_count > most || count > best_count
        } else {
            best_count > most && count < best_count
        };
        if better {
            best = meshes;
            best_count = count;
            best_cap = cap;
        }
    }
    (best, best_cap)
}

/// The element count at which the light-driven rounds stop (95% of `budget`): a round adds
/// what the budget has room for, and the last few percent are not worth evaluating the light
/// on the whole scene again.
pub(super) fn rounds_stop(budget: usize) -> usize {
    budget.saturating_mul(19).div_ceil(20)
}

/// The most elements a meshing for `budget` may have: `budget` (1 + [`BUDGET_SLACK`]).
pub(super) fn with_slack(budget: usize) -> usize {
    (budget as f64 * (1.0 + BUDGET_SLACK)) as usize
}

/// The average element area (scene units²) at `budget` elements over the whole scene; the budget
/// search's cap stays within [`COARSEST`] times it.
pub(super) fn element_area(scene: &Scene, budget: usize) -> f64 {
    let total_area: f64 = scene.polygons.iter().map(|p| p.area).sum();
    total_area / budget.max(1) as f64
}

/// Meshes every polygon at one area cap, with a refinement vertex cap from the polygon's
/// expected element count and its outline.
pub(super) fn mesh_at<F>(scene: &Scene, max_area: f64, mesh_one: &F) -> Vec<ReceiverMesh>
where
    F: Fn(usize, f64, usize) -> ReceiverMesh + Sync,
{
    (0..scene.polygons.len())
        .into_par_iter()
        .map(|i| mesh_one(i, max_area, vertex_cap(&scene.polygons[i], max_area)))
        .collect()
}

/// Most vertices refinement may add to polygon `p` at area cap `max_area`: four times the
/// elements the cap asks for, plus room for the outline's grading.
pub(super) fn vertex_cap(p: &Polygon, max_area: f64) -> usize {
    let expected = (p.area / max_area).ceil().min(1e9) as usize;
    4 * expected + 4 * p.boundary.len() + 64
}

/// The snapping distance and the clearance between lines ([`Lines`]) of the discontinuity
/// mesher at `budget` (scene units): the discontinuity stage's tolerance, and half the side of
/// an average element.
pub(super) fn line_spacing(scene: &Scene, budget: usize) -> (f64, f64) {
    let snap = 10.0 * crate::discontinuity::TOLERANCE * scene.extent();
    (snap, 0.5 * element_area(scene, budget).sqrt())
}

/// The elements the geometry itself takes at `budget`: the count of the coarsest meshing the
/// budget search uses (area cap [`COARSEST`] times area/budget), with the D0 (contact) lines of
/// `segments` and no wedge piece (pass no segments for the uniform and adaptive meshers). It is
/// usually below the input's triangle count (a box's faces are one polygon each), but not where
/// the angle bound refines thin or notched polygons (boards, walls with doors): the default
/// element budget leaves room above it (`bake::element_budget`), and the discontinuity mesher
/// gives its wedges a share of what is left above it ([`DM_SHARE`]).
pub(crate) fn geometry_floor(
    scene: &Scene,
    segments: &[Vec<Segment>],
    budget: usize,
    strips: bool,
) -> usize {
    let d0: Vec<Vec<Segment>> = segments
        .iter()
        .map(|segs| {
            segs.iter()
                .filter(|s| !s.kind.is_wedge())
                .cloned()
                .collect()
        })
        .collect();
    lines_floor(scene, &d0, budget, strips)
}

/// The elements the geometry and every one of `segments` take at `budget`: as
/// [`geometry_floor`], with the wedge pieces too. The default element budget stays above it
/// (`bake::element_budget`), so that no line the discontinuity stage kept is dropped for the
/// budget and the open areas between the lines are refined all the same.
pub(crate) fn lines_floor(
    scene: &Scene,
    segments: &[Vec<Segment>],
    budget: usize,
    strips: bool,
) -> usize {
    let (snap, clearance) = line_spacing(scene, budget);
    let d0 = segments;
    let coarsest = element_area(scene, budget) * COARSEST;
    element_count(&mesh_at(scene, coarsest, &|i, area, cap| {
        // As the mesher that asks meshes: the uniform mesher with no lines at all.
        let lines = match d0.get(i) {
            Some(segments) => Lines {
                segments,
                snap,
                clearance,
                points: &[],
                strips,
            },
            None => Lines::default(),
        };
        triangulate_with(i, &scene.polygons[i], lines, area, cap).0
    }))
}
