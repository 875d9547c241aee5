//! Seam stitching: where a surface is cut into two charts (or two places of one chart, or two
//! pages), the texels on the two sides of the cut are filled and dilated independently, so a
//! bilinear lookup just inside one side reads other values than one just inside the other, and
//! the cut shows as a line. Stitching moves the texels in the bilinear footprints of both sides
//! so that the lookups along the cut agree, and holds them weakly to their baked values.
//!
//! The method is least-squares seam stitching (M. Iwanicki, "Lighting Technology of The Last
//! of Us", SIGGRAPH 2013; J. Sylvan, "Least Squares Seam Stitching", 2017; the energy is the
//! seam term of H. Liu, M. Ferguson, A. Jacobson, Y. Gingold, "Seamless: Seam erasure and seam-
//! aware decoupling of shape from mesh resolution", SIGGRAPH Asia 2017):
//!
//! - **Seam edges** ([`find`]): a scene edge (two world positions, so vertices that a glTF file
//!   duplicates for its own normals or UVs still join) shared by two receiving triangles that
//!   run it in opposite directions (both fronts on one side) and whose lightmap UV edges differ
//!   (another chart, another place of the chart, or another page); a triangle and its own back
//!   side (a double-sided surface) are not such a pair. Only edges where the surface
//!   is smooth are stitched: the two triangles' normals within [`SMOOTH_COS`]. Across a crease
//!   (a box's edge, a wall's foot) the irradiance really differs on the two sides, since it
//!   depends on the normal, and a jump there is the right answer; such edges are counted as
//!   `creases` and left alone.
//! - **Samples** ([`samples`]): each seam edge is sampled at most half a texel apart on both
//!   sides, ends included. Each sample gives, per side, the four texels and weights of the
//!   bilinear lookup a GPU makes there ([`Footprint`]: clamp to edge, the output's sampler).
//! - **Least squares** ([`stitch`]): with `t` the values of every texel in some footprint (the
//!   unknowns; padding texels among them), minimise, per colour channel,
//!   `sum over samples (sum_a w_a t_a - sum_b w_b t_b)^2 + LAMBDA^2 sum over unknowns
//!   (t - t_baked)^2`. The normal equations `(A^T A + LAMBDA^2 I) t = LAMBDA^2 t_baked` are
//!   symmetric positive definite; they are solved by conjugate gradients with a Jacobi
//!   preconditioner, separately for each connected group of unknowns (texels joined by a
//!   sample), each group serially and the groups in parallel, so the result does not depend
//!   on the thread count. Texels in no footprint do not move.
//!
//! [`LAMBDA`] = 0.1 (as in the seamoptimizer library's example, after Iwanicki): a sample
//! whose two sides read one texel each keeps `LAMBDA^2 / (2 + LAMBDA^2)` = 0.5% of its
//! mismatch. The weak term makes the system definite (the seam terms alone leave free any
//! change both sides share) and holds each texel near its baked value where the samples pull
//! on it only weakly. A larger lambda leaves more of the seam; a much smaller one makes the
//! system ill-conditioned (more iterations) and lets texels drift where the samples do not pin
//! them.
//!
//! The mismatch ([`mismatch`]) is, per sample, `|side A - side B|` (mean over the channels) of
//! the two bilinear lookups, relative to the lightmap's mean covered texel value (mean over the
//! channels); `--stats` reports its mean and maximum over all samples before and after.

use super::Lightmap;
use crate::atlas::Atlas;
use crate::scene::Scene;
use crate::visibility::Visibility;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use serde::Serialize;

/// Seam edges are stitched where the two triangles' unit normals have at least this dot
/// product (8.1 degrees): the planar pieces of one surface, and the facets of a finely
/// tessellated curved one. (The seamoptimizer library's example stitches "triangles that are
/// on the same plane" at the same threshold.)
pub(crate) const SMOOTH_COS: f64 = 0.99;

/// Weight of the term holding each stitched texel to its baked value, relative to a seam
/// sample's (see the module documentation).
pub(crate) const LAMBDA: f64 = 0.1;

/// Two UV ends closer than this (texels) are the same place.
const SAME_UV: f64 = 1e-3;

/// Conjugate gradients stop when every channel's residual is below this fraction of its
/// right-hand side (or of the first residual, whichever is larger).
const CG_TOLERANCE: f64 = 1e-10;

