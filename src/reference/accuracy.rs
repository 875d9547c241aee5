//! A bake's float lightmap against the Monte Carlo reference of its own layout, by surface
//! class and light: `penumbra reference BAKED.glb --out REF.exr --against BAKED.exr`.
//!
//! The measure is the one `penumbra compare` documents (RMSE with the reference's variance
//! removed), but relative to the mean reference irradiance `E` of all covered texels, so that
//! scenes without a fully lit region (a city lit by street lamps) are measured too:
//!
//! ```text
//! RMSE = sqrt(max(0, mean_i mean_c (b - r)² - mean_i mean_c s²)) / E
//! bias = (mean_i mean_c b - mean_i mean_c r) / E
//! ```
//!
//! Each region's RMSE and bias are relative to the same `E`, so a region's figure shows what it
//! adds to the whole; `share` is its part of the total squared error.
//!
//! **Regions.** A texel's surface class comes from its sub-samples' mean normal and height:
//! *ground* faces up (normal `y > 0.7`) within [`GROUND_BAND`] of the scene's height above the
//! lowest up-facing texel, *roof* faces up above that, *wall* is everything else (walls,
//! overhangs, the undersides). Its light comes from the reference's emitter visibility: *lit*
//! when at least half of its direct light arrives unblocked, *shadow* otherwise (and where no
//! emitter faces it).

use crate::error::{Error, Result};
use crate::reference::{ReferenceMap, TexelLayout};
use glam::DVec3;
use std::collections::BTreeMap;
use std::path::Path;

/// A texel is *ground* when it faces up and lies within this fraction of the scene's height
/// span (the up-facing texels' height range) above the lowest up-facing texel: one storey in a
/// city 50 m tall, a table top's thickness in a room.
pub(crate) const GROUND_BAND: f64 = 0.04;

/// Error of one set of texels, relative to the mean reference irradiance of all covered texels.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Accuracy {
    pub(crate) texels: usize,
    /// RMSE with the reference noise removed, as a fraction of the mean.
    pub rmse: f64,
    /// Mean of (bake - reference), as a fraction of the mean.
    pub(crate) bias: f64,
    /// The reference's RMS standard error, as a fraction of the mean.
    pub(crate) noise: f64,
    /// This set's part of the total squared error (0..1; 1 for all texels).
    pub(crate) share: f64,
}

/// Accuracy over all covered texels and by region (`ground-lit`, `wall-shadow`, ...).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Report {
    /// Mean reference irradiance of the covered texels (channel mean), W/m².
    pub mean: f64,
    pub all: Accuracy,
    pub regions: BTreeMap<String, Accuracy>,
}

#[derive(Default)]
struct Sums {
    n: usize,
    sq: f64,
    var: f64,
    diff: f64,
}

impl Sums {
    fn add(&mut self, b: DVec3, r: DVec3, s: DVec3) {
        self.n += 1;
        self.sq += (b - r).length_squared() / 3.0;
        self.var += s.length_squared() / 3.0;
        self.diff += (b - r).element_sum() / 3.0;
    }

    fn accuracy(&self, mean: f64, total_sq: f64) -> Accuracy {
        let n = self.n.max(1) as f64;
        Accuracy {
            texels: self.n,
            rmse: ((self.sq - self.var) / n).max(0.0).sqrt() / mean,
            bias: self.diff / n / mean,
            noise: (self.var / n).sqrt() / mean,
            share: if total_sq > 0.0 {
                self.sq / total_sq
            } else {
                0.0
            },
        }
    }
}

