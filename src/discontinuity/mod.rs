//! Discontinuity segments: where the illumination of each receiver polygon, or one of its
//! derivatives, is discontinuous (Heckbert, "Discontinuity meshing for radiosity", 1992;
//! Lischinski, Tampieri, Greenberg, "Discontinuity meshing for accurate radiosity", 1992).
//!
//! * **D0**: where a surface touches or crosses a receiver (a box standing on a floor), the
//!   contact segment. Always kept: it stops light leaking under the box.
//! * **VE / EV wedges** of every area emitter: an emitter vertex with an occluder edge, and an
//!   emitter edge with an occluder vertex, kept when the wedge is tangent to the occluder
//!   (silhouette edge or vertex) and has the whole emitter on one side (the extremal events that
//!   bound umbra and penumbra). EEE events are not traced.
//! * **Punctual lights**: the hard shadow boundaries of silhouette edges (central projection for
//!   point and spot lights, parallel projection for directional lights).
//!
//! Each wedge is intersected with the receivers its bounding box reaches (those whose bounding
//! box its plane crosses), clipped to the wedge and to the receiver's triangles (a large
//! receiver's, such as a ground plane cut around thousands of buildings, found through a grid
//! of them: [`BoxGrid`](crate::geometry::BoxGrid)), and only the pieces whose generator is really visible from the
//! receiver and from the emitter are kept (shadow rays at sample points, transitions bisected to
//! 1e-6 of the scene extent). Pieces are ranked by significance, the share of the receiver's
//! unoccluded irradiance that the wedge's emitter carries at the piece; pieces under the
//! threshold are dropped, and the weakest go first when the element budget would be exceeded.

mod contacts;
mod receivers;
mod significance;
mod trace;
mod wedges;

pub use significance::keep_most_significant;

use crate::scene::Scene;
use crate::visibility::Visibility;
use contacts::contacts;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use receivers::PolygonIndex;
use significance::strongest_emitter;
use trace::trace;
use wedges::{Pass, Topology, wedges};

/// Geometric tolerance of the stage, relative to the scene's extent: contacts closer than this
/// count as touching, and the mesher merges segments closer than this.
pub(crate) const TOLERANCE: f64 = 1e-6;

/// A surface parallel to a receiver and closer to its front than this (relative to the scene's
/// extent) is treated as lying on it: its outline is a contact (D0) line.
pub(crate) const NEAR_CONTACT: f64 = 1e-3;

/// What made a discontinuity segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
pub enum Kind {
    /// A surface touching or crossing the receiver (value discontinuity).
    D0,
    /// Emitter vertex x occluder edge.
    Ve,
    /// Emitter edge x occluder vertex.
    Ev,
    /// Silhouette edge of a punctual light.
    Punctual,
    /// Another surface meets the receiver along its outline, in front of it (a wall's foot on
    /// the ground, a roof against a taller neighbour's wall). No jump inside the polygon, but the
    /// bounce light changes fastest beside it: the mesher grades its elements toward it.
    Corner,
}

impl Kind {
    /// A jump in the light (a contact, a punctual light's hard shadow): it cannot be
    /// interpolated across, so the mesher always keeps it and values its vertices per side.
    pub(crate) fn is_jump(self) -> bool {
        matches!(self, Kind::D0 | Kind::Punctual)
    }

    /// A piece of a light's wedge (ranked by significance, dropped for the budget when the
    /// mesh cannot hold it); contacts and corners are the geometry's and always kept.
    pub fn is_wedge(self) -> bool {
        !matches!(self, Kind::D0 | Kind::Corner)
    }
}

/// A discontinuity segment on one receiver polygon, in its plane coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    pub a: DVec2,
    pub b: DVec2,
    pub kind: Kind,
    /// Id of the event (wedge or contact) that made it; unique within one [`segments`] call.
    pub event: u32,
    /// Unoccluded irradiance of the wedge's light at the segment, relative to the brightest
    /// wedge piece of the scene (0..1); 1 for D0.
    pub significance: f64,
    /// The area light and occluder feature (edge or vertex) of a wedge piece, hashed: the
    /// pieces that bound one penumbra (the same occluder edge seen from different emitter
    /// vertices) share it. 0 for D0 lines and punctual lights' lines, which bound none.
    pub feature: u64,
}

/// Options of the discontinuity stage.
#[derive(Clone, Debug)]
pub struct DmOptions {
    /// Pieces whose significance (relative unoccluded irradiance) is below this are dropped.
    pub threshold: f64,
    /// At most this many wedge pieces are kept over the scene (the most significant).
    pub max_pieces: usize,
    /// Skip the wedges whose generator the light does not see ([`DmStats::unseen`]); `false`
    /// traces them all (to measure what the skip saves and loses).
    pub skip_unseen: bool,
}