/// One side of a seam edge: where the edge lies in the lightmap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Side {
    /// Lightmap page.
    pub(crate) page: u32,
    /// UV of the edge's two ends, texels within the page (the same end first on both sides).
    pub(crate) ends: [DVec2; 2],
}

/// A scene edge whose two sides lie at different places of the lightmap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeamEdge {
    /// World positions of the edge's two ends (in the order of [`Side::ends`]).
    pub(crate) ends: [DVec3; 2],
    /// Unit front normal of the first side's triangle.
    pub(crate) normal: DVec3,
    pub(crate) sides: [Side; 2],
}

/// The seam edges of a scene's atlas, and the UV seams left alone at creases.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Seams {
    /// Smooth seam edges (stitched), in the order of their end positions.
    pub edges: Vec<SeamEdge>,
    /// Edges whose two sides lie at different places of the lightmap but meet at a crease
    /// (normals further apart than [`SMOOTH_COS`]): not stitched.
    pub(crate) creases: usize,
}

/// The texels a bilinear lookup reads and their weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// Indices into [`Lightmap::texels`] (pages stacked).
    pub texels: [usize; 4],
    /// Bilinear weights, summing to 1.
    pub weights: [f64; 4],
}

impl Footprint {
    /// The lookup at `uv` (texels, within the page: texel `(x, y)` has its centre at
    /// `(x + 0.5, y + 0.5)`) on page `page` of a map of `width` x `height` pages, with linear
    /// filtering and clamp-to-edge wrapping, as the output's sampler asks of a client.
    /// `width` and `height` must be at least 1.
    pub(crate) fn at(width: u32, height: u32, page: usize, uv: DVec2) -> Footprint {
        let (w, h) = (width as usize, height as usize);
        let x = (uv.x - 0.5).clamp(0.0, w as f64 - 1.0);
        let y = (uv.y - 0.5).clamp(0.0, h as f64 - 1.0);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let base = page * w * h;
        Footprint {
            texels: [
                base + y0 * w + x0,
                base + y0 * w + x1,
                base + y1 * w + x0,
                base + y1 * w + x1,
            ],
            weights: [
                (1.0 - fx) * (1.0 - fy),
                fx * (1.0 - fy),
                (1.0 - fx) * fy,
                fx * fy,
            ],
        }
    }

    /// The lookup's value in `texels`.
    pub(crate) fn sample(&self, texels: &[DVec3]) -> DVec3 {
        (0..4)
            .map(|k| texels[self.texels[k]] * self.weights[k])
            .sum()
    }
}

/// One sample along a seam edge: the lookups on its two sides at the same scene point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeamSample {
    /// The scene point (world space).
    pub(crate) point: DVec3,
    pub sides: [Footprint; 2],
}

/// The seam edges of `atlas` (laid out for `scene`); see the module documentation.
pub fn find(scene: &Scene, atlas: &Atlas) -> Seams {
    // A world position as a key: its bits (with -0 as +0), so equal positions join.
    let key = |p: DVec3| (p + DVec3::ZERO).to_array().map(f64::to_bits);
    struct Run {
        ends: ([u64; 3], [u64; 3]),
        /// True when the triangle runs the edge from `ends.0` to `ends.1`.
        forward: bool,
        triangle: usize,
        world: [DVec3; 2],
        side: Side,
    }
    let mut runs = Vec::new();
    for (inst, am) in scene.instances.iter().zip(&atlas.meshes) {
        for (k, t) in am.indices.chunks_exact(3).enumerate() {
            let triangle = inst.first_triangle + k;
            if scene.triangles[triangle].polygon.is_none() {
                continue;
            }
            let page = am.page.get(k).copied().unwrap_or(0);
            for c in 0..3 {
                let (i, j) = (t[c] as usize, t[(c + 1) % 3] as usize);
                let (a, b) = (am.xref[i] as usize, am.xref[j] as usize);
                let (pa, pb) = (inst.positions_world[a], inst.positions_world[b]);
                let (ka, kb) = (key(pa), key(pb));
                if ka == kb {
                    continue;
                }
                let uv = |v: usize| DVec2::new(am.uv[v][0] as f64, am.uv[v][1] as f64);
                let forward = ka < kb;
                let (ends, world, uvs) = if forward {
                    ((ka, kb), [pa, pb], [uv(i), uv(j)])
                } else {
                    ((kb, ka), [pb, pa], [uv(j), uv(i)])
                };
                runs.push(Run {
                    ends,
                    forward,
                    triangle,
                    world,
                    side: Side { page, ends: uvs },
                });
            }
        }
    }
    runs.sort_by_key(|r| (r.ends, r.triangle));
    let mut seams = Seams::default();
    for group in runs.chunk_by(|a, b| a.ends == b.ends) {
        for (i, a) in group.iter().enumerate() {
            for b in &group[i + 1..] {
                if a.triangle == b.triangle || a.forward == b.forward {
                    continue; // not two sides of one surface
                }
                if scene.twin_triangle(a.triangle) == Some(b.triangle) {
                    continue; // the two sides of a double-sided surface, back to back
                }
                let same = a.side.page == b.side.page
                    && (0..2).all(|e| a.side.ends[e].distance(b.side.ends[e]) <= SAME_UV);
                if same {
                    continue;
                }
                let normal = scene.triangles[a.triangle].normal;
                if normal.dot(scene.triangles[b.triangle].normal) >= SMOOTH_COS {
                    seams.edges.push(SeamEdge {
                        ends: a.world,
                        normal,
                        sides: [a.side, b.side],
                    });
                } else {
                    seams.creases += 1;
                }
            }
        }
    }
    seams
}