/// The surface class of each covered texel of `layout` (`None`: uncovered), see the module docs.
pub(crate) fn surface_classes(layout: &TexelLayout) -> Vec<Option<&'static str>> {
    let means: Vec<Option<(DVec3, DVec3)>> = layout
        .samples
        .iter()
        .map(|s| {
            (!s.is_empty()).then(|| {
                let k = s.len() as f64;
                let p = s.iter().map(|x| x.p).sum::<DVec3>() / k;
                let n = s.iter().map(|x| x.n).sum::<DVec3>().normalize_or_zero();
                (p, n)
            })
        })
        .collect();
    let up = |n: DVec3| n.y > 0.7;
    let (lo, hi) = means
        .iter()
        .flatten()
        .filter(|(_, n)| up(*n))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (p, _)| {
            (lo.min(p.y), hi.max(p.y))
        });
    let band = lo + GROUND_BAND * (hi - lo).max(0.0);
    means
        .iter()
        .map(|m| {
            m.map(|(p, n)| match (up(n), p.y <= band) {
                (true, true) => "ground",
                (true, false) => "roof",
                (false, _) => "wall",
            })
        })
        .collect()
}

/// Measures `bake` (the float lightmap, row-major, top row first, pages stacked as the
/// reference stacks them) against `reference` over `layout`'s covered texels.
pub fn measure(bake: &[DVec3], reference: &ReferenceMap, layout: &TexelLayout) -> Report {
    let classes = surface_classes(layout);
    let mut all = Sums::default();
    let mut by: BTreeMap<String, Sums> = BTreeMap::new();
    for (i, class) in classes.iter().enumerate() {
        let Some(class) = class else { continue };
        let (b, r, s) = (bake[i], reference.mean[i], reference.std_error[i]);
        let light = match reference.visibility[i] {
            Some(v) if v >= 0.5 => "lit",
            _ => "shadow",
        };
        all.add(b, r, s);
        by.entry(format!("{class}-{light}"))
            .or_default()
            .add(b, r, s);
    }
    let mean_ref = {
        let (mut sum, mut n) = (0.0, 0usize);
        for (i, c) in classes.iter().enumerate() {
            if c.is_some() {
                sum += reference.mean[i].element_sum() / 3.0;
                n += 1;
            }
        }
        if n > 0 && sum > 0.0 {
            sum / n as f64
        } else {
            1.0
        }
    };
    Report {
        mean: mean_ref,
        all: all.accuracy(mean_ref, all.sq),
        regions: by
            .iter()
            .map(|(k, s)| (k.clone(), s.accuracy(mean_ref, all.sq)))
            .collect(),
    }
}

/// A per-texel picture of [`measure`]'s inputs, for finding where the error is: red is the
/// relative error `(bake - reference) / E` (channel means, `E` the report's mean, reference
/// noise not removed), green the reference's direct-light visibility (-1 where it has none),
/// blue the surface class (0 ground, 1 roof, 2 wall; -1 uncovered, and then red is 0).
pub fn error_map(
    bake: &[DVec3],
    reference: &ReferenceMap,
    layout: &TexelLayout,
    mean: f64,
) -> Vec<DVec3> {
    surface_classes(layout)
        .iter()
        .enumerate()
        .map(|(i, class)| {
            let Some(class) = class else {
                return DVec3::new(0.0, -1.0, -1.0);
            };
            let error = (bake[i] - reference.mean[i]).element_sum() / 3.0 / mean;
            let visibility = reference.visibility[i].map_or(-1.0, f64::from);
            let class = match *class {
                "ground" => 0.0,
                "roof" => 1.0,
                _ => 2.0,
            };
            DVec3::new(error, visibility, class)
        })
        .collect()
}

