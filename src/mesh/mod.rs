//! Receiver meshes: per polygon, a constrained Delaunay triangulation (spade) of its outline,
//! refined to a maximum element area.
//!
//! Every mesher produces the same [`ReceiverMesh`], so the solve, atlas and lightmap stages are
//! shared and comparisons between meshers are fair by construction. Refinement is Ruppert/Chew
//! Delaunay refinement as implemented by spade (Shewchuk, "Delaunay refinement algorithms for
//! triangular mesh generation", 2002).

pub(crate) mod arrangement;
mod budget;
mod cdt;
mod lines;
pub mod quality;
mod safe_frame;

use budget::{
    BUDGET_PASSES, COARSEST, element_area, line_spacing, mesh_at, rounds_stop, to_budget,
    vertex_cap, with_slack,
};
pub(crate) use budget::{BUDGET_SLACK, element_count, geometry_floor, lines_floor};
pub use cdt::triangulate_with;
pub(crate) use cdt::{ANGLE_LIMIT_DEG, triangulate_points};
pub(crate) use safe_frame::MeshFailure;

use crate::discontinuity::{Kind, Segment};
use crate::scene::Scene;
use glam::DVec2;
use rayon::prelude::*;

/// Which mesher builds the receiver meshes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize)]
#[cfg_attr(any(feature = "cli", feature = "measure"), derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Mesher {
    /// Quality Delaunay refinement of each polygon's outline to an area cap from the budget.
    Uniform,
    /// Discontinuity meshing: umbra, penumbra and contact lines as constraints, then the same
    /// refinement as uniform.
    #[default]
    Discontinuity,
    /// A-posteriori adaptive meshing: uniform start, split where the solved direct light varies
    /// most across an element or is missed most between its vertices, repeat to the budget.
    Adaptive,
}

/// What goes into a polygon's triangulation besides its outline (see [`triangulate_with`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct Lines<'a> {
    /// Discontinuity segments in plane coordinates, inserted as constraints.
    pub segments: &'a [Segment],
    /// Merge tolerance, scene units.
    pub snap: f64,
    /// Wedge segments along a stronger line closer than this (scene units) are left out.
    pub clearance: f64,
    /// Extra vertices (plane coordinates) inserted before refinement: the light-driven splits.
    pub points: &'a [DVec2],
    /// Rows of thin elements along the corner and contact lines of polygons a few elements
    /// across (`cdt::corner_strip`). On for the default budget, which counts them in its
    /// floor; off for a budget the user fixes, where they would come out of the elements the
    /// light-driven rounds spend.
    pub strips: bool,
}

/// What [`triangulate_with`] did with its segments besides inserting them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Inserted {
    /// Constraint pieces spade refused (they would have crossed another; should be 0).
    pub refused: usize,
    /// Wedge segments left out because they run along a stronger line within the clearance
    /// (or, all of them, along the other boundary of their own penumbra).
    pub(crate) crowded: usize,
}

/// A triangulated receiver polygon. Coordinates are in the polygon's plane frame
/// ([`crate::scene::Polygon::frame`]); values are solved at its vertices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReceiverMesh {
    /// Index into [`Scene::polygons`].
    pub polygon: usize,
    /// Vertex positions in plane coordinates (scene units).
    pub vertices: Vec<DVec2>,
    /// Triangles, counter-clockwise in the plane (front side up).
    pub triangles: Vec<[u32; 3]>,
    /// The mesh edges that lie on discontinuity segments, with the kind and event id of the
    /// segment that made each (for debugging and the significance ranking). Vertex ids are those
    /// of the side kept by the first copy when a D0 line splits its vertices.
    pub constraints: Vec<Constraint>,
}

/// A mesh edge on a discontinuity segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Constraint {
    pub(crate) a: u32,
    pub(crate) b: u32,
    pub kind: Kind,
    /// [`Segment::event`] of the segment.
    pub(crate) event: u32,
}

impl ReceiverMesh {
    /// Total area of the triangles (scene units²).
    pub fn area(&self) -> f64 {
        self.triangles.iter().map(|t| self.triangle_area(t)).sum()
    }

    /// Area of the triangle `t` of this mesh (scene units²; its triangles wind
    /// counter-clockwise, so it is positive).
    pub fn triangle_area(&self, t: &[u32; 3]) -> f64 {
        crate::geometry::signed_area(&t.map(|i| self.vertices[i as usize]))
    }
}

/// When not every discontinuity fits, the wedge pieces kept may take at most this share of what
/// the coarsest meshing without them leaves of the budget; the rest refines between the lines
/// (at 0.75 the Cornell box's walls got 8 elements at a budget of 250: 20% error where lit).
pub(crate) const DM_SHARE: f64 = 0.5;

