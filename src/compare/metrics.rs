//! The error measures: texel regions from the reference, a bake's lightmap error against the
//! reference (the measure [`crate::compare`] documents), a mesh's direct light against the
//! exact one at sample points, and the direct-light shadow error of the floor used by the
//! mesher tests.

use crate::Bake;
use crate::lightmap::{Lightmap, Locator};
use crate::reference::ReferenceMap;
use crate::solve::{Direct, SurfacePoint};
use crate::visibility::Visibility;
use glam::DVec3;
use std::collections::BTreeMap;
use std::f64::consts::PI;

/// A texel's region, from the reference (see [`crate::compare`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Region {
    Lit,
    Penumbra,
    Umbra,
    Contact,
    Indirect,
}

impl Region {
    pub(crate) const ALL: [Region; 5] = [
        Region::Lit,
        Region::Penumbra,
        Region::Umbra,
        Region::Contact,
        Region::Indirect,
    ];

    pub(crate) fn name(self) -> &'static str {
        match self {
            Region::Lit => "lit",
            Region::Penumbra => "penumbra",
            Region::Umbra => "umbra",
            Region::Contact => "contact",
            Region::Indirect => "indirect",
        }
    }
}

/// Emitter visibility above which a texel is lit, below `1 -` which it is in umbra.
const LIT_VISIBILITY: f32 = 0.995;

/// Classifies every texel of `reference` (`None`: uncovered). `contact_distance`: scene units.
pub fn classify(reference: &ReferenceMap, contact_distance: f64) -> Vec<Option<Region>> {
    (0..reference.mean.len())
        .map(|i| {
            if reference.coverage[i] <= 0.0 {
                return None;
            }
            if (reference.nearest_surface[i] as f64) < contact_distance {
                return Some(Region::Contact);
            }
            Some(match reference.visibility[i] {
                None => Region::Indirect,
                Some(v) if v > LIT_VISIBILITY => Region::Lit,
                Some(v) if v < 1.0 - LIT_VISIBILITY => Region::Umbra,
                Some(_) => Region::Penumbra,
            })
        })
        .collect()
}

/// Error of one bake over a set of texels, relative to the mean lit irradiance (see
/// [`crate::compare`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ErrorStats {
    pub texels: usize,
    /// RMSE with the reference's variance removed.
    pub rmse: f64,
    /// RMSE as measured (bake error and reference noise together).
    pub(crate) rmse_raw: f64,
    /// The reference's RMS standard error over the same texels.
    pub noise: f64,
    /// Largest texel error beyond three reference standard errors.
    pub(crate) max: f64,
}

#[derive(Default)]
struct Accumulator {
    n: usize,
    sq: f64,
    var: f64,
    max: f64,
}

impl Accumulator {
    fn add(&mut self, b: DVec3, r: DVec3, s: DVec3) {
        let sq = (b - r).length_squared() / 3.0;
        let var = s.length_squared() / 3.0;
        self.n += 1;
        self.sq += sq;
        self.var += var;
        self.max = self.max.max(sq.sqrt() - 3.0 * var.sqrt());
    }

    fn stats(&self, scale: f64) -> ErrorStats {
        let n = self.n.max(1) as f64;
        ErrorStats {
            texels: self.n,
            rmse: ((self.sq - self.var) / n).max(0.0).sqrt() / scale,
            rmse_raw: (self.sq / n).sqrt() / scale,
            noise: (self.var / n).sqrt() / scale,
            max: self.max.max(0.0) / scale,
        }
    }
}