/// Samples along every seam edge, at most half a texel apart on either side, both ends
/// included, on a map of `width` x `height` pages; only those at which `keep(world point,
/// normal)` holds (the bake keeps the points not buried under other geometry: nobody sees a
/// seam there, and the dilation fills both sides independently).
pub fn samples(
    edges: &[SeamEdge],
    width: u32,
    height: u32,
    keep: impl Fn(DVec3, DVec3) -> bool,
) -> Vec<SeamSample> {
    let mut out = Vec::new();
    for e in edges {
        let length = e
            .sides
            .iter()
            .map(|s| s.ends[0].distance(s.ends[1]))
            .fold(0.0, f64::max);
        let n = (2.0 * length).ceil().clamp(1.0, 1e6) as usize;
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let point = e.ends[0].lerp(e.ends[1], t);
            if !keep(point, e.normal) {
                continue;
            }
            out.push(SeamSample {
                point,
                sides: e.sides.map(|s| {
                    let uv = s.ends[0].lerp(s.ends[1], t);
                    Footprint::at(width, height, s.page as usize, uv)
                }),
            });
        }
    }
    out
}

/// The seam mismatch (module documentation) over some samples.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Mismatch {
    /// Mean and largest over the samples, relative to the scale.
    pub mean: f64,
    pub max: f64,
    /// The sample with the largest (the first of equals), if any.
    pub(crate) worst: Option<usize>,
}

/// The mismatch of `texels` at `samples`, relative to `scale`; zero without samples or when
/// `scale` is not positive.
pub fn mismatch(texels: &[DVec3], samples: &[SeamSample], scale: f64) -> Mismatch {
    let mut m = Mismatch::default();
    if samples.is_empty() || scale <= 0.0 || !scale.is_finite() {
        return m;
    }
    let mut sum = 0.0;
    for (i, s) in samples.iter().enumerate() {
        let d = (s.sides[0].sample(texels) - s.sides[1].sample(texels))
            .abs()
            .element_sum()
            / (3.0 * scale);
        sum += d;
        if m.worst.is_none() || d > m.max {
            (m.max, m.worst) = (d, Some(i));
        }
    }
    m.mean = sum / samples.len() as f64;
    m
}

/// The mean over covered texels of the mean of their channels (the mismatch's unit).
pub fn mean_covered(map: &Lightmap) -> f64 {
    let (sum, n) = map
        .texels
        .iter()
        .zip(&map.coverage)
        .filter(|(_, c)| **c > 0.0)
        .fold((0.0, 0usize), |(s, n), (t, _)| {
            (s + t.element_sum() / 3.0, n + 1)
        });
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// What [`stitch`] moved.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Stitched {
    /// The texels that were unknowns (in some footprint), sorted.
    pub(crate) texels: Vec<usize>,
    /// Connected groups solved.
    pub(crate) groups: usize,
    /// Most conjugate-gradient iterations any group took.
    pub(crate) iterations: usize,
}