/// The share of the budget above the coarsest meshing that the discontinuity mesher leaves to
/// refinement where the light varies most.
pub(crate) const LIGHT_SHARE: f64 = 0.2;

/// Rounds of light-driven refinement after discontinuity meshing (each evaluates the direct
/// light on the whole mesh).
pub(crate) const LIGHT_ROUNDS: usize = 3;

/// Elements split by [`adaptive`] and by the discontinuity mesher's refinement when their
/// error (the light's spread over their vertices, or the light they miss between them: see
/// `refine_by_light`) is more than this fraction of the brightest vertex.
pub(crate) const LIGHT_TOLERANCE: f64 = 0.01;

/// The light-driven refinement looks for light missed between an element's vertices in the
/// elements larger than this fraction of the average element: in smaller ones the vertices
/// sample the light finely enough. On interior-20 and a two-room house this found the same
/// meshes as looking in every element, and the extra direct light costs 0.12 s of mesh stage on
/// bevy_DepthOfFieldExample (2048 emitters) instead of 0.95 s; above the average element
/// (1.0), the two-room house at 2 000 elements showed 92% of its lamps' light instead of 96%.
pub(crate) const MISSED_AREA: f64 = 0.5;

/// The direct light (W/m², linear RGB) at every vertex of a set of meshes.
pub(crate) type Evaluate<'a> = dyn Fn(&[ReceiverMesh]) -> Vec<Vec<glam::DVec3>> + 'a;

/// The receiver mesh of each of the scene's polygons: an index into `meshes`, `usize::MAX` for
/// a polygon without one.
pub(crate) fn mesh_of_polygon(scene: &Scene, meshes: &[ReceiverMesh]) -> Vec<usize> {
    let mut of = vec![usize::MAX; scene.polygons.len()];
    for (i, m) in meshes.iter().enumerate() {
        of[m.polygon] = i;
    }
    of
}

/// The uniform mesher: every polygon refined to one area cap, about `budget` triangles in all.
pub fn uniform(scene: &Scene, budget: usize) -> Vec<ReceiverMesh> {
    uniform_with_cap(scene, budget).0
}

/// [`uniform`], and the area cap it meshed to (scene units²).
pub(crate) fn uniform_with_cap(scene: &Scene, budget: usize) -> (Vec<ReceiverMesh>, f64) {
    to_budget(scene, budget, with_slack(budget), |i, area, cap| {
        triangulate_with(i, &scene.polygons[i], Lines::default(), area, cap).0
    })
}