/// A bake's error over all covered texels and per region. `scale`: the mean lit irradiance.
pub fn lightmap_error(
    bake: &Lightmap,
    reference: &ReferenceMap,
    regions: &[Option<Region>],
    scale: f64,
) -> (ErrorStats, BTreeMap<Region, ErrorStats>) {
    let mut all = Accumulator::default();
    let mut by: BTreeMap<Region, Accumulator> = BTreeMap::new();
    for (i, r) in regions.iter().enumerate() {
        let Some(r) = r else { continue };
        let (b, m, s) = (bake.texels[i], reference.mean[i], reference.std_error[i]);
        all.add(b, m, s);
        by.entry(*r).or_default().add(b, m, s);
    }
    (
        all.stats(scale),
        by.iter().map(|(r, a)| (*r, a.stats(scale))).collect(),
    )
}

/// Mean reference irradiance (channel mean) of the lit texels; of all directly lit texels if
/// none is fully lit; of all covered texels if none is.
pub(crate) fn mean_lit_irradiance(reference: &ReferenceMap, regions: &[Option<Region>]) -> f64 {
    let mean_of = |keep: &dyn Fn(Region) -> bool| {
        let (mut sum, mut n) = (0.0, 0usize);
        for (i, r) in regions.iter().enumerate() {
            if let Some(r) = r
                && keep(*r)
            {
                sum += reference.mean[i].element_sum() / 3.0;
                n += 1;
            }
        }
        (n > 0 && sum > 0.0).then(|| sum / n as f64)
    };
    mean_of(&|r| r == Region::Lit)
        .or_else(|| mean_of(&|r| r != Region::Indirect))
        .or_else(|| mean_of(&|_| true))
        .unwrap_or(0.0)
}

/// The seven points per element where [`mesh_samples`] compares a mesh's direct light with the
/// exact one, as (barycentric coordinates, weight): Dunavant's degree-5 rule ("High degree
/// efficient symmetrical Gaussian quadrature rules for the triangle", 1985). Every point is
/// inside the element: on an edge, which may lie on a hard shadow line, the exact light is
/// either side's by rounding.
const MESH_POINTS: [([f64; 3], f64); 7] = {
    const A1: f64 = 0.059_715_871_789_770;
    const B1: f64 = 0.470_142_064_105_115;
    const W1: f64 = 0.132_394_152_788_506;
    const A2: f64 = 0.797_426_985_353_087;
    const B2: f64 = 0.101_286_507_323_456;
    const W2: f64 = 0.125_939_180_544_827;
    [
        ([1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0], 0.225),
        ([A1, B1, B1], W1),
        ([B1, A1, B1], W1),
        ([B1, B1, A1], W1),
        ([A2, B2, B2], W2),
        ([B2, A2, B2], W2),
        ([B2, B2, A2], W2),
    ]
};

/// One point of a mesh where [`mesh_samples`] compared the light its vertices show with the
/// exact direct light.
#[derive(Clone, Copy, Debug)]
pub struct MeshSample {
    /// The receiver polygon.
    pub(crate) polygon: usize,
    /// The area it stands for (scene units²).
    pub(crate) weight: f64,
    /// What linear interpolation between the element's vertex values shows there (W/m²,
    /// channel mean).
    pub(crate) shown: f64,
    /// The exact direct irradiance there (W/m², channel mean).
    pub(crate) exact: f64,
}