/// Least-squares stitching of `texels` along `samples` (module documentation).
pub(crate) fn stitch(texels: &mut [DVec3], samples: &[SeamSample]) -> Stitched {
    // Equations: (texel, coefficient) runs, side A positive, side B negative, merged.
    let mut starts = vec![0];
    let mut terms: Vec<(usize, f64)> = Vec::new();
    for s in samples {
        let first = terms.len();
        for (side, sign) in s.sides.iter().zip([1.0, -1.0]) {
            for k in 0..4 {
                let (t, w) = (side.texels[k], sign * side.weights[k]);
                if w == 0.0 {
                    continue;
                }
                match terms[first..].iter_mut().find(|(u, _)| *u == t) {
                    Some(term) => term.1 += w,
                    None => terms.push((t, w)),
                }
            }
        }
        // A texel both sides read with the same weight drops out.
        let tail: Vec<(usize, f64)> = terms.drain(first..).filter(|t| t.1 != 0.0).collect();
        terms.extend(tail);
        starts.push(terms.len());
    }
    let mut unknowns: Vec<usize> = terms.iter().map(|&(t, _)| t).collect();
    unknowns.sort_unstable();
    unknowns.dedup();
    let local = |t: usize| unknowns.binary_search(&t).unwrap_or(0);
    // Connected groups of unknowns (union-find over the equations).
    let mut parent: Vec<usize> = (0..unknowns.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for e in 0..starts.len() - 1 {
        let eq = &terms[starts[e]..starts[e + 1]];
        if let Some(&(first, _)) = eq.first() {
            // Each set's root is its smallest member.
            let mut a = root(&mut parent, local(first));
            for &(t, _) in &eq[1..] {
                let b = root(&mut parent, local(t));
                parent[b.max(a)] = b.min(a);
                a = a.min(b);
            }
        }
    }
    // Groups numbered in the order of their smallest texel; each with its unknowns (sorted)
    // and equations (in sample order), indices local to the group.
    let mut group_of = vec![usize::MAX; unknowns.len()];
    let mut groups: Vec<Group> = Vec::new();
    let mut position = vec![0; unknowns.len()];
    for i in 0..unknowns.len() {
        let r = root(&mut parent, i);
        if group_of[r] == usize::MAX {
            group_of[r] = groups.len();
            groups.push(Group::default());
        }
        let g = group_of[r];
        group_of[i] = g;
        position[i] = groups[g].unknowns.len();
        groups[g].unknowns.push(unknowns[i]);
    }
    for e in 0..starts.len() - 1 {
        let eq = &terms[starts[e]..starts[e + 1]];
        let Some(&(first, _)) = eq.first() else {
            continue;
        };
        let g = &mut groups[group_of[local(first)]];
        g.terms
            .extend(eq.iter().map(|&(t, w)| (position[local(t)], w)));
        g.starts.push(g.terms.len());
    }
    let solved: Vec<(Vec<DVec3>, usize)> = groups
        .par_iter()
        .map(|g| {
            let baked: Vec<DVec3> = g.unknowns.iter().map(|&t| texels[t]).collect();
            g.solve(&baked)
        })
        .collect();
    let mut iterations = 0;
    for (g, (values, its)) in groups.iter().zip(solved) {
        for (&t, v) in g.unknowns.iter().zip(values) {
            texels[t] = v;
        }
        iterations = iterations.max(its);
    }
    Stitched {
        texels: unknowns,
        groups: groups.len(),
        iterations,
    }
}

/// One connected group of the stitching problem.
#[derive(Debug)]
struct Group {
    /// Lightmap texel of each local unknown.
    unknowns: Vec<usize>,
    /// Equation `e` is `terms[starts[e]..starts[e + 1]]`: (local unknown, coefficient).
    starts: Vec<usize>,
    terms: Vec<(usize, f64)>,
}

impl Default for Group {
    fn default() -> Self {
        Group {
            unknowns: Vec::new(),
            starts: vec![0],
            terms: Vec::new(),
        }
    }
}

impl Group {
    fn equations(&self) -> impl Iterator<Item = &[(usize, f64)]> {
        self.starts.windows(2).map(|s| &self.terms[s[0]..s[1]])
    }

    /// `(A^T A + LAMBDA^2 I) v`.
    fn apply(&self, v: &[DVec3]) -> Vec<DVec3> {
        let mut out: Vec<DVec3> = v.iter().map(|x| *x * (LAMBDA * LAMBDA)).collect();
        for eq in self.equations() {
            let s: DVec3 = eq.iter().map(|&(i, c)| v[i] * c).sum();
            for &(i, c) in eq {
                out[i] += s * c;
            }
        }
        out
    }

    /// The least-squares values of the unknowns, from their baked values, by preconditioned
    /// conjugate gradients (all three channels at once, each with its own step lengths);
    /// with the iterations taken.
    fn solve(&self, baked: &[DVec3]) -> (Vec<DVec3>, usize) {
        let n = baked.len();
        let lambda2 = LAMBDA * LAMBDA;
        let mut diagonal = vec![lambda2; n];
        for eq in self.equations() {
            for &(i, c) in eq {
                diagonal[i] += c * c;
            }
        }
        let dot =
            |a: &[DVec3], b: &[DVec3]| -> DVec3 { a.iter().zip(b).map(|(x, y)| *x * *y).sum() };
        let rhs: Vec<DVec3> = baked.iter().map(|b| *b * lambda2).collect();
        let mut x = baked.to_vec();
        let ax = self.apply(&x);
        let mut r: Vec<DVec3> = rhs.iter().zip(&ax).map(|(b, a)| *b - *a).collect();
        let reference = dot(&rhs, &rhs).max(dot(&r, &r));
        let done = |r: &[DVec3]| {
            let rr = dot(r, r);
            (0..3).all(|c| rr[c] <= CG_TOLERANCE * CG_TOLERANCE * reference[c])
        };
        let mut z: Vec<DVec3> = r.iter().zip(&diagonal).map(|(r, d)| *r / *d).collect();
        let mut p = z.clone();
        let mut rz = dot(&r, &z);
        let ratio = |a: DVec3, b: DVec3| {
            DVec3::from_array(std::array::from_fn(|c| {
                if b[c] > 0.0 { a[c] / b[c] } else { 0.0 }
            }))
        };
        let limit = 10 * n + 100;
        let mut iterations = 0;
        while iterations < limit && !done(&r) {
            iterations += 1;
            let ap = self.apply(&p);
            let alpha = ratio(rz, dot(&p, &ap));
            for i in 0..n {
                x[i] += alpha * p[i];
                r[i] -= alpha * ap[i];
                z[i] = r[i] / diagonal[i];
            }
            let rz_next = dot(&r, &z);
            let beta = ratio(rz_next, rz);
            rz = rz_next;
            for i in 0..n {
                p[i] = z[i] + beta * p[i];
            }
        }
        (x, iterations)
    }
}

/// The seam statistics of a bake (`--stats` `seams`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SeamStats {
    /// False with `--seams off`: the mismatch is measured, nothing is moved.
    pub stitched: bool,
    /// Smooth seam edges (stitched).
    pub edges: usize,
    /// UV seams at creases (normals more than 8.1 degrees apart): left alone.
    pub creases: usize,
    /// Samples along the seam edges.
    pub samples: usize,
    /// Texels in the samples' footprints (the unknowns), and their connected groups.
    pub texels: usize,
    pub groups: usize,
    /// Most conjugate-gradient iterations a group took.
    pub iterations: usize,
    /// Mean and largest seam mismatch before stitching, relative to the mean covered texel.
    pub mismatch_mean_before: f64,
    pub mismatch_max_before: f64,
    /// Where the largest mismatch before stitching is: the world point of its sample (`null`
    /// without samples).
    pub worst_before_at: Option<[f64; 3]>,
    /// The same after stitching (equal to the before values with `--seams off`).
    pub mismatch_mean: f64,
    pub mismatch_max: f64,
}