/// The discontinuity mesher: each polygon's discontinuity `segments` as constraints, then the
/// same refinement as [`uniform`], at most `budget` (1 + [`BUDGET_SLACK`]) triangles in all.
///
/// Discontinuities take the budget first: when every wedge piece does not fit even with the
/// coarsest refinement, the weakest pieces (lowest significance; D0 lines are always kept)
/// are dropped until the coarsest meshing costs at most [`DM_SHARE`] of what the meshing
/// without them ([`geometry_floor`]) leaves of the budget, so that the rest still refines the surfaces between the lines.
///
/// With `refine` (the direct light at the vertices of a set of meshes), [`LIGHT_SHARE`] of what
/// the coarsest meshing with the lines leaves of the budget is kept back, and goes where the light
/// varies most across an element or is missed most between its vertices ([`LIGHT_ROUNDS`]
/// rounds of the adaptive mesher's rule,
/// splitting at the centroid so that no split lands on a line). The uniform step before them
/// stays under where the rounds stop ([`rounds_stop`]) whenever the lines leave room there.
///
/// Returns the meshes, what became of the segments passed to the triangulation, the wedge
/// pieces dropped for the budget and the area cap of the last meshing (scene units²).
pub(crate) fn discontinuity(
    scene: &Scene,
    segments: &[Vec<Segment>],
    budget: usize,
    refine: Option<&Evaluate<'_>>,
    strips: bool,
) -> (Vec<ReceiverMesh>, Inserted, usize, f64) {
    // Wedge pieces, strongest first (ties by polygon and position: a total, fixed order).
    let mut ranked: Vec<(usize, usize)> = segments
        .iter()
        .enumerate()
        .flat_map(|(p, segs)| {
            segs.iter()
                .enumerate()
                .filter(|(_, s)| s.kind.is_wedge())
                .map(move |(i, _)| (p, i))
        })
        .collect();
    ranked.sort_by(|&(p, i), &(q, j)| {
        segments[q][j]
            .significance
            .total_cmp(&segments[p][i].significance)
            .then((p, i).cmp(&(q, j)))
    });
    let (snap, clearance) = line_spacing(scene, budget);
    // The strongest `keep` wedge pieces and every D0 line, per polygon.
    let select = |keep: usize| -> Vec<Vec<Segment>> {
        let mut kept: Vec<Vec<bool>> = segments
            .iter()
            .map(|segs| segs.iter().map(|s| !s.kind.is_wedge()).collect())
            .collect();
        for &(p, i) in &ranked[..keep] {
            kept[p][i] = true;
        }
        segments
            .iter()
            .zip(&kept)
            .map(|(segs, k)| {
                segs.iter()
                    .zip(k)
                    .filter(|(_, k)| **k)
                    .map(|(s, _)| s.clone())
                    .collect()
            })
            .collect()
    };
    // What became of each polygon's segments: decided before refinement, so the same at every
    // cap; the last meshing (the final selection) writes last.
    let inserted = std::sync::Mutex::new(vec![Inserted::default(); scene.polygons.len()]);
    let mesh_one = |selected: &[Vec<Segment>],
                    i: usize,
                    points: &[DVec2],
                    area: f64,
                    cap: usize| {
            let lines = Lines {
                segments: &selected[i],
                snap,
                clearance,
                points,
                strips,
            };
            let (m, ins) = triangulate_with(i, &scene.polygons[i], lines, area, cap);
            inserted.lock().unwrap_or_else(|e| e.into_inner())[i] = ins;
            m
        };
    // The count at the coarsest cap with the strongest `keep` pieces.
    let coarsest = element_area(scene, budget) * COARSEST;
    let floor = |keep: usize| -> usize {
        let selected = select(keep);
        element_count(&mesh_at(scene, coarsest, &|i, area, cap| {
            mesh_one(&selected, i, &[], area, cap)
        }))
    };
    let mut keep = ranked.len();
    let most = (budget as f64 * (1.0 + BUDGET_SLACK)) as usize;
    let all = floor(keep);
    // The coarsest meshing's count with the pieces kept.
    let mut least = all;
    if all > most {
        // The wedges may take DM_SHARE of what the meshing without them leaves of the budget:
        // search for the most pieces that fit, interpolating (the count grows about linearly
        // in the pieces kept) or bisecting between the most known to fit and the fewest known
        // not to.
        let none = geometry_floor(scene, segments, budget, strips);
        let share = none + ((budget.saturating_sub(none)) as f64 * DM_SHARE) as usize;
        let (mut fits, mut fails) = ((0, none), (ranked.len(), all));
        for _ in 0..BUDGET_PASSES {
            if none > share || fails.0 - fits.0 <= (ranked.len() / 100).max(1) {
                break;
            }
            let span = (fails.0 - fits.0) as f64;
            let t = (share - fits.1) as f64 / (fails.1 - fits.1).max(1) as f64;
            let t = if (0.1..=0.9).contains(&t) { t } else { 0.5 };
            let guess = fits.0 + ((span * t) as usize).clamp(1, fails.0 - fits.0 - 1);
            let n = floor(guess);
            if n <= share {
                fits = (guess, n);
            } else {
                fails = (guess, n);
            }
        }
        (keep, least) = if none <= share { fits } else { (0, none) };
    }
    let selected = select(keep);
    // With light-driven refinement, the lines and the uniform refinement leave it LIGHT_SHARE
    // of what the coarsest meshing with the lines leaves of the budget.
    let first = match refine {
        Some(_) => least + (budget.saturating_sub(least) as f64 * (1.0 - LIGHT_SHARE)) as usize,
        None => budget,
    };
    let uniform_step = |most: usize| {
        to_budget(scene, first, most, |i, area, vertices| {
            mesh_one(&selected, i, &[], area, vertices)
        })
    };
    let (mut meshes, mut cap) = uniform_step(with_slack(first));
    // The light rounds stop at `rounds_stop`: where the lines leave room under it but the
    // uniform step's slack carried it past, the step is redone under it, so that the rounds
    // still run (interior-20 at 100 000 elements: the lines' coarsest meshing is 92 840, the
    // step landed at 101 285, and the bake showed less light than at 70 000).
    let stop = rounds_stop(budget);
    if refine.is_some() && least < stop && element_count(&meshes) >= stop {
        (meshes, cap) = uniform_step(stop - 1);
    }
    if let Some(evaluate) = refine {
        let start = meshes;
        let added;
        (meshes, added) = refine_by_light(
            &start,
            budget,
            LIGHT_ROUNDS,
            evaluate,
            |t| (t[0] + t[1] + t[2]) / 3.0,
            |mi, points| {
                let i = start[mi].polygon;
                let vertices = vertex_cap(&scene.polygons[i], cap) + 4 * points.len();
                mesh_one(&selected, i, points, cap, vertices)
            },
        );
        // Where the light varies little, the rounds stop short of the budget: the rest refines
        // uniformly, keeping the points added.
        if element_count(&meshes) * 10 < budget * 9 {
            (meshes, cap) = to_budget(scene, budget, with_slack(budget), |i, area, vertices| {
                mesh_one(&selected, i, &added[i], area, vertices + 4 * added[i].len())
            });
        }
    }
    let total = inserted
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .fold(Inserted::default(), |t, i| Inserted {
            refused: t.refused + i.refused,
            crowded: t.crowded + i.crowded,
        });
    (meshes, total, ranked.len() - keep, cap)
}