/// How well a mesh shows the direct light, with no Monte Carlo reference: at seven points per
/// element ([`MESH_POINTS`]), what linear interpolation of the vertex values of
/// `bake.solution.direct` shows, against the exact direct light there (`direct`, the bake's own
/// direct-light evaluator). The vertex values are exact, but near an area emitter, where they
/// are the fans' means ([`crate::solve::Solution::direct`]) and the lightmap takes the
/// emitter's light per texel instead. Points buried under other geometry are left out (no one
/// sees them, as the reference leaves out buried texels). It isolates the mesh: every error it
/// measures is what interpolation between exact values cannot show (a shadow edge across an
/// element, a pool of light between vertices).
pub fn mesh_samples(bake: &Bake, vis: &Visibility, direct: &Direct<'_>) -> Vec<MeshSample> {
    let mean = |c: DVec3| c.element_sum() / 3.0;
    let mut samples = Vec::new();
    for (m, at_vertices) in bake.meshes.iter().zip(&bake.solution.direct) {
        let frame = &bake.scene.polygons[m.polygon].frame;
        let mut points = Vec::new();
        let mut shown = Vec::new();
        for t in &m.triangles {
            let p = t.map(|i| m.vertices[i as usize]);
            let v = t.map(|i| mean(at_vertices[i as usize]));
            let a = m.triangle_area(t);
            for (w, weight) in MESH_POINTS {
                let at = frame.world_from_plane(p[0] * w[0] + p[1] * w[1] + p[2] * w[2]);
                if vis.buried(at, frame.n) {
                    continue;
                }
                points.push(SurfacePoint::new(at, frame.n, m.polygon, vis));
                shown.push((a * weight, v[0] * w[0] + v[1] * w[1] + v[2] * w[2]));
            }
        }
        let exact = direct.irradiance_points(&points);
        samples.extend(
            shown
                .iter()
                .zip(&exact)
                .map(|(&(weight, shown), &e)| MeshSample {
                    polygon: m.polygon,
                    weight,
                    shown,
                    exact: mean(e),
                }),
        );
    }
    samples
}

/// The error of a set of [`MeshSample`]s, as fractions of the mean exact light over the lit
/// points (those with any direct light).
#[derive(Clone, Copy, Debug)]
pub struct MeshError {
    /// Area-weighted RMSE over all points.
    pub rmse: f64,
    /// Area-weighted RMSE over the lit points.
    pub(crate) rmse_lit: f64,
    /// The light shown over the exact light, both integrated over the points.
    pub shown_over_exact: f64,
    /// The mean exact light over the lit points (W/m²).
    pub(crate) lit_mean: f64,
}

/// The error of `samples` (see [`MeshError`]); `None` when no point is lit.
pub fn mesh_error(samples: &[MeshSample]) -> Option<MeshError> {
    let sum = |keep: &dyn Fn(&MeshSample) -> bool, f: &dyn Fn(&MeshSample) -> f64| {
        samples.iter().filter(|s| keep(s)).map(f).sum::<f64>()
    };
    let (all, lit) = (|_: &MeshSample| true, |s: &MeshSample| s.exact > 0.0);
    let lit_area = sum(&lit, &|s| s.weight);
    let lit_mean = sum(&lit, &|s| s.weight * s.exact) / lit_area;
    if lit_area <= 0.0 || lit_mean <= 0.0 {
        return None;
    }
    let squared = |s: &MeshSample| s.weight * (s.shown - s.exact).powi(2);
    Some(MeshError {
        rmse: (sum(&all, &squared) / sum(&all, &|s| s.weight)).sqrt() / lit_mean,
        rmse_lit: (sum(&lit, &squared) / lit_area).sqrt() / lit_mean,
        shown_over_exact: sum(&all, &|s| s.weight * s.shown) / sum(&all, &|s| s.weight * s.exact),
        lit_mean,
    })
}
/// Error of the direct light in the shadowed part of the floor.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct ShadowError {
    /// RMS error relative to the floor's peak irradiance.
    pub rms: f64,
    /// Max error relative to the floor's peak irradiance.
    pub max: f64,
    /// Sample points in shadow (exact below 99.5% of unoccluded).
    pub points: usize,
}

