//! Triangulation at any scale: a polygon outside [`SAFE_EXTENT`] is meshed in a frame scaled by
//! a power of two, and a panic of the triangulation (spade's refinement panics on a loss of
//! precision) becomes a [`MeshFailure`] that names the polygon.

use super::{Inserted, Lines, ReceiverMesh};
use crate::discontinuity::Segment;
use crate::scene::Polygon;
use glam::DVec2;

/// Polygon extents (bounding box diagonal in the plane, scene units) triangulated as they
/// are. A polygon outside this range is scaled into it by a power of two first, which is exact,
/// so its vertices map back bit for bit; the scenes in practical units keep their own frame,
/// and their meshes stay the same to the last bit.
pub(crate) const SAFE_EXTENT: std::ops::RangeInclusive<f64> = 1e-3..=1e4;

/// A triangulation that panicked, as the payload it unwinds with: the polygon (index into
/// [`crate::scene::Scene::polygons`]) and the panic's message. The bake turns it into an error.
#[derive(Debug)]
pub(crate) struct MeshFailure {
    pub(crate) polygon: usize,
    pub(crate) message: String,
}

/// Runs `triangulate` on the polygon in a frame scaled by a power of two when its extent is
/// outside [`SAFE_EXTENT`] (the mesh's vertices scaled back), with its panics caught: one
/// unwinds on as a [`MeshFailure`], without a message of the panic hook on stderr.
pub(super) fn in_safe_frame(
    id: usize,
    polygon: &Polygon,
    lines: Lines<'_>,
    max_area: f64,
    vertex_cap: usize,
    triangulate: fn(usize, &Polygon, Lines<'_>, f64, usize) -> (ReceiverMesh, Inserted),
) -> (ReceiverMesh, Inserted) {
    let (lo, hi) = polygon.triangles_plane.iter().flatten().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let extent = (hi - lo).length();
    let exponent = if extent.is_finite() && extent > 0.0 && !SAFE_EXTENT.contains(&extent) {
        (-extent.log2().round()).clamp(-1000.0, 1000.0) as i32
    } else {
        0
    };
    let run = || {
        if exponent == 0 {
            return triangulate(id, polygon, lines, max_area, vertex_cap);
        }
        let (s, back) = (2f64.powi(exponent), 2f64.powi(-exponent));
        let scaled = Polygon {
            triangles_plane: polygon
                .triangles_plane
                .iter()
                .map(|t| t.map(|p| p * s))
                .collect(),
            boundary: polygon.boundary.iter().map(|e| e.map(|p| p * s)).collect(),
            area: polygon.area * s * s,
            ..polygon.clone()
        };
        let segments: Vec<Segment> = lines
            .segments
            .iter()
            .map(|g| Segment {
                a: g.a * s,
                b: g.b * s,
                ..g.clone()
            })
            .collect();
        let points: Vec<DVec2> = lines.points.iter().map(|p| *p * s).collect();
        let lines = Lines {
            segments: &segments,
            snap: lines.snap * s,
            clearance: lines.clearance * s,
            points: &points,
            strips: lines.strips,
        };
        let (mut mesh, inserted) = triangulate(id, &scaled, lines, max_area * s * s, vertex_cap);
        for v in &mut mesh.vertices {
            *v *= back;
        }
        (mesh, inserted)
    };
    match quietly(run) {
        Ok(done) => done,
        Err(message) => std::panic::resume_unwind(Box::new(MeshFailure {
            polygon: id,
            message,
        })),
    }
}

thread_local! {
    /// Set while [`quietly`] runs on this thread: the panic hook then stays silent.
    static QUIET: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f`, catching a panic as its message. The process's panic hook is wrapped (once) so it
/// stays silent for panics on a thread inside `quietly`, and prints as before for all others.
fn quietly<R>(f: impl FnOnce() -> R) -> Result<R, String> {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    let was = QUIET.with(|q| q.replace(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    QUIET.with(|q| q.set(was));
    result.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|m| m.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "the triangulation panicked".into())
    })
}
