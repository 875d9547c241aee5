//! The refinement of the links: the oracle's limits, its decision for one link, and the
//! refinement passes from the root-to-root link or from a previous pass's links.

use super::transfer::{
    Factors, PairVisibility, Tint, WHITE, across_plane, facing, pair_visibility, point_bound,
    power_bound, seen_offset,
};
use super::tree::{Hierarchy, Node, Sample};
use super::{DEFAULT_HR_TOLERANCE, MAX_LINKS, PARTIAL_VISIBILITY, SHADOWED_SOURCE};
use super::{FIRST_GROWTH, FIRST_STAGE, STAGE, STAGE_ROOM};
use super::{SOURCE_VARIATION, VARIATION};
use crate::light::NO_POLYGON;
use crate::visibility::Visibility;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Above this many elements in a link's two nodes, the pairs its split makes are refined in
/// parallel (below, in turn: a parallel task per small pair costs more than it saves).
const PARALLEL_ELEMENTS: u32 = 2048;

/// A link: `H[receiver] += k B[source]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    pub(crate) receiver: u32,
    pub(crate) source: u32,
    /// Transport coefficient (dimensionless): mean irradiance over the receiver per unit
    /// radiosity of the source.
    pub(crate) k: f64,
    /// The oracle's power factor (scene units²): the link carries at most `B_s × power` (W);
    /// zero when neither end can be split. The oracle's factors are kept in f32 (links are
    /// the solver's memory: 48 bytes each), which only moves a threshold by 1e-7.
    pub(crate) power: f32,
    /// The oracle's irradiance factor (dimensionless): `B_s × spread` bounds how much the
    /// link's irradiance varies across the receiver (or, for a straddling source, the
    /// disk estimate's error); zero when splitting cannot reduce it.
    pub(crate) spread: f32,
    /// The oracle's source factor (dimensionless): `ΔB_s × reach` bounds the error of treating
    /// the source as uniform (its radiosity spread `ΔB_s` times the most the receiver can see
    /// of it); zero when the source has no children.
    pub(crate) reach: f32,
    /// The oracle's visibility factor (dimensionless): the unoccluded `K` of a partially
    /// visible link (or of a wholly hidden one that another test would split), whose
    /// `B_s × shade` is the irradiance its visible fraction decides; zero when the link is
    /// wholly visible, or neither end can be split.
    pub(crate) shade: f32,
    /// Where in a surface source the receiver looks (scene units): the offset from the plain
    /// mean of the source's samples to their mean weighted by the point-to-point kernel from
    /// the receiver's samples. The link gathers the source's radiosity at its centre moved by
    /// this much along the source's radiosity gradient (see [`Hierarchy::gradients`]); zero
    /// for a cluster end.
    pub(crate) toward: [f32; 3],
    /// The colour of the see-through surfaces between the ends ([`Tint`]): the gather takes
    /// `k` per channel as `k x tinted(tint)`. [`WHITE`] for most links; three bytes that the
    /// struct's alignment would leave empty anyway.
    pub(crate) tint: Tint,
}

/// The source radiosities the refinement oracle reads, per node (W/m², mean over RGB).
#[derive(Clone, Debug)]
pub struct Sources {
    /// Area-weighted mean radiosity.
    pub(crate) b: Vec<f64>,
    /// Largest minus smallest radiosity of the node's elements.
    pub(crate) spread: Vec<f64>,
}

/// The oracle's limits: the most power one link may carry (W), the most a source's irradiance
/// may vary across a receiver (W/m²), the most irradiance a source's non-uniformity may
/// misplace at a lit receiver (W/m²), the most irradiance a partially visible link may carry
/// (W/m²), and the direct irradiance from which a receiver counts as lit (W/m²; zero: every
/// receiver does).
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    pub power: f64,
    pub variation: f64,
    pub source: f64,
    pub visibility: f64,
    pub lit: f64,
    /// The most links a refinement may hold (the links of zero `K` kept for a later pass
    /// count); past it the refinement stops and reports an overflow ([`Linked::overflow`]).
    pub max_links: usize,
}