/// Counters, reported in `--stats`.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct DmStats {
    /// Wedges traced (tangent to the occluder, emitter on one side).
    pub wedges: usize,
    /// D0 (contact) segments.
    pub d0: usize,
    /// Corner segments: outline edges that another surface meets in front ([`Kind::Corner`]).
    pub corners: usize,
    /// Wedge pieces kept as constraints.
    pub kept: usize,
    /// Wedge pieces whose generator was hidden.
    pub hidden: usize,
    /// Wedges whose generator the light does not see at any of [`GENERATOR_SAMPLES`](trace::GENERATOR_SAMPLES) points
    /// (an occluder behind a wall, in another room): not intersected with any receiver, as
    /// every piece of them would be hidden.
    pub unseen: usize,
    /// Wedge pieces below the significance threshold.
    pub dropped_threshold: usize,
    /// (Area emitter, occluder edge or vertex) pairs whose wedges were not built: no piece of
    /// them could reach the threshold (bound from the emitter's power and distance).
    pub culled: usize,
    /// Wedge pieces dropped to stay within the element budget.
    pub dropped_budget: usize,
    /// Constraint pieces spade refused (they would have crossed another; should be 0).
    pub refused: usize,
    /// Wedge pieces left out by the mesher because they run along a stronger line (the
    /// outline, a D0 line, a stronger wedge piece) within half an element, or all along the
    /// other boundary of their own penumbra.
    pub crowded: usize,
}

/// Per receiver polygon: its discontinuity segments.
pub fn segments(
    scene: &Scene,
    vis: &Visibility,
    options: &DmOptions,
) -> (Vec<Vec<Segment>>, DmStats) {
    let extent = scene.extent();
    let tol = TOLERANCE * extent;
    let topo = Topology::new(scene);
    let index = PolygonIndex::new(scene);
    let mut stats = DmStats::default();

    // D0: contacts, per receiver.
    let d0: Vec<[Vec<(DVec3, DVec3)>; 2]> = (0..scene.polygons.len())
        .into_par_iter()
        .map(|r| contacts(scene, &index, r, tol))
        .collect();

    // Wedges of every light, in a fixed order, in two passes. First the strongest area emitter
    // and the punctual lights: their brightest piece is a lower bound of the final peak. Then
    // the other area emitters, skipping every occluder feature too far from the emitter for
    // any of its pieces to reach `threshold` of that bound (their pieces would be dropped
    // below): significance before construction.
    let strongest = strongest_emitter(scene);
    let skip = options.skip_unseen;
    let first = wedges(scene, &topo, extent, Pass::Strongest(strongest), 0.0);
    let (mut pieces, hidden, unseen) = trace(scene, vis, &index, &first.wedges, 0, extent, skip);
    stats.hidden += hidden;
    stats.unseen += unseen;
    let peak_so_far = pieces.iter().map(|p| p.significance).fold(0.0, f64::max);
    let cutoff = options.threshold * peak_so_far;
    let rest = wedges(scene, &topo, extent, Pass::Others(strongest), cutoff);
    let (more, hidden, unseen) = trace(
        scene,
        vis,
        &index,
        &rest.wedges,
        first.wedges.len(),
        extent,
        skip,
    );
    pieces.extend(more);
    stats.hidden += hidden;
    stats.unseen += unseen;
    stats.wedges = first.wedges.len() + rest.wedges.len();
    stats.culled = first.culled + rest.culled;
    let wedge_count = stats.wedges;
    // Significance relative to the brightest piece: an event where its light is faint cannot
    // cause a visible change.
    let peak = pieces.iter().map(|p| p.significance).fold(0.0, f64::max);
    for p in &mut pieces {
        p.significance = if peak > 0.0 {
            p.significance / peak
        } else {
            0.0
        };
    }
    let before = pieces.len();
    pieces.retain(|p| p.significance >= options.threshold);
    stats.dropped_threshold = before - pieces.len();
    stats.kept = pieces.len();

    let mut out: Vec<Vec<Segment>> = vec![Vec::new(); scene.polygons.len()];
    let first_d0_event = wedge_count as u32;
    let mut event = first_d0_event;
    for (r, [contacts, corners]) in d0.iter().enumerate() {
        let frame = &scene.polygons[r].frame;
        let tagged = contacts
            .iter()
            .map(|s| (s, Kind::D0))
            .chain(corners.iter().map(|s| (s, Kind::Corner)));
        for (&(a, b), kind) in tagged {
            out[r].push(Segment {
                a: frame.plane_from_world(a),
                b: frame.plane_from_world(b),
                kind,
                event,
                significance: 1.0,
                feature: 0,
            });
            event += 1;
            match kind {
                Kind::D0 => stats.d0 += 1,
                _ => stats.corners += 1,
            }
        }
    }
    for p in pieces {
        let frame = &scene.polygons[p.polygon].frame;
        out[p.polygon].push(Segment {
            a: frame.plane_from_world(p.a),
            b: frame.plane_from_world(p.b),
            kind: p.kind,
            event: p.event,
            significance: p.significance,
            feature: p.feature,
        });
    }
    keep_most_significant(&mut out, options.max_pieces, &mut stats);
    (out, stats)
}