/// Measures the seams of `map` (rasterized and dilated for `atlas` and `scene`, whose BVH is
/// `vis`) and, when
/// `stitch` is set, stitches them and re-dilates the padding from the covered and the
/// stitched texels, so that the padding and every mipmap level agree with the stitched
/// values.
pub(crate) fn stitch_seams(
    map: &mut Lightmap,
    scene: &Scene,
    vis: &Visibility,
    atlas: &Atlas,
    on: bool,
) -> SeamStats {
    if map.width == 0 || map.height == 0 {
        return SeamStats {
            stitched: on,
            ..SeamStats::default()
        };
    }
    let seams = find(scene, atlas);
    let samples = samples(&seams.edges, map.width, map.height, |p, n| {
        !vis.buried(p, n)
    });
    let scale = mean_covered(map);
    let before = mismatch(&map.texels, &samples, scale);
    let mut stats = SeamStats {
        stitched: on,
        edges: seams.edges.len(),
        creases: seams.creases,
        samples: samples.len(),
        mismatch_mean_before: before.mean,
        mismatch_max_before: before.max,
        worst_before_at: before.worst.map(|i| samples[i].point.to_array()),
        mismatch_mean: before.mean,
        mismatch_max: before.max,
        ..SeamStats::default()
    };
    if !on || samples.is_empty() {
        return stats;
    }
    let stitched = stitch(&mut map.texels, &samples);
    let mut fixed: Vec<bool> = map.coverage.iter().map(|&c| c > 0.0).collect();
    for &t in &stitched.texels {
        fixed[t] = true;
    }
    super::dilate_from(map, fixed, u32::MAX);
    let after = mismatch(&map.texels, &samples, scale);
    (stats.mismatch_mean, stats.mismatch_max) = (after.mean, after.max);
    stats.texels = stitched.texels.len();
    stats.groups = stitched.groups;
    stats.iterations = stitched.iterations;
    stats
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atlas::AtlasMesh;
    use crate::fixtures::{GlbBuilder, Material, TriangleMesh};

    /// A deterministic value in [0, 1) for `i` (SplitMix64's finaliser).
    fn noise(i: u64) -> f64 {
        use crate::rng::{GAMMA, mix64, unit_f64};
        unit_f64(mix64(i.wrapping_add(1).wrapping_mul(GAMMA)))
    }

    #[test]
    fn footprint_reproduces_linear_functions_and_clamps_at_the_edges() {
        let (w, h) = (8u32, 6u32);
        let f = |x: f64, y: f64, page: f64| 1.0 + 2.0 * x + 3.0 * y + 100.0 * page;
        // Two pages; the value at texel centres is f of the centre.
        let texels: Vec<DVec3> = (0..2 * w * h)
            .map(|i| {
                let (page, k) = (i / (w * h), i % (w * h));
                let (x, y) = ((k % w) as f64 + 0.5, (k / w) as f64 + 0.5);
                DVec3::splat(f(x, y, page as f64))
            })
            .collect();
        for (k, page) in [(0u64, 0usize), (1, 1), (2, 0), (3, 1)] {
            let uv = DVec2::new(0.5 + 7.0 * noise(2 * k), 0.5 + 5.0 * noise(2 * k + 1));
            let fp = Footprint::at(w, h, page, uv);
            assert!((fp.weights.iter().sum::<f64>() - 1.0).abs() < 1e-15);
            let v = fp.sample(&texels).x;
            assert!((v - f(uv.x, uv.y, page as f64)).abs() < 1e-12, "{uv}: {v}");
        }
        // Outside the centres of the border texels: the border texel (clamp to edge).
        let fp = Footprint::at(w, h, 1, DVec2::new(0.1, 5.9));
        assert_eq!(fp.sample(&texels).x, f(0.5, 5.5, 1.0));
    }

    #[test]
    fn two_texels_meet_at_the_closed_form() {
        // One sample reading texel 0 on one side and texel 1 on the other: minimising
        // (a - b)^2 + l^2 ((a - a0)^2 + (b - b0)^2) keeps the mean and leaves a difference of
        // l^2 (a0 - b0) / (2 + l^2).
        let a0 = DVec3::new(1.0, 4.0, 0.0);
        let b0 = DVec3::new(3.0, 1.0, 0.0);
        let mut texels = vec![a0, b0];
        let one = |t: usize| Footprint {
            texels: [t; 4],
            weights: [1.0, 0.0, 0.0, 0.0],
        };
        let sample = SeamSample {
            point: DVec3::ZERO,
            sides: [one(0), one(1)],
        };
        let stitched = stitch(&mut texels, &[sample]);
        assert_eq!(stitched.texels, vec![0, 1]);
        assert_eq!(stitched.groups, 1);
        let l2 = LAMBDA * LAMBDA;
        let d = (a0 - b0) * l2 / (2.0 + l2);
        let m = (a0 + b0) / 2.0;
        for (got, want) in texels.iter().zip([m + d / 2.0, m - d / 2.0]) {
            assert!((*got - want).abs().max_element() < 1e-12, "{got} != {want}");
        }
        // 0.5% of the mismatch is left (the weak term's price).
        let left = (texels[0] - texels[1]).x / (a0 - b0).x;
        assert!((left - l2 / (2.0 + l2)).abs() < 1e-12);
    }

    /// Solves `m x = b` by Gaussian elimination with partial pivoting.
    fn dense_solve(mut m: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
        let n = b.len();
        for c in 0..n {
            let p = (c..n)
                .max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))
                .unwrap();
            m.swap(c, p);
            b.swap(c, p);
            let (top, rest) = m.split_at_mut(c + 1);
            let pivot = &top[c];
            for (r, row) in rest.iter_mut().enumerate() {
                let f = row[c] / pivot[c];
                for (x, p) in row[c..].iter_mut().zip(&pivot[c..]) {
                    *x -= f * p;
                }
                b[c + 1 + r] -= f * b[c];
            }
        }
        let mut x = vec![0.0; n];
        for r in (0..n).rev() {
            let s: f64 = (r + 1..n).map(|k| m[r][k] * x[k]).sum();
            x[r] = (b[r] - s) / m[r][r];
        }
        x
    }

    #[test]
    fn stitching_is_the_dense_least_squares_solution() {
        // A 16 x 8 page: chart A's edge runs down x = 3 (y 1 -> 6), chart B's up x = 11.5
        // (y 6.5 -> 1.5, so the ends swap and the texel grids are offset); a second, short
        // seam far away forms a group of its own. Baked values are noise.
        let (w, h) = (16u32, 8u32);
        let mut texels: Vec<DVec3> = (0..(w * h) as u64)
            .map(|i| DVec3::new(noise(3 * i), noise(3 * i + 1), noise(3 * i + 2)))
            .collect();
        let baked = texels.clone();
        let side = |a: [f64; 2], b: [f64; 2]| Side {
            page: 0,
            ends: [DVec2::from(a), DVec2::from(b)],
        };
        let edge = |a: Side, b: Side| SeamEdge {
            ends: [DVec3::ZERO, DVec3::X],
            normal: DVec3::Y,
            sides: [a, b],
        };
        let edges = [
            edge(side([3.0, 1.0], [3.0, 6.0]), side([11.5, 6.5], [11.5, 1.5])),
            edge(side([7.2, 0.7], [8.1, 0.7]), side([7.3, 7.4], [8.2, 7.4])),
        ];
        let samples = samples(&edges, w, h, |_, _| true);
        // 5 texels long: 10 segments, 11 samples; 0.9 long: 2 segments, 3 samples.
        assert_eq!(samples.len(), 14);
        let before = mismatch(&texels, &samples, 1.0);
        let stitched = stitch(&mut texels, &samples);
        assert_eq!(stitched.groups, 2);
        // The normal equations, dense, over the same unknowns.
        let u = &stitched.texels;
        let n = u.len();
        let mut m = vec![vec![0.0; n]; n];
        for (i, row) in m.iter_mut().enumerate() {
            row[i] = LAMBDA * LAMBDA;
        }
        for s in &samples {
            let mut row = vec![0.0; n];
            for (side, sign) in s.sides.iter().zip([1.0, -1.0]) {
                for k in 0..4 {
                    if let Ok(i) = u.binary_search(&side.texels[k]) {
                        row[i] += sign * side.weights[k];
                    }
                }
            }
            for i in 0..n {
                for j in 0..n {
                    m[i][j] += row[i] * row[j];
                }
            }
        }
        for c in 0..3 {
            let b: Vec<f64> = u.iter().map(|&t| LAMBDA * LAMBDA * baked[t][c]).collect();
            let x = dense_solve(m.clone(), b);
            for (i, &t) in u.iter().enumerate() {
                assert!(
                    (texels[t][c] - x[i]).abs() < 1e-9,
                    "texel {t}: {} vs {}",
                    texels[t][c],
                    x[i]
                );
            }
        }
        // Texels in no footprint are untouched; the mismatch drops far more than 5x.
        for (t, (now, then)) in texels.iter().zip(&baked).enumerate() {
            if u.binary_search(&t).is_err() {
                assert_eq!(now, then);
            }
        }
        let after = mismatch(&texels, &samples, 1.0);
        assert!(after.mean < before.mean / 20.0, "{before:?} -> {after:?}");
    }

    /// A square [0, 1]² at y = 0 facing up, two triangles sharing the diagonal (0-2), plus a
    /// third triangle folded up at 90 degrees along edge 0-1; as a scene.
    fn square_and_flap() -> Scene {
        let mesh = TriangleMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 0.0, 1.0],
                [0.0, 0.0, 1.0],
                [0.5, 1.0, 0.0],
            ],
            normals: None,
            texcoords: None,
            tangents: None,
            // Up-facing: (0,0,0) (0,0,1) (1,0,1) runs counter-clockwise seen from +y.
            indices: vec![0, 2, 1, 0, 3, 2, 0, 1, 4],
        };
        let mut b = GlbBuilder::new();
        let grey = b.add_material(Material::diffuse("grey", [0.5; 3]));
        b.add_mesh_node("square", &mesh, grey);
        let gltf = crate::load::from_bytes(b.to_glb(), std::path::Path::new("square.glb"))
            .expect("parses");
        crate::load::scene(&gltf).expect("a scene")
    }

    fn atlas(xref: Vec<u32>, uv: Vec<[f32; 2]>, indices: Vec<u32>) -> Atlas {
        Atlas {
            width: 32,
            height: 32,
            pages: 1,
            texels_per_unit: 10.0,
            meshes: vec![AtlasMesh {
                xref,
                uv,
                indices,
                page: vec![0; 3],
            }],
        }
    }

    #[test]
    fn seam_edges_are_smooth_edges_whose_sides_lie_apart() {
        let scene = square_and_flap();
        assert!(scene.triangles.iter().all(|t| t.polygon.is_some()));
        // One chart for the square, the flap apart: only the crease 0-1 differs.
        let joined = atlas(
            vec![0, 1, 2, 3, 0, 1, 4],
            vec![
                [2.0, 2.0],
                [12.0, 2.0],
                [12.0, 12.0],
                [2.0, 12.0],
                [20.0, 2.0],
                [30.0, 2.0],
                [25.0, 12.0],
            ],
            vec![0, 2, 1, 0, 3, 2, 4, 5, 6],
        );
        let seams = find(&scene, &joined);
        assert_eq!((seams.edges.len(), seams.creases), (0, 1));
        // The second triangle moved to a place of its own: the diagonal becomes a seam.
        let split = atlas(
            vec![0, 1, 2, 0, 3, 2, 0, 1, 4],
            vec![
                [2.0, 2.0],
                [12.0, 2.0],
                [12.0, 12.0],
                [2.0, 16.0],
                [2.0, 26.0],
                [12.0, 26.0],
                [20.0, 2.0],
                [30.0, 2.0],
                [25.0, 12.0],
            ],
            vec![0, 2, 1, 3, 4, 5, 6, 7, 8],
        );
        let seams = find(&scene, &split);
        assert_eq!((seams.edges.len(), seams.creases), (1, 1));
        let e = seams.edges[0];
        // The ends in the same order on both sides: (0,0,0) at UV (2,2) and (2,16), (1,0,1)
        // at (12,12) and (12,26).
        let at_origin = if e.ends[0] == DVec3::ZERO { 0 } else { 1 };
        assert_eq!(e.ends[at_origin], DVec3::ZERO);
        assert_eq!(e.ends[1 - at_origin], DVec3::new(1.0, 0.0, 1.0));
        let uv = |s: usize, end: usize| e.sides[s].ends[end].to_array();
        let mut sides = [
            (uv(0, at_origin), uv(0, 1 - at_origin)),
            (uv(1, at_origin), uv(1, 1 - at_origin)),
        ];
        sides.sort_by(|a, b| a.0[1].total_cmp(&b.0[1]));
        assert_eq!(
            sides,
            [([2.0, 2.0], [12.0, 12.0]), ([2.0, 16.0], [12.0, 26.0])]
        );
        assert!((e.normal - DVec3::Y).length() < 1e-12);
    }
}