/// Evaluates the bake's mesh interpolant of the irradiance against the exact direct light
/// ([`Direct`], backprojection) on a stratified grid of `points_per_side` points per side of
/// each triangle of the floor, keeping the points in shadow. Meaningful for bakes with
/// `bounces = Some(0)`. `None` when the scene has no upward polygon.
pub fn shadow_error(b: &Bake, points_per_side: usize) -> Option<ShadowError> {
    let scene = &b.scene;
    let vis = Visibility::new(scene);
    let direct = Direct::new(scene, &vis, 64);
    let floor = (0..scene.polygons.len())
        .filter(|&i| scene.polygons[i].frame.n.y > 0.99)
        .max_by(|&i, &j| scene.polygons[i].area.total_cmp(&scene.polygons[j].area))?;
    let poly = &scene.polygons[floor];
    let mi = b.meshes.iter().position(|m| m.polygon == floor)?;
    let loc = Locator::new(&b.meshes[mi], &b.solution.irradiance[mi]);
    let mut errors = Vec::new();
    let mut peak: f64 = 0.0;
    let n = points_per_side.max(1);
    for t in &poly.triangles_plane {
        for q in crate::geometry::triangle_grid(t, n) {
            let p = poly.frame.world_from_plane(q);
            let at = SurfacePoint::new(p, poly.frame.n, floor, &vis);
            let exact = direct.irradiance(&at).x;
            let unoccluded: f64 = direct
                .emitters
                .iter()
                .map(|e| PI * e.radiance.x * e.form_factor(p, poly.frame.n))
                .sum();
            peak = peak.max(exact);
            if exact < 0.995 * unoccluded {
                errors.push((loc.value(q).x - exact).abs());
            }
        }
    }
    let peak = peak.max(f64::MIN_POSITIVE);
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
    let max = errors.iter().copied().fold(0.0, f64::max);
    Some(ShadowError {
        rms: rms / peak,
        max: max / peak,
        points: errors.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(mean: Vec<DVec3>, std_error: Vec<DVec3>) -> ReferenceMap {
        let n = mean.len();
        ReferenceMap {
            width: n as u32,
            height: 1,
            mean,
            std_error,
            coverage: vec![1.0; n],
            visibility: vec![Some(1.0); n],
            nearest_surface: vec![f32::INFINITY; n],
        }
    }

    #[test]
    fn the_reference_variance_is_removed_from_the_error() {
        // Bake exactly right; reference off by its own standard error everywhere: no error.
        let r = map(vec![DVec3::splat(1.1); 100], vec![DVec3::splat(0.1); 100]);
        let b = Lightmap {
            width: 100,
            height: 1,
            texels: vec![DVec3::ONE; 100],
            coverage: vec![1.0; 100],
        };
        let regions = classify(&r, 0.0);
        assert!(regions.iter().all(|r| *r == Some(Region::Lit)));
        let scale = mean_lit_irradiance(&r, &regions);
        assert!((scale - 1.1).abs() < 1e-12);
        let (e, by) = lightmap_error(&b, &r, &regions, scale);
        assert!(e.rmse < 1e-6, "{e:?}");
        assert!((e.rmse_raw - 0.1 / 1.1).abs() < 1e-12);
        assert!((e.noise - 0.1 / 1.1).abs() < 1e-12);
        assert_eq!(e.max, 0.0);
        assert_eq!(by[&Region::Lit], e);
        // Off by 0.3 from the reference mean, whose own noise is 0.1: sqrt(0.3² - 0.1²).
        let b = Lightmap {
            texels: vec![DVec3::splat(1.4); 100],
            ..b
        };
        let (e, _) = lightmap_error(&b, &r, &regions, scale);
        assert!((e.rmse - 0.08f64.sqrt() / 1.1).abs() < 1e-9, "{e:?}");
        assert!(e.max.abs() < 1e-9); // 0.3 = 3 standard errors: not beyond
    }

    #[test]
    fn regions_follow_visibility_and_distance() {
        let mut r = map(vec![DVec3::ONE; 6], vec![DVec3::ZERO; 6]);
        r.visibility = vec![Some(1.0), Some(0.5), Some(0.0), Some(1.0), None, Some(1.0)];
        r.nearest_surface[3] = 0.01;
        r.coverage[5] = 0.0;
        assert_eq!(
            classify(&r, 0.02),
            vec![
                Some(Region::Lit),
                Some(Region::Penumbra),
                Some(Region::Umbra),
                Some(Region::Contact),
                Some(Region::Indirect),
                None
            ]
        );
    }
}