/// Reads a bake's float lightmap: `path` (page 0) and, for a lightmap of `pages` pages, the
/// page files beside it ([`crate::bake::exr_page_path`]), stacked top to bottom as
/// [`crate::reference::texel_layout`] stacks the pages. Each page must be `width` x
/// `page_height` texels.
pub fn read_lightmap(path: &Path, width: u32, height: u32, pages: u32) -> Result<Vec<DVec3>> {
    let page_height = height / pages.max(1);
    let mut texels = Vec::with_capacity(width as usize * height as usize);
    for page in 0..pages.max(1) {
        let file = if page == 0 {
            path.to_path_buf()
        } else {
            crate::bake::exr_page_path(path, page)
        };
        let bad = |reason: String| Error::BadItem {
            path: file.clone(),
            item: "lightmap".into(),
            reason,
        };
        let image = image::open(&file)
            .map_err(|e| bad(format!("cannot read it as OpenEXR: {e}")))?
            .to_rgb32f();
        if image.width() != width || image.height() != page_height {
            return Err(bad(format!(
                "it is {}x{}, the baked file's lightmap page is {width}x{page_height}",
                image.width(),
                image.height()
            )));
        }
        texels.extend(
            image
                .pixels()
                .map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)),
        );
    }
    Ok(texels)
}

/// The report as a few lines of text: the whole, then each region with its share of the error.
pub fn text(report: &Report) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let line = |s: &mut String, name: &str, a: &Accuracy| {
        let _ = writeln!(
            s,
            "  {name:<14} {:>9} texels  RMSE {:>6.2}%  bias {:>+6.2}%  noise {:>5.2}%  share {:>5.1}%",
            a.texels,
            100.0 * a.rmse,
            100.0 * a.bias,
            100.0 * a.noise,
            100.0 * a.share
        );
    };
    let _ = writeln!(s, "against the reference (mean {:.4} W/m²):", report.mean);
    line(&mut s, "all", &report.all);
    for (k, a) in &report.regions {
        line(&mut s, k, a);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::SurfacePoint;

    fn point(y: f64, n: DVec3) -> SurfacePoint {
        SurfacePoint {
            p: DVec3::new(0.0, y, 0.0),
            n,
            ray_origin: DVec3::ZERO,
            polygon: 0,
        }
    }

    #[test]
    fn regions_and_errors_follow_their_definitions() {
        // Four texels: ground (y 0), roof (y 10), wall, uncovered.
        let layout = TexelLayout {
            width: 4,
            height: 1,
            pages: 1,
            supersample: 1,
            samples: vec![
                vec![point(0.0, DVec3::Y)],
                vec![point(10.0, DVec3::Y)],
                vec![point(5.0, DVec3::X)],
                vec![],
            ],
        };
        assert_eq!(
            surface_classes(&layout),
            vec![Some("ground"), Some("roof"), Some("wall"), None]
        );
        let reference = ReferenceMap {
            width: 4,
            height: 1,
            mean: vec![DVec3::splat(2.0); 4],
            std_error: vec![DVec3::ZERO, DVec3::ZERO, DVec3::splat(0.1), DVec3::ZERO],
            coverage: vec![1.0, 1.0, 1.0, 0.0],
            visibility: vec![Some(1.0), Some(0.2), None, None],
            nearest_surface: vec![f32::INFINITY; 4],
        };
        // Ground exact, roof 0.5 high, wall 0.1 low (its noise is 0.1: no error left).
        let bake = vec![
            DVec3::splat(2.0),
            DVec3::splat(2.5),
            DVec3::splat(1.9),
            DVec3::splat(99.0),
        ];
        let r = measure(&bake, &reference, &layout);
        assert_eq!(r.mean, 2.0);
        assert_eq!(r.all.texels, 3);
        // sq = 0 + 0.25 + 0.01, var = 0.01: sqrt(0.25 / 3) / 2.
        assert!((r.all.rmse - (0.25f64 / 3.0).sqrt() / 2.0).abs() < 1e-12);
        assert!((r.all.bias - (0.5 - 0.1) / 3.0 / 2.0).abs() < 1e-12);
        assert!((r.regions["roof-shadow"].rmse - 0.25).abs() < 1e-12);
        assert!((r.regions["roof-shadow"].share - 0.25 / 0.26).abs() < 1e-12);
        assert_eq!(r.regions["ground-lit"].rmse, 0.0);
        // Its error is all noise (up to rounding).
        assert!(r.regions["wall-shadow"].rmse < 1e-6);
        assert_eq!(r.regions.len(), 3);
    }
}