impl Limits {
    /// The limits a bake refines with: one link may carry `tolerance` of the reflected direct
    /// power `initial` (W), and the variation, source and visibility limits are
    /// [`VARIATION`], [`SOURCE_VARIATION`] and [`PARTIAL_VISIBILITY`] times the mean
    /// reflected direct radiosity `initial / area` (`area`: all elements', scene units²),
    /// scaled by `tolerance` against [`DEFAULT_HR_TOLERANCE`] (so one option loosens or
    /// tightens every test of the oracle together); a receiver is lit from `lit`, the
    /// elements' mean direct irradiance (W/m², [`Hierarchy::mean_direct`]).
    pub fn of_bake(tolerance: f64, initial: f64, area: f64, lit: f64) -> Limits {
        let mean = initial / area * (tolerance / DEFAULT_HR_TOLERANCE);
        Limits {
            power: tolerance * initial,
            variation: VARIATION * mean,
            source: SOURCE_VARIATION * mean,
            visibility: PARTIAL_VISIBILITY * mean,
            lit,
            max_links: MAX_LINKS,
        }
    }

    /// The most irradiance a source's non-uniformity may misplace at the receiver `r` (W/m²):
    /// the `source` limit scaled by the receiver's brightest direct irradiance against `lit`,
    /// within [`SHADOWED_SOURCE`] and 1.
    fn source_at(&self, r: &Node) -> f64 {
        if self.lit > 0.0 {
            self.source * (r.direct / self.lit).clamp(SHADOWED_SOURCE, 1.0)
        } else {
            self.source
        }
    }
}

/// What a refinement reads besides the hierarchy, and how many links it holds so far (all
/// its parallel parts together), so that it stops once they pass [`Limits::max_links`]
/// instead of growing without bound. The count is of every link kept, so whether a
/// refinement overflows does not depend on the order its parts run in.
struct Refinement<'a> {
    vis: &'a Visibility,
    b: &'a Sources,
    limits: Limits,
    kept: AtomicUsize,
}

impl<'a> Refinement<'a> {
    fn new(vis: &'a Visibility, b: &'a Sources, limits: Limits) -> Self {
        Refinement {
            vis,
            b,
            limits,
            kept: AtomicUsize::new(0),
        }
    }

    /// Counts a link kept into `out`: in `out` first, then in the shared count by batches (one
    /// shared counter updated per link would be written by both cores all the time).
    fn keep(&self, out: &mut Refined) {
        out.pending += 1;
        if out.pending >= KEEP_BATCH {
            self.kept.fetch_add(out.pending, Ordering::Relaxed);
            out.pending = 0;
        }
    }

    /// True once more links are counted than the limit allows (the links of a batch not yet
    /// counted can only add to it).
    fn full(&self) -> bool {
        self.kept.load(Ordering::Relaxed) > self.limits.max_links
    }

    /// The refinement's result from its output (all its parts appended: their counts too).
    fn linked(&self, mut out: Refined) -> Linked {
        self.kept
            .fetch_add(std::mem::take(&mut out.pending), Ordering::Relaxed);
        let overflow = self.full();
        let (links, refinements, rays) = if overflow {
            (Vec::new(), out.refinements, out.rays)
        } else {
            out.sorted()
        };
        Linked {
            links,
            refinements,
            rays,
            overflow,
        }
    }
}

/// Links a refinement's part keeps before adding them to the shared count.
const KEEP_BATCH: usize = 1024;

/// The result of a refinement pass ([`Hierarchy::link`], [`Hierarchy::relink`]).
#[derive(Debug)]
pub struct Linked {
    /// The links, sorted by receiver then source; empty on overflow.
    pub links: Vec<Link>,
    /// Links split.
    pub(crate) refinements: u64,
    /// Shadow rays cast.
    pub(crate) rays: u64,
    /// True when the refinement stopped at [`Limits::max_links`] links.
    pub(crate) overflow: bool,
}