/// The a-posteriori adaptive mesher, the classic alternative to discontinuity meshing (e.g.
/// Cohen, Greenberg, Immel, Brock, "An efficient radiosity approach for realistic image
/// synthesis", 1986): start from a uniform mesh of a quarter of the budget, solve, and split the
/// elements across which the solution varies most, or whose centroid it misses most (the
/// longest edge at its midpoint; the error of `refine_by_light`), then solve and split again,
/// until the budget is reached or no element's error is over [`LIGHT_TOLERANCE`] of the
/// brightest vertex. `evaluate` gives the values (irradiance) at every mesh's vertices.
pub(crate) fn adaptive(scene: &Scene, budget: usize, evaluate: &Evaluate<'_>) -> Vec<ReceiverMesh> {
    let start = uniform(scene, (budget / 4).max(1));
    refine_by_light(
        &start,
        budget,
        8,
        evaluate,
        |t| crate::geometry::longest_edge_midpoint(&t),
        |mi, points| {
            let m = &start[mi];
            let mut all = m.vertices.clone();
            all.extend(points);
            triangulate_points(m.polygon, &scene.polygons[m.polygon], &all)
        },
    )
    .0
}

/// The adaptive rule on top of `start`: up to `rounds` times, evaluate the light, rank the
/// elements whose error exceeds [`LIGHT_TOLERANCE`] of the brightest vertex, and add a vertex
/// (`split` of the triangle's corners) to the worst ones, as many as the budget allows;
/// `rebuild(mesh, points)` remeshes `start[mesh]` with all the points added to it so far.
/// Stops at [`rounds_stop`] (95% of the budget); a round that would overshoot it by more than
/// [`BUDGET_SLACK`] is undone. Returns the meshes and the points added to each.
///
/// An element's error is the larger of
///
/// * the *variation*: the spread of the light over its three vertices (the classic rule, Cohen
///   et al. 1986), which finds shadow edges and steep falloff, and
/// * the *missed* light: the exact light at its centroid minus the mean of its vertices (what
///   linear interpolation shows there), times its area in average elements (at least one);
///   looked for in the elements larger than [`MISSED_AREA`] of the average one.
///
/// The first alone cannot see a peak between an element's vertices: a house's wall under a
/// ceiling light is dark at the ceiling and at the floor and brightest in between, and with
/// every vertex of its few large elements on those edges the wall read a third of its light.
/// On a 20-room house (`interior-20`) the bake's direct light over all surfaces was 82% of what
/// the lamps emit, and against the Monte Carlo reference the RMSE over all texels was 18.8% of
/// the lit mean; with the missed light, 94% and 11.6%; at night under 256 street lamps
/// (`night-town-25k`) 17.1% and 14.4% (the ground's lit pools: their bias from -16% to 0.1%).
/// The missed light is weighted by area because a large element that misses a peak misplaces
/// that light over all its area, as much as that many average elements would; unweighted
/// it changed nothing. The variation stays unweighted: weighted too, the Cornell box's
/// penumbra error went from 0.69% to 1.13% of the lit mean, the budget taken from the small
/// elements along the shadow edges (the missed light alone leaves the Cornell box's mesh as
/// it was).
fn refine_by_light<S, R>(
    start: &[ReceiverMesh],
    budget: usize,
    rounds: usize,
    evaluate: &Evaluate<'_>,
    split: S,
    rebuild: R,
) -> (Vec<ReceiverMesh>, Vec<Vec<DVec2>>)
where
    S: Fn([DVec2; 3]) -> DVec2,
    R: Fn(usize, &[DVec2]) -> ReceiverMesh + Sync,
{
    let lum = |c: &glam::DVec3| crate::light::luminance(*c);
    let most = (budget as f64 * (1.0 + BUDGET_SLACK)) as usize;
    let mut meshes = start.to_vec();
    let mut added: Vec<Vec<DVec2>> = vec![Vec::new(); start.len()];
    // Elements one split adds, measured after each round.
    let mut per_split = 2.0;
    // The light at each mesh's vertices (after a round, only the rebuilt meshes are evaluated
    // again) and at the centroids of its elements larger than MISSED_AREA of the round's
    // average element (evaluated once per element: `None` until then).
    let mut values: Vec<Vec<glam::DVec3>> = vec![Vec::new(); meshes.len()];
    let mut centroids: Vec<Vec<Option<glam::DVec3>>> = vec![Vec::new(); meshes.len()];
    let mut stale: Vec<usize> = (0..meshes.len()).collect();
    for _ in 0..rounds {
        let total = element_count(&meshes);
        if total >= rounds_stop(budget) {
            break;
        }
        let mean_area = meshes.iter().map(ReceiverMesh::area).sum::<f64>() / total.max(1) as f64;
        for &mi in &stale {
            centroids[mi] = vec![None; meshes[mi].triangles.len()];
        }
        // Per mesh, the large elements whose centroid has no value yet.
        let wanted: Vec<(usize, Vec<usize>)> = meshes
            .iter()
            .enumerate()
            .filter_map(|(mi, m)| {
                let ts: Vec<usize> = (0..m.triangles.len())
                    .filter(|&ti| {
                        centroids[mi][ti].is_none()
                            && m.triangle_area(&m.triangles[ti]) > MISSED_AREA * mean_area
                    })
                    .collect();
                (!ts.is_empty()).then_some((mi, ts))
            })
            .collect();
        // One evaluation for both: the stale meshes' vertices, then per mesh a mesh of the
        // wanted centroids alone (no triangles: the points are inside the polygon).
        let mut subset: Vec<ReceiverMesh> = stale.iter().map(|&mi| meshes[mi].clone()).collect();
        subset.extend(
            wanted
                .iter()
                .map(|(mi, ts)| centroid_points(&meshes[*mi], ts)),
        );
        let mut out = evaluate(&subset).into_iter();
        for &mi in &stale {
            values[mi] = out.next().unwrap_or_default();
        }
        for (mi, ts) in &wanted {
            for (&ti, h) in ts.iter().zip(out.next().unwrap_or_default()) {
                centroids[*mi][ti] = Some(h);
            }
        }
        // The brightest point seen, vertex or centroid: a pool of light may lie between dark
        // vertices only.
        let peak = values
            .iter()
            .flatten()
            .chain(centroids.iter().flatten().flatten())
            .map(lum)
            .fold(0.0, f64::max);
        if peak <= 0.0 {
            break;
        }
        // (error, mesh, triangle), largest first; ties in a fixed order.
        let mut ranked: Vec<(f64, usize, usize)> = Vec::new();
        for (mi, (m, v)) in meshes.iter().zip(&values).enumerate() {
            for (ti, t) in m.triangles.iter().enumerate() {
                let l = t.map(|i| lum(&v[i as usize]));
                let variation = l.iter().fold(f64::MIN, |a, &b| a.max(b))
                    - l.iter().fold(f64::MAX, |a, &b| a.min(b));
                let missed = match centroids[mi].get(ti) {
                    Some(Some(c)) => {
                        let weight = (m.triangle_area(t) / mean_area).max(1.0);
                        (lum(c) - (l[0] + l[1] + l[2]) / 3.0).abs() * weight
                    }
                    _ => 0.0,
                };
                let error = variation.max(missed);
                if error > LIGHT_TOLERANCE * peak {
                    ranked.push((error, mi, ti));
                }
            }
        }
        if ranked.is_empty() {
            break;
        }
        ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then((a.1, a.2).cmp(&(b.1, b.2))));
        let room = (budget - total) as f64 / per_split;
        ranked.truncate((room as usize).clamp(1, total.div_ceil(2)));
        // A round that overshoots is retried once with fewer splits, scaled by the overshoot.
        let mut accepted = None;
        for _ in 0..2 {
            let mut touched = vec![false; meshes.len()];
            let mut next_added = added.clone();
            for &(_, mi, ti) in &ranked {
                let m = &meshes[mi];
                next_added[mi].push(split(m.triangles[ti].map(|i| m.vertices[i as usize])));
                touched[mi] = true;
            }
            let next: Vec<ReceiverMesh> = (0..meshes.len())
                .into_par_iter()
                .map(|mi| {
                    if touched[mi] {
                        rebuild(mi, &next_added[mi])
                    } else {
                        meshes[mi].clone()
                    }
                })
                .collect();
            let count = element_count(&next);
            per_split = ((count as f64 - total as f64) / ranked.len() as f64).max(1.0);
            if count <= most {
                accepted = Some((next, next_added));
                break;
            }
            let fewer = ((budget - total) as f64 / per_split * 0.95) as usize;
            if fewer == 0 {
                break;
            }
            ranked.truncate(fewer);
        }
        let Some((next, next_added)) = accepted else {
            break;
        };
        stale = (0..meshes.len())
            .filter(|&mi| next_added[mi].len() != added[mi].len())
            .collect();
        meshes = next;
        added = next_added;
    }
    (meshes, added)
}

