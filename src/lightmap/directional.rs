//! Directional lightmaps (`--directional`): per texel, how the irradiance changes with the
//! normal, so that a normal map shades baked light.
//!
//! The quantity is the L1 band of the irradiance's spherical harmonics (Ramamoorthi, Hanrahan,
//! "An efficient representation for irradiance environment maps", SIGGRAPH 2001), in the
//! layout of Godot's directional lightmaps: `H(n) = L0 + 4 L0 (r · n)` for a unit world-space
//! normal `n`, per linear RGB channel, with `r` stored as three pages (its `x`, `y` and `z`
//! components; each `8-bit code / 255 x 2 - 1`). The L1 band of the incident radiance `L` is
//! half its light vector `Q = ∫ L ω dω` ([`crate::light::LightVector`]); `L0` is chosen so
//! that the geometric normal `n_g` gets the lightmap's own irradiance `H` exactly (as Unity
//! rebalances its directional maps): since `Q · n_g = H`, `L0 = H / 2` and `r = Q / (4 H)`.
//! So `H(n) = H (1/2 + 2 r · n)`, and the pages hold nothing but `r`. A uniform hemisphere
//! (an open sky, the furnace) gives `r = n_g / 4` exactly, and `H(n)` is then exact for every
//! `n`; light from one direction `ω` gives `r = ω / (4 ω · n_g)`, exact at `n_g` and `n = ω`
//! only when `ω = n_g`. Each component is kept within [-1, 1], which holds light up to 76°
//! from the normal.
//!
//! The light vectors come from the solve ([`crate::solve::Solution::light`]) and are
//! rasterized as the irradiance is ([`super::rasterize`]), component by component, so their
//! texels are means over the same sub-samples, dilated and stitched the same way.

use super::{Lightmap, Locator, Raster, interpolate, rasterize_many};
use crate::light::LightVector;
use glam::DVec3;

/// The ratio pages `r` (`x`, `y`, `z`) in the atlas from the light vector at the vertices of
/// `meshes` (`light[m][v]`) and their irradiance (`irradiance[m][v]`): both rasterized in one
/// pass as the lightmap is ([`super::rasterize`], each map stitched at the seams when
/// `stitch`), then [`ratios`]. The irradiance is the vertices' own, interpolated: where the
/// lightmap takes a punctual light per texel (a shadow edge inside an element) the light
/// vector stays interpolated, and so must the irradiance it is divided by.
pub(crate) fn ratio_maps(
    r: &Raster,
    light: &[Vec<LightVector>],
    irradiance: &[Vec<DVec3>],
) -> [Lightmap; 3] {
    // The locators find the triangle and weights; the values are interpolated per map.
    let axes: Vec<[Vec<DVec3>; 3]> = light
        .iter()
        .map(|l| [0, 1, 2].map(|axis| l.iter().map(|q| q[axis]).collect()))
        .collect();
    let locators: Vec<Locator> = r
        .meshes
        .iter()
        .zip(irradiance)
        .map(|(m, h)| Locator::new(m, h))
        .collect();
    let mut maps = rasterize_many(r, &|at, hint| match locators[at.mesh]
        .locate_near(at.q, &mut hint.triangle)
    {
        Some((t, l)) => {
            let [x, y, z] = &axes[at.mesh];
            [x, y, z, &irradiance[at.mesh]].map(|v| interpolate(v, t, l))
        }
        None => [DVec3::ZERO; 4],
    });
    for map in &mut maps {
        r.stitch_seams(map);
    }
    let [x, y, z, h] = maps;
    ratios(&h, &[x, y, z])
}

/// The ratio pages `r = Q / (4 H)` from the irradiance map `irradiance` and the light vector's
/// components `light` (`x`, `y`, `z`; each per channel, the same texel grid), each component
/// kept within [-1, 1]; 0 where the irradiance is 0.
pub(crate) fn ratios(irradiance: &Lightmap, light: &[Lightmap; 3]) -> [Lightmap; 3] {
    light.clone().map(|mut q| {
        for (r, h) in q.texels.iter_mut().zip(&irradiance.texels) {
            let ratio = *r / (4.0 * *h);
            *r = DVec3::select(h.cmpgt(DVec3::ZERO), ratio, DVec3::ZERO)
                .clamp(DVec3::splat(-1.0), DVec3::ONE);
        }
        q
    })
}

/// The irradiance for a unit world-space normal `n` (W/m², per channel) from the lightmap's
/// irradiance `h` and its ratios `r` (`x`, `y`, `z`): `H (1/2 + 2 r · n)`, at least zero.
pub(crate) fn shade(h: DVec3, r: [DVec3; 3], n: DVec3) -> DVec3 {
    let dot = r[0] * n.x + r[1] * n.y + r[2] * n.z;
    (h * (DVec3::splat(0.5) + 2.0 * dot)).max(DVec3::ZERO)
}

/// 8-bit RGB of every page of a ratio map (page-major, rows top first): `r` in [-1, 1] to
/// `round((r + 1) / 2 x 255)`, no curve (Godot's encoding of its L1 pages).
pub(crate) fn to_rgb8(map: &Lightmap) -> Vec<u8> {
    map.texels
        .iter()
        .flat_map(|t| {
            t.to_array()
                .map(|c| ((c.clamp(-1.0, 1.0) + 1.0) * 0.5 * 255.0).round() as u8)
        })
        .collect()
}

/// The ratio of an 8-bit code ([`to_rgb8`]'s inverse).
pub fn decode(code: u8) -> f64 {
    code as f64 / 255.0 * 2.0 - 1.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(texels: Vec<DVec3>) -> Lightmap {
        Lightmap {
            width: texels.len() as u32,
            height: 1,
            coverage: vec![1.0; texels.len()],
            texels,
        }
    }

    #[test]
    fn the_geometric_normal_gets_the_lightmap_and_codes_round_trip() {
        // Light from 30° off the normal z, along x: Q = H (tan 30°, 0, 1).
        let h = DVec3::new(2.0, 1.0, 0.0);
        let t = 30f64.to_radians().tan();
        let q = [h * t, DVec3::ZERO, h];
        let r = ratios(&map(vec![h]), &q.map(|c| map(vec![c])));
        let r = [0, 1, 2].map(|a| r[a].texels[0]);
        assert_eq!(r[2], DVec3::new(0.25, 0.25, 0.0));
        assert!((shade(h, r, DVec3::Z) - h).abs().max_element() < 1e-15);
        // Facing the light: H (1/2 + (sin 30° tan 30° + cos 30°) / 2) = H / 2 + H / (2 cos 30°).
        let w = DVec3::new(30f64.to_radians().sin(), 0.0, 30f64.to_radians().cos());
        let want = h * (0.5 + 0.5 / 30f64.to_radians().cos());
        assert!((shade(h, r, w) - want).abs().max_element() < 1e-12);
        for code in [0u8, 1, 127, 128, 254, 255] {
            let m = map(vec![DVec3::splat(decode(code))]);
            assert_eq!(to_rgb8(&m), vec![code; 3]);
        }
    }
}