/// The output of refining links: the links kept, the links split, the shadow rays cast.
///
/// The links are kept in runs, in order: parts refined in parallel are appended by moving
/// their runs, not their links, and the runs are copied once, into one vector of the exact
/// size, by `Refined::sorted`. (Appending the links themselves would copy them once per level
/// of the parallel split and regrow each vector as it went: on box-grid-20, half the bake's
/// page faults.)
#[derive(Debug, Default)]
struct Refined {
    /// Finished runs of links, in order.
    runs: Vec<Vec<Link>>,
    /// The run being filled, after `runs`.
    links: Vec<Link>,
    refinements: u64,
    rays: u64,
    /// Links kept and not yet counted in the refinement's shared count
    /// ([`Refinement::keep`]).
    pending: usize,
}

impl Refined {
    /// The links sorted by receiver, then source, the refinements and the rays.
    fn sorted(self) -> (Vec<Link>, u64, u64) {
        let total = self.runs.iter().map(Vec::len).sum::<usize>() + self.links.len();
        let mut links = Vec::with_capacity(total);
        for run in self.runs {
            links.extend(run);
        }
        links.extend(self.links);
        // One link per node pair: the keys are distinct, and an unstable sort needs no buffer.
        links.par_sort_unstable_by_key(|l| (l.receiver, l.source));
        debug_assert!(
            links
                .windows(2)
                .all(|w| (w[0].receiver, w[0].source) < (w[1].receiver, w[1].source))
        );
        (links, self.refinements, self.rays)
    }

    /// Adds `other` after what `self` holds.
    fn append(&mut self, other: Refined) {
        if !self.links.is_empty() {
            self.runs.push(std::mem::take(&mut self.links));
        }
        self.runs.extend(other.runs);
        if !other.links.is_empty() {
            self.runs.push(other.links);
        }
        self.refinements += other.refinements;
        self.rays += other.rays;
        self.pending += other.pending;
    }

    /// Keeps only the links that `keep` accepts.
    fn retain(&mut self, keep: impl Fn(&Link) -> bool) {
        for run in &mut self.runs {
            run.retain(&keep);
        }
        self.links.retain(&keep);
    }
}