/// A mesh of the centroids of `m`'s `triangles` as vertices, with no triangles (for
/// evaluating the light there).
fn centroid_points(m: &ReceiverMesh, triangles: &[usize]) -> ReceiverMesh {
    ReceiverMesh {
        polygon: m.polygon,
        vertices: triangles
            .iter()
            .map(|&ti| {
                m.triangles[ti]
                    .iter()
                    .map(|&i| m.vertices[i as usize])
                    .sum::<DVec2>()
                    / 3.0
            })
            .collect(),
        triangles: Vec::new(),
        constraints: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::lines::{Obstacles, keep_clear};
    use super::*;
    use crate::scene::{Instance, Material};
    use glam::DVec3;

    fn floor_scene(corners: Vec<DVec3>, indices: Vec<u32>) -> Scene {
        let mut scene = Scene::default();
        scene.materials.push(Material {
            name: "m".into(),
            rho: DVec3::splat(0.5),
            radiance: DVec3::ZERO,
            base: None,
        });
        scene.add_instance(Instance::new(corners, indices), 0);
        scene
    }

    /// A ground with thousands of short contact lines crowded round its centre (3 600 jittered
    /// footprints on a 1 m pitch, overlapping their neighbours at small angles, like a real
    /// city's buildings on one ground polygon): refinement spent its whole vertex cap around
    /// the lines and left the open ground in elements up to 211 times the area cap. The
    /// polygon is triangulated again with a lattice in its open areas, and the repair brings
    /// every element within the cap and the angle limit.
    #[test]
    fn crowded_lines_leave_the_open_ground_its_share_of_the_cap() {
        let scene = rectangle(200.0, 200.0);
        let p = &scene.polygons[0];
        // The plane frame turns the square; the footprints go round its centre.
        let corners: Vec<DVec2> = p.triangles_plane.iter().flatten().copied().collect();
        let centre = corners.iter().sum::<DVec2>() / corners.len() as f64;
        let lo = centre - DVec2::splat(45.0);
        let mut rng = crate::rng::SplitMix64(7);
        let mut segments = Vec::new();
        const N: usize = 60;
        for i in 0..N {
            for j in 0..N {
                let o = lo + DVec2::new(1.0 * i as f64, 1.0 * j as f64);
                let c: Vec<DVec2> = [(0.0, 0.0), (1.2, 0.0), (1.2, 1.2), (0.0, 1.2)]
                    .iter()
                    .map(|&(x, y)| {
                        o + DVec2::new(x + 0.3 * rng.next_f64(), y + 0.3 * rng.next_f64())
                    })
                    .collect();
                for k in 0..4 {
                    segments.push(Segment {
                        a: c[k],
                        b: c[(k + 1) % 4],
                        kind: Kind::D0,
                        event: (4 * (N * i + j) + k) as u32,
                        significance: 1.0,
                        feature: 0,
                    });
                }
            }
        }
        let max_area = p.area / 2000.0;
        let lines = Lines {
            segments: &segments,
            snap: 1e-4,
            clearance: 0.5 * max_area.sqrt(),
            points: &[],
            strips: false,
        };
        let (mesh, _) = triangulate_with(0, p, lines, max_area, vertex_cap(p, max_area));
        // Measured: 211 times the cap before the lattice, 6.4 times with it (the band along the
        // outline, between the lattice and the outline's far-apart corners, was left to
        // refinement with no vertices left); within it with the repair.
        let q = quality::measure(std::slice::from_ref(&mesh), max_area);
        assert_eq!(q.over_cap, 0, "{q:?}");
        assert_eq!(q.sharp, 0, "{q:?}");
        assert!((mesh.area() / p.area - 1.0).abs() < 1e-9);
    }

    /// A 20 x 4 m wall meshed at a cap larger than itself: the bounded passes leave it alone
    /// (two triangles at 11°), and the repair splits its long sides (the circumcentres lie
    /// across them, outside the wall) until no element above a tenth of the cap is skinny,
    /// with a handful of elements and the outline intact.
    #[test]
    fn a_wall_smaller_than_one_element_is_not_two_slivers() {
        let scene = rectangle(20.0, 4.0);
        let p = &scene.polygons[0];
        let cap = 100.0;
        let (mesh, _) = triangulate_with(0, p, Lines::default(), cap, vertex_cap(p, cap));
        let q = quality::measure(std::slice::from_ref(&mesh), cap);
        assert_eq!((q.over_cap, q.sharp), (0, 0), "{q:?}");
        assert!(mesh.triangles.len() > 2 && mesh.triangles.len() <= 24, "{q:?}");
        assert!((mesh.area() / p.area - 1.0).abs() < 1e-12);
        // Every vertex on the outline or inside it, none outside.
        for v in &mesh.vertices {
            assert!(p.contains(*v) || p.boundary.iter().any(|[a, b]| {
                (*b - *a).perp_dot(*v - *a).abs() < 1e-9 * (*b - *a).length()
            }));
        }
    }

    /// A `w` x `d` floor at y = 0 (two triangles).
    fn rectangle(w: f64, d: f64) -> Scene {
        floor_scene(
            vec![
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(w, 0.0, 0.0),
                DVec3::new(w, 0.0, -d),
                DVec3::new(0.0, 0.0, -d),
            ],
            vec![0, 1, 2, 0, 2, 3],
        )
    }

    /// The unit square's outline, counter-clockwise (inside on the left).
    fn unit_square() -> Vec<[DVec2; 2]> {
        let c = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        (0..4).map(|i| [c[i], c[(i + 1) % 4]]).collect()
    }

    #[test]
    fn segment_ends_near_the_outline_go_onto_it() {
        let outline = unit_square();
        let gap = 0.05;
        // Ends 1e-12 and 0.03 from the bottom and top edges, crossing at 60 degrees: both go
        // onto the edges along the segment's line, a hair outside.
        let (a, b) = (
            DVec2::new(0.3, 1e-12),
            DVec2::new(0.3 + 0.97 / 3f64.sqrt(), 0.97),
        );
        let (a2, b2) = keep_clear(a, b, &outline, gap, true).expect("kept");
        assert!(a2.y <= 0.0 && a2.y > -1e-8, "{a2}");
        assert!(b2.y >= 1.0 && b2.y < 1.0 + 1e-8, "{b2}");
        let dir = (b - a).normalize();
        assert!((a2 - a).perp_dot(dir).abs() < 1e-8 && (b2 - a).perp_dot(dir).abs() < 1e-8);
        // An end 0.01 from a corner goes onto the corner.
        let (_, c) = keep_clear(
            DVec2::new(0.5, 0.5),
            DVec2::new(0.99, 0.992),
            &outline,
            gap,
            true,
        )
        .expect("kept");
        assert_eq!(c, DVec2::new(1.0, 1.0));
        // An end far from the outline stays; a segment along an edge is left out.
        let (p, _) = keep_clear(DVec2::new(0.5, 0.5), b, &outline, gap, true).expect("kept");
        assert_eq!(p, DVec2::new(0.5, 0.5));
        assert!(
            keep_clear(
                DVec2::new(0.1, 0.02),
                DVec2::new(0.9, 0.03),
                &outline,
                gap,
                true
            )
            .is_none()
        );
    }

    #[test]
    fn uniform_mesh_covers_the_polygon_and_meets_the_budget() {
        let scene = rectangle(2.0, 1.0);
        let meshes = uniform(&scene, 500);
        assert_eq!(meshes.len(), 1);
        let m = &meshes[0];
        assert!((m.area() - 2.0).abs() < 1e-9, "area {}", m.area());
        let n = m.triangles.len();
        assert!(
            (450..=525).contains(&n),
            "{n} triangles for a budget of 500"
        );
        assert!(m.triangles.iter().all(|t| m.triangle_area(t) > 0.0));
    }

    /// A pool of light (a paraboloid cap of radius 1.2, zero outside) in the middle of a 4 x 4
    /// floor whose two triangles' corners are all dark: the spread over the vertices sees
    /// nothing, the light missed at the centroids finds the pool, and the refined mesh shows
    /// its light (`pi r² / 2` exactly) to within 5% (measured 1.6% at 400 elements).
    #[test]
    fn light_between_dark_vertices_is_found_and_refined() {
        let scene = rectangle(4.0, 4.0);
        let polygon = &scene.polygons[0];
        let start = vec![triangulate_points(0, polygon, &[])];
        assert_eq!(start[0].triangles.len(), 2);
        let centre = polygon.frame.plane_from_world(DVec3::new(2.0, 0.0, -2.0));
        let (r, peak) = (1.2, 1.0);
        let light = |v: DVec2| peak * (1.0 - (v - centre).length_squared() / (r * r)).max(0.0);
        let evaluate = |meshes: &[ReceiverMesh]| -> Vec<Vec<DVec3>> {
            meshes
                .iter()
                .map(|m| m.vertices.iter().map(|&v| DVec3::splat(light(v))).collect())
                .collect()
        };
        let (meshes, added) = refine_by_light(
            &start,
            400,
            8,
            &evaluate,
            |t| (t[0] + t[1] + t[2]) / 3.0,
            |mi, points| {
                let mut all = start[mi].vertices.clone();
                all.extend(points);
                triangulate_points(0, polygon, &all)
            },
        );
        assert!(!added[0].is_empty(), "no split");
        let m = &meshes[0];
        let shown: f64 = m
            .triangles
            .iter()
            .map(|t| {
                m.triangle_area(t)
                    * t.iter()
                        .map(|&i| light(m.vertices[i as usize]))
                        .sum::<f64>()
                    / 3.0
            })
            .sum();
        let exact = std::f64::consts::PI * r * r / 2.0 * peak;
        assert!(
            (shown / exact - 1.0).abs() < 0.05,
            "shown {shown:.4} of {exact:.4} with {} elements",
            m.triangles.len()
        );
    }

    /// A 40 x 1 board on a 100 x 100 ground: the board is larger than the coarsest element (64
    /// times 10 040 / 20 000 = 32) and far too thin for good angles, so its coarsest meshing
    /// takes many more elements than its two triangles, which the floor counts.
    #[test]
    fn a_penumbra_boundary_leaves_out_where_it_runs_along_its_pair() {
        // A placed boundary from the origin along +x, and a second one leaving the same point
        // 3 degrees apart: within the clearance 0.1 of the first for its first 0.1 / sin 3° =
        // 1.91 units.
        let mut obstacles = Obstacles::new(DVec2::splat(-10.0), DVec2::splat(10.0), 0.1, 16);
        obstacles.push(DVec2::ZERO, DVec2::new(8.0, 0.0), 7);
        let angle = 3f64.to_radians();
        let end = DVec2::new(angle.cos(), angle.sin()) * 8.0;
        let pieces = obstacles.apart_from_its_pair(DVec2::ZERO, end, 7);
        assert_eq!(pieces.len(), 1, "{pieces:?}");
        // It starts where it is the clearance away from the first (its height above the x
        // axis), and runs on to its end.
        let (a, b) = pieces[0];
        assert!(
            (a.length() - 0.1 / angle.sin()).abs() < 1e-6,
            "starts at {a}"
        );
        assert!((a.y - 0.1).abs() < 1e-6 && b == end, "{a} {b}");
        // The boundary of another penumbra, or one opening wider than the angle limit, stays.
        assert_eq!(
            obstacles.apart_from_its_pair(DVec2::ZERO, end, 8),
            vec![(DVec2::ZERO, end)]
        );
        let wide = DVec2::new(30f64.to_radians().cos(), 30f64.to_radians().sin()) * 8.0;
        assert_eq!(
            obstacles.apart_from_its_pair(DVec2::ZERO, wide, 7),
            vec![(DVec2::ZERO, wide)]
        );
        // A line with no feature (D0, punctual) is never cut.
        assert_eq!(
            obstacles.apart_from_its_pair(DVec2::ZERO, end, 0),
            vec![(DVec2::ZERO, end)]
        );
    }

    #[test]
    fn the_geometry_floor_counts_the_angle_refinement_of_a_thin_board() {
        let p = |x: f64, z: f64| DVec3::new(x, 0.0, -z);
        let q = |x: f64, y: f64| DVec3::new(x, y, -50.0);
        let mut scene = floor_scene(
            vec![p(-50., -50.), p(50., -50.), p(50., 50.), p(-50., 50.)],
            vec![0, 1, 2, 0, 2, 3],
        );
        scene.add_instance(
            Instance::new(
                vec![q(0., 0.), q(40., 0.), q(40., 1.), q(0., 1.)],
                vec![0, 1, 2, 0, 2, 3],
            ),
            0,
        );
        let floor = geometry_floor(&scene, &[], 20_000, false);
        let coarsest = mesh_at(
            &scene,
            element_area(&scene, 20_000) * COARSEST,
            &|i, a, c| triangulate_with(i, &scene.polygons[i], Lines::default(), a, c).0,
        );
        assert_eq!(floor, element_count(&coarsest));
        let board = coarsest.iter().find(|m| m.polygon == 1).expect("board");
        assert!(board.triangles.len() >= 10, "{}", board.triangles.len());
        // The discontinuity mesher's floor keeps the ground's contact lines (a line across
        // it, in its plane coordinates) and leaves out every wedge piece.
        let segment = |kind, y: f64| Segment {
            a: DVec2::new(-40.0, y),
            b: DVec2::new(40.0, y),
            kind,
            event: 0,
            significance: 1.0,
            feature: 0,
        };
        let count = |segs: Vec<Segment>| geometry_floor(&scene, &[segs, Vec::new()], 20_000, false);
        let d0 = count(vec![segment(Kind::D0, 0.5)]);
        assert!(d0 > count(Vec::new()), "{d0}");
        assert_eq!(
            count(vec![segment(Kind::D0, 0.5), segment(Kind::Ve, 10.0)]),
            d0
        );
    }

    #[test]
    fn concave_polygon_keeps_its_notch() {
        // An L shape: the notch [1,2]x[1,2] must stay empty.
        let p = |x: f64, y: f64| DVec3::new(x, 0.0, -y);
        let scene = floor_scene(
            vec![
                p(0., 0.),
                p(2., 0.),
                p(2., 1.),
                p(1., 1.),
                p(1., 2.),
                p(0., 2.),
            ],
            vec![0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5],
        );
        let meshes = uniform(&scene, 300);
        let m = &meshes[0];
        assert!((m.area() - 3.0).abs() < 1e-9, "area {}", m.area());
    }
}