/// What the refinement oracle decides for one link.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Decision {
    /// Split the receiver (`true`) or the source.
    Split(bool),
    /// Keep this link.
    Keep(Link),
    /// The link carries nothing.
    Drop,
}
impl Hierarchy {
    /// The refinement oracle for the link `r ← s` (see the `hierarchical` module doc): `b_s` is the
    /// source's radiosity (W/m², scalar), `threshold` the most power a link may carry (W),
    /// `variation` the most the source's irradiance may vary across the receiver's samples (W/m²);
    /// `factors` the receiver samples' point form factors to the source where both ends are surface
    /// nodes and the contour formula applies ([`Hierarchy::point_factors`]), else `None` (a cluster
    /// end). Casts only the shadow rays the decision needs (counted in `rays`).
    #[allow(clippy::too_many_arguments)]
    fn decide(
        &self,
        vis: &Visibility,
        r: u32,
        s: u32,
        (b_s, spread_s): (f64, f64),
        factors: Option<Factors>,
        limits: Limits,
        rays: &mut u64,
    ) -> Decision {
        let (threshold, variation) = (limits.power, limits.variation);
        let (nr, ns) = (&self.nodes[r as usize], &self.nodes[s as usize]);
        let (sr, ss) = (&self.samples[r as usize], &self.samples[s as usize]);
        let can_split = nr.kids.is_some() || ns.kids.is_some();
        let larger = match (nr.kids, ns.kids) {
            (Some(_), Some(_)) => nr.area >= ns.area,
            (r, _) => r.is_some(),
        };
        // The kept link `r ← s` (the oracle's factors in f32, see `Link`).
        let keep =
            |k: f64, power: f64, spread: f64, reach: f64, shade: f64, toward: DVec3, tint: Tint| {
                Decision::Keep(Link {
                    receiver: r,
                    source: s,
                    k,
                    power: power as f32,
                    spread: spread as f32,
                    reach: reach as f32,
                    shade: shade as f32,
                    toward: toward.as_vec3().to_array(),
                    tint,
                })
            };
        // A link whose tested sample pairs all see nothing of each other: a receiver's four
        // samples may all lie behind an occluder that the rest of it sees past (a floor node
        // reaching from behind a box to the foot of the box's face). Where the receiver's
        // point that sees the source most is much nearer than its samples, the link is split
        // at the receiver while the irradiance that point may get is over the variation limit;
        // under it, that form factor is kept as the link's spread, for a later pass to test
        // again. `None`: split.
        let doubt = |spread: f64, nearest: Option<f64>| -> Option<f64> {
            match nearest {
                Some(f) => (b_s * f <= variation).then_some(spread.max(f)),
                None => Some(spread),
            }
        };
        let visible = |a: &Sample, b: &Sample, rays: &mut u64| {
            *rays += 1;
            vis.transmitted_skipping(a.ray, b.ray, [a.polygon, b.polygon]) != DVec3::ZERO
        };
        let Some((f, n)) = factors else {
            // A cluster end (or a large straddling source): the geometric bound decides, with
            // no rays; a kept link is estimated by the sampled disk formula.
            let carried = power_bound(nr, ns);
            // Nothing in one node faces the other along any direction between them: no part
            // of this link can carry light, at any level below either.
            if carried <= 0.0 {
                return Decision::Drop;
            }
            let bound = point_bound(nr, ns);
            if can_split && b_s * carried > threshold {
                return Decision::Split(larger);
            }
            // A cluster receiver pushes what it gathers unchanged to all its surfaces, whichever
            // way they face, so the irradiance the link brings varies across them by up to
            // `B_s K̂`: split it while that is over the variation limit.
            let cluster_receiver = nr.polygon == NO_POLYGON && nr.kids.is_some();
            if cluster_receiver && b_s * bound > variation {
                return Decision::Split(true);
            }
            // A large surface source straddling the receiver's horizon: the disk estimate is
            // crude near the horizon (a contact), so the source is split until the bound on
            // the irradiance it gives is within the variation limit.
            let surfaces = nr.polygon != NO_POLYGON && ns.polygon != NO_POLYGON;
            if surfaces && ns.kids.is_some() && b_s * bound > variation {
                return Decision::Split(false);
            }
            // A non-uniform source: its mean radiosity misplaces up to `ΔB_s K̂`.
            let reach = if ns.kids.is_some() { bound } else { 0.0 };
            if spread_s * reach > limits.source_at(nr) {
                return Decision::Split(false);
            }
            let t = self.disk_transfer(vis, r, s);
            *rays += t.rays;
            let power = if can_split { carried } else { 0.0 };
            // The variation tests' factor, for the next pass to test again: a cluster receiver's
            // (across its surfaces) or a straddling surface source's.
            let spread = if cluster_receiver || (surfaces && ns.kids.is_some()) {
                bound
            } else {
                0.0
            };
            // A zero estimate is kept (as `K = 0`) for the next pass to test again: four
            // samples of a cluster may miss what it sees.
            return keep(t.k, power, spread, reach, 0.0, DVec3::ZERO, t.tint);
        };
        let f = &f[..n];
        let unoccluded = f.iter().sum::<f64>() / n as f64;
        if unoccluded <= 0.0 {
            // A receiver across the source's plane whose samples all lie behind it (a floor
            // node reaching past a box's corner): its part in front still sees the source.
            // Split it while the bound on what that part may receive is over the variation
            // limit, else keep it at `K = 0` for a later pass to test again. (With a sample in
            // front, the variation test below decides on the samples' own values.)
            if nr.kids.is_some() && across_plane(nr, ns) {
                let bound = point_bound(nr, ns);
                if b_s * bound > variation {
                    return Decision::Split(true);
                }
                return keep(0.0, 0.0, bound, 0.0, 0.0, DVec3::ZERO, WHITE);
            }
            return Decision::Drop;
        }
        let (lo, hi) = f.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
        // Where the receiver's point that sees the source most is much nearer than its samples,
        // its form factor there widens the spread ([`Hierarchy::nearest_factor`]; only a
        // receiver with children has a spread, so only it is asked).
        let nearest = nr.kids.and_then(|_| self.nearest_factor(r, s));
        let spread = match nr.kids {
            Some(_) => hi.max(nearest.unwrap_or(0.0)) - lo,
            None => 0.0,
        };
        let power = if can_split { unoccluded * nr.area } else { 0.0 };
        let reach = if ns.kids.is_some() { hi } else { 0.0 };
        let vary = b_s * spread > variation;
        let heavy = b_s * power > threshold;
        let uneven = spread_s * reach > limits.source_at(nr);
        // The receiver when its irradiance varies; the larger node when the link is heavy;
        // else the source (it is uneven).
        let split = Decision::Split(vary || (heavy && larger));
        if vary || heavy || uneven {
            // Split, with the bound (the unoccluded transfer), when any pair sees the other end
            // or when the link would be split even if wholly hidden (below): then no ray.
            if b_s * unoccluded > limits.visibility {
                return split;
            }
            let (mut tested, mut hidden) = (false, true);
            'pairs: for a in sr {
                for b in ss {
                    if facing(a, b) > 0.0 {
                        tested = true;
                        if visible(a, b, rays) {
                            hidden = false;
                            break 'pairs;
                        }
                    }
                }
            }
            // Wholly hidden to its samples, the link may still see past the occluder between
            // them: like a partially visible one, it is split while `B_s K_unoccluded` (what
            // its visibility decides) is over the limit, else kept as `K = 0` with only
            // `shade` (the same rays would answer again; a later pass with brighter sources may
            // split it).
            if hidden && tested && b_s * unoccluded <= limits.visibility {
                return match doubt(0.0, nearest) {
                    Some(spread) => keep(0.0, 0.0, spread, 0.0, unoccluded, DVec3::ZERO, WHITE),
                    None => Decision::Split(true),
                };
            }
            return split;
        }
        // Partially visible: the visible fraction of the pairs stands for the whole link, and
        // the parts that see each other are usually the near ones, of the larger form factor.
        // Such a link is split when `B_s K_unoccluded` is over the limit, else kept: either
        // way the first pairs that disagree settle it, and the other pairs need no ray. Only a
        // link over the limit that cannot be split (two leaves) casts every pair.
        let over = b_s * unoccluded > limits.visibility;
        let splits_if_partial = can_split && over;
        let PairVisibility {
            seen,
            tested,
            partial,
            rays: cast,
            visible,
            tint,
        } = pair_visibility(vis, sr, ss, facing, can_split || !over);
        *rays += cast;
        if partial && splits_if_partial {
            return Decision::Split(larger);
        }
        let shade = if partial && can_split {
            unoccluded
        } else {
            0.0
        };
        let spread = if tested > 0.0 && seen == 0.0 {
            match doubt(spread, nearest) {
                Some(spread) => spread,
                None => return Decision::Split(true),
            }
        } else {
            spread
        };
        let v = if tested > 0.0 { seen / tested } else { 1.0 };
        let toward = if ns.kids.is_some() {
            seen_offset(sr, ss, ns.area, visible)
        } else {
            DVec3::ZERO
        };
        keep(unoccluded * v, power, spread, reach, shade, toward, tint)
    }

    /// The links from refining the root-to-root link with the source radiosities `b` (W/m²,
    /// scalar) and the oracle's `limits`, sorted by receiver, then source (including links of
    /// zero `K`, estimated hidden, that a later pass may refine).
    pub fn link(&self, vis: &Visibility, b: &Sources, limits: Limits) -> Linked {
        let root = self.root();
        let cx = Refinement::new(vis, b, limits);
        let mut out = Refined::default();
        self.refine_into(&cx, root, root, None, &mut out);
        cx.linked(out)
    }

    /// The links of a first pass that may pass the link cap ([`Limits::max_links`]): two
    /// coarse refinements first, at [`FIRST_STAGE`] times `tolerance` and [`STAGE`] times
    /// finer (the second from the first's links, [`Hierarchy::relink`]), whose link counts
    /// predict the count at `tolerance` (`links ∝ tolerance^-a`, `a` from their ratio: 0.85 on
    /// the Cornell box, 0.4-0.45 on the cities). Then one refinement from the root, as
    /// [`Hierarchy::link`], at `tolerance`, or, when that is predicted past [`STAGE_ROOM`] of
    /// the cap, at the tolerance predicted to fit (with a warning that names it). Returns the
    /// links (with the refinements and rays of every stage) and the tolerance they were
    /// refined at; a coarse stage that overflows, or whose links already pass [`STAGE_ROOM`] of
    /// the cap, is returned as it is, at its tolerance.
    ///
    /// The final refinement starts from the root because refining on from a coarse stage's
    /// links re-tests them by their stored factors only, a weaker test than the oracle's: on
    /// Florence that gave 10.6% RMSE where the refinement from the root gives 8.9%. Refining
    /// from the root and starting again 4x looser on each overflow, as a small hierarchy still
    /// does, threw away every link refined so far: on a 267 000-triangle city three times, for
    /// most of its bake.
    pub(crate) fn staged_link(
        &self,
        vis: &Visibility,
        b: &Sources,
        tolerance: f64,
        limits: impl Fn(f64) -> Limits,
        warnings: &mut Vec<String>,
    ) -> (Linked, f64) {
        let cap = limits(tolerance).max_links;
        let room = STAGE_ROOM * cap as f64;
        let coarse = (tolerance * FIRST_STAGE).min(1.0);
        let first = self.link(vis, b, limits(coarse));
        if first.overflow {
            return (first, coarse);
        }
        if first.links.len() as f64 > room {
            warnings.push(format!(
                "hierarchical radiosity: {} links at --hr-tolerance {coarse:.2e}, more than \
                 {STAGE_ROOM} of the {cap} allowed; refined at {coarse:.2e} instead of \
                 {tolerance:.2e}",
                first.links.len()
            ));
            return (first, coarse);
        }
        let t = (coarse / STAGE).max(tolerance);
        let mut second = self.relink(vis, &first.links, b, limits(t), false);
        second.refinements += first.refinements;
        second.rays += first.rays;
        let count = second.links.len() as f64;
        if second.overflow || t <= tolerance {
            return (second, t);
        }
        let a = if count > first.links.len() as f64 && !first.links.is_empty() {
            (count / first.links.len() as f64).ln() / STAGE.ln()
        } else {
            FIRST_GROWTH
        };
        let predicted = count * (t / tolerance).powf(a);
        let mut fits = tolerance;
        if predicted > room {
            fits = t * (count / room).powf(1.0 / a);
            warnings.push(format!(
                "hierarchical radiosity: about {predicted:.0} links at --hr-tolerance \
                 {tolerance:.2e} (predicted from the {count} at {t:.2e}), more than {STAGE_ROOM} \
                 of the {cap} allowed; refined at {:.2e} instead",
                fits.min(t)
            ));
            if fits >= t {
                return (second, t);
            }
        }
        let mut r = self.link(vis, b, limits(fits));
        r.refinements += second.refinements;
        r.rays += second.rays;
        (r, fits)
    }

    /// Refines existing `links` with new source radiosities `b` (W/m², scalar): a link the
    /// oracle still accepts is kept as it is (no new estimate), the others are refined from
    /// their node pair as in [`Hierarchy::link`]. As [`Hierarchy::link`], without the links
    /// of zero `K` when this is the `last` pass (no later pass tests them again).
    pub fn relink(
        &self,
        vis: &Visibility,
        links: &[Link],
        b: &Sources,
        limits: Limits,
        last: bool,
    ) -> Linked {
        let cx = Refinement::new(vis, b, limits);
        // In chunks of links, each refined in turn into one output: most links are kept as
        // they are, and a task or a vector per link would cost more than the test.
        let parts: Vec<Refined> = links
            .par_chunks(1024)
            .map(|chunk| {
                let mut out = Refined::default();
                for l in chunk {
                    if cx.full() {
                        break;
                    }
                    let (bs, ds) = (b.b[l.source as usize], b.spread[l.source as usize]);
                    if bs * f64::from(l.power) > limits.power
                        || bs * f64::from(l.spread) > limits.variation
                        || ds * f64::from(l.reach)
                            > limits.source_at(&self.nodes[l.receiver as usize])
                        || bs * f64::from(l.shade) > limits.visibility
                    {
                        self.refine_into(&cx, l.receiver, l.source, None, &mut out);
                    } else {
                        cx.keep(&mut out);
                        out.links.push(*l);
                    }
                }
                if last {
                    out.retain(|l| l.k > 0.0);
                }
                out
            })
            .collect();
        let mut out = Refined::default();
        for part in parts {
            out.append(part);
        }
        cx.linked(out)
    }

    /// Refines the link `r ← s` into `out`: the pairs a split makes are refined in parallel
    /// while they span more than [`PARALLEL_ELEMENTS`] elements, else in turn into the same
    /// output (the links come out in the same order either way). Nothing once the refinement
    /// holds more than its [`Limits::max_links`].
    ///
    /// `known`: the receiver samples' point form factors to `s` when the caller has them
    /// ([`Hierarchy::source_split_factors`]), else they are computed here.
    fn refine_into(
        &self,
        cx: &Refinement<'_>,
        r: u32,
        s: u32,
        known: Option<Factors>,
        out: &mut Refined,
    ) {
        if cx.full() {
            return;
        }
        let split = |pairs: &[(u32, u32, Option<Factors>)], out: &mut Refined| {
            let (nr, ns) = (&self.nodes[r as usize], &self.nodes[s as usize]);
            if (nr.hi - nr.lo) + (ns.hi - ns.lo) > PARALLEL_ELEMENTS {
                let parts: Vec<Refined> = pairs
                    .par_iter()
                    .map(|&(r, s, known)| {
                        let mut part = Refined::default();
                        self.refine_into(cx, r, s, known, &mut part);
                        part
                    })
                    .collect();
                for part in parts {
                    out.append(part);
                }
            } else {
                for &(r, s, known) in pairs {
                    self.refine_into(cx, r, s, known, out);
                }
            }
        };
        if r == s {
            let n = &self.nodes[r as usize];
            // A self-link split is not a refinement of an estimated link.
            if let (Some([a, c]), NO_POLYGON) = (n.kids, n.polygon) {
                split(
                    &[(a, a, None), (a, c, None), (c, a, None), (c, c, None)],
                    out,
                );
            }
            return;
        }
        if self.culled(r, s) {
            return;
        }
        let source = (cx.b.b[s as usize], cx.b.spread[s as usize]);
        let factors = known.or_else(|| self.point_factors(r, s));
        let d = self.decide(cx.vis, r, s, source, factors, cx.limits, &mut out.rays);
        let (nr, ns) = (&self.nodes[r as usize], &self.nodes[s as usize]);
        match d {
            Decision::Split(receiver) => {
                let pairs = match (receiver, nr.kids, ns.kids) {
                    (true, Some(kr), _) => [(kr[0], s, None), (kr[1], s, None)],
                    (_, _, Some(ks)) => {
                        let [fa, fb] = match factors {
                            Some(f) => self.source_split_factors(r, s, f, ks),
                            None => [None, None],
                        };
                        [(r, ks[0], fa), (r, ks[1], fb)]
                    }
                    (_, Some(kr), None) => [(kr[0], s, None), (kr[1], s, None)],
                    (_, None, None) => unreachable!("a split needs a node with children"),
                };
                out.refinements += 1;
                split(&pairs, out);
            }
            Decision::Keep(l)
                if l.k > 0.0 || l.power > 0.0 || l.spread > 0.0 || l.reach > 0.0 || l.shade > 0.0 =>
            {
                cx.keep(out);
                out.links.push(l);
            }
            Decision::Keep(..) | Decision::Drop => {}
        }
    }

    /// The oracle's view of the element radiosities `b_elements`: per node its mean and spread
    /// (mean over RGB).
    pub fn sources(&self, b_elements: &[DVec3]) -> Sources {
        let mean = |c: DVec3| c.element_sum() / 3.0;
        let b = self.pull(b_elements).iter().map(|b| mean(*b)).collect();
        let mut range = vec![(f64::INFINITY, f64::NEG_INFINITY); self.nodes.len()];
        for (e, &n) in self.leaf.iter().enumerate() {
            let x = mean(b_elements[e]);
            range[n as usize] = (x, x);
        }
        for i in 0..self.nodes.len() {
            if let Some([x, y]) = self.nodes[i].kids {
                let (a, c) = (range[x as usize], range[y as usize]);
                range[i] = (a.0.min(c.0), a.1.max(c.1));
            }
        }
        Sources {
            b,
            spread: range.iter().map(|(lo, hi)| (hi - lo).max(0.0)).collect(),
        }
    }
}
