//! Base-colour textures as the bake reads them: decoded 8-bit sRGB RGBA with a mip chain,
//! glTF sampler wrap modes, the texture's `texCoord` set and `KHR_texture_transform`.
//!
//! Two lookups: [`Image::bilinear`] at a point of the finest level (the alpha test of a ray's
//! hit, the reference's albedo at a path vertex), and [`Image::filtered`], trilinear between the
//! mip levels whose texels match a footprint (the mean albedo over a mesh element). Texels are
//! held as 16-bit linear values (an 8-bit sRGB code loses nothing, and box means do not drift
//! by re-quantising); levels are 2x2 box means of the level above; alpha is linear throughout.

use glam::{DVec2, DVec3};
use std::sync::OnceLock;

/// A glTF sampler's wrap mode along one texture axis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Wrap {
    /// 10497, the glTF default.
    #[default]
    Repeat,
    /// 33071.
    ClampToEdge,
    /// 33648.
    MirroredRepeat,
}

impl Wrap {
    /// The wrap mode of a glTF sampler's `wrapS`/`wrapT` code.
    pub(crate) fn from_gl(code: u32) -> Wrap {
        match code {
            33071 => Wrap::ClampToEdge,
            33648 => Wrap::MirroredRepeat,
            _ => Wrap::Repeat,
        }
    }

    /// Texel index `i` of an axis of `n` texels, wrapped into `0..n`.
    fn index(self, i: i64, n: usize) -> usize {
        let n = n as i64;
        match self {
            Wrap::Repeat => i.rem_euclid(n) as usize,
            Wrap::ClampToEdge => i.clamp(0, n - 1) as usize,
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                (if m < n { m } else { 2 * n - 1 - m }) as usize
            }
        }
    }
}

/// How a material reads one texture: which image, which `TEXCOORD_n`, the sampler's wrap
/// modes and the `KHR_texture_transform` affine map (rows of `uv' = M (u, v, 1)`).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct TextureRef {
    /// Index into [`crate::scene::Scene::images`].
    pub(crate) image: usize,
    /// The `TEXCOORD_n` set.
    pub(crate) tex_coord: u32,
    /// `wrapS`, `wrapT`.
    pub(crate) wrap: [Wrap; 2],
    /// `KHR_texture_transform` as two rows of an affine map; identity without one.
    pub(crate) transform: [DVec3; 2],
}

impl TextureRef {
    /// The identity transform.
    pub(crate) const IDENTITY: [DVec3; 2] = [DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.0, 1.0, 0.0)];

    /// `KHR_texture_transform`'s matrix, translation x rotation x scale (the extension's
    /// definition; rotation in radians, counter-clockwise in UV space).
    pub(crate) fn transform_of(offset: DVec2, rotation: f64, scale: DVec2) -> [DVec3; 2] {
        let (s, c) = rotation.sin_cos();
        [
            DVec3::new(c * scale.x, s * scale.y, offset.x),
            DVec3::new(-s * scale.x, c * scale.y, offset.y),
        ]
    }

    /// The texture coordinate that a mesh UV maps to.
    pub(crate) fn apply(&self, uv: DVec2) -> DVec2 {
        let h = DVec3::new(uv.x, uv.y, 1.0);
        DVec2::new(self.transform[0].dot(h), self.transform[1].dot(h))
    }
}

/// One decoded image and its mip chain.
pub(crate) struct Image {
    /// Level 0 first; each level half the size of the one above (at least 1 texel a side).
    levels: Vec<Level>,
}

struct Level {
    width: usize,
    height: usize,
    /// Linear RGB and alpha in units of 1/65535, row-major from the image's top-left (glTF's
    /// UV origin).
    texels: Vec<[u16; 4]>,
}

impl std::fmt::Debug for Image {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (w, h) = self.size();
        write!(f, "Image({w}x{h}, {} levels)", self.levels.len())
    }
}

/// sRGB code to linear value in units of 1/65535, for the 256 codes.
fn linear_of(code: u8) -> u16 {
    static LUT: OnceLock<[u16; 256]> = OnceLock::new();
    LUT.get_or_init(|| {
        std::array::from_fn(|i| {
            (crate::color::srgb_to_linear(i as f64 / 255.0) * 65535.0).round() as u16
        })
    })[code as usize]
}

/// Linear value in [0, 1] to units of 1/65535.
fn unit(v: f64) -> u16 {
    (v.clamp(0.0, 1.0) * 65535.0).round() as u16
}

impl Image {
    /// An image of `width` x `height` RGBA8 texels (sRGB colour, linear alpha), row-major from
    /// the top-left. `None` when the size is 0 or does not match the texels.
    pub(crate) fn new(width: usize, height: usize, texels: Vec<[u8; 4]>) -> Option<Image> {
        if width == 0 || height == 0 || texels.len() != width * height {
            return None;
        }
        let texels = texels
            .into_iter()
            .map(|t| {
                [
                    linear_of(t[0]),
                    linear_of(t[1]),
                    linear_of(t[2]),
                    (u16::from(t[3]) << 8) | u16::from(t[3]),
                ]
            })
            .collect();
        let mut levels = vec![Level {
            width,
            height,
            texels,
        }];
        while let Some(last) = levels.last()
            && (last.width > 1 || last.height > 1)
        {
            levels.push(last.half());
        }
        Some(Image { levels })
    }

    /// Width and height of level 0, texels.
    pub(crate) fn size(&self) -> (usize, usize) {
        (self.levels[0].width, self.levels[0].height)
    }

    /// Linear RGB and alpha at texture coordinate `uv`, bilinear on level 0.
    pub(crate) fn bilinear(&self, uv: DVec2, wrap: [Wrap; 2]) -> (DVec3, f64) {
        self.levels[0].bilinear(uv, wrap)
    }

    /// Linear RGB and alpha averaged over a square footprint `footprint` texture units wide
    /// around `uv`: trilinear between the two mip levels whose texels are nearest that size.
    pub(crate) fn filtered(&self, uv: DVec2, footprint: f64, wrap: [Wrap; 2]) -> (DVec3, f64) {
        let (w, h) = self.size();
        let texels = footprint * w.max(h) as f64;
        let lod = if texels > 1.0 { texels.log2() } else { 0.0 };
        let top = (self.levels.len() - 1) as f64;
        let lod = lod.min(top);
        let (l0, frac) = (lod.floor() as usize, lod.fract());
        let a = self.levels[l0].bilinear(uv, wrap);
        if frac <= 0.0 || l0 + 1 >= self.levels.len() {
            return a;
        }
        let b = self.levels[l0 + 1].bilinear(uv, wrap);
        (
            a.0 * (1.0 - frac) + b.0 * frac,
            a.1 * (1.0 - frac) + b.1 * frac,
        )
    }
}

impl Level {
    fn texel(&self, x: usize, y: usize) -> (DVec3, f64) {
        let t = self.texels[y * self.width + x].map(|c| f64::from(c) / 65535.0);
        (DVec3::new(t[0], t[1], t[2]), t[3])
    }

    fn bilinear(&self, uv: DVec2, wrap: [Wrap; 2]) -> (DVec3, f64) {
        let x = uv.x * self.width as f64 - 0.5;
        let y = uv.y * self.height as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let xs = [
            wrap[0].index(x0, self.width),
            wrap[0].index(x0 + 1, self.width),
        ];
        let ys = [
            wrap[1].index(y0, self.height),
            wrap[1].index(y0 + 1, self.height),
        ];
        let mut rgb = DVec3::ZERO;
        let mut alpha = 0.0;
        for (j, wy) in [(0, 1.0 - fy), (1, fy)] {
            for (i, wx) in [(0, 1.0 - fx), (1, fx)] {
                let w = wx * wy;
                if w > 0.0 {
                    let (c, a) = self.texel(xs[i], ys[j]);
                    rgb += c * w;
                    alpha += a * w;
                }
            }
        }
        (rgb, alpha)
    }

    /// The next mip level: 2x2 box means in linear colour (an odd last row or column is
    /// averaged into its neighbour's texel).
    fn half(&self) -> Level {
        let (w, h) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let mut texels = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let (mut rgb, mut alpha, mut n) = (DVec3::ZERO, 0.0, 0.0);
                for sy in 2 * y..(2 * y + 2).min(self.height) {
                    for sx in 2 * x..(2 * x + 2).min(self.width) {
                        let (c, a) = self.texel(sx, sy);
                        rgb += c;
                        alpha += a;
                        n += 1.0;
                    }
                }
                let (rgb, alpha) = (rgb / n, alpha / n);
                texels.push([unit(rgb.x), unit(rgb.y), unit(rgb.z), unit(alpha)]);
            }
        }
        Level {
            width: w,
            height: h,
            texels,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_modes_index_as_gl_does() {
        assert_eq!(Wrap::Repeat.index(-1, 4), 3);
        assert_eq!(Wrap::Repeat.index(5, 4), 1);
        assert_eq!(Wrap::ClampToEdge.index(-3, 4), 0);
        assert_eq!(Wrap::ClampToEdge.index(9, 4), 3);
        assert_eq!(Wrap::MirroredRepeat.index(4, 4), 3);
        assert_eq!(Wrap::MirroredRepeat.index(-1, 4), 0);
        assert_eq!(Wrap::MirroredRepeat.index(7, 4), 0);
    }

    #[test]
    fn a_checker_filters_to_its_linear_mean_and_samples_sharp() {
        // 8x8 checker of sRGB 255 and 0: linear mean 0.5 at the coarsest level.
        let texels = (0..64)
            .map(|i| {
                let v = if (i % 8 + i / 8) % 2 == 0 { 255 } else { 0 };
                [v, v, v, 255]
            })
            .collect();
        let img = Image::new(8, 8, texels).unwrap();
        let (mean, a) = img.filtered(DVec2::new(0.3, 0.7), 1.0, [Wrap::Repeat; 2]);
        assert!(
            (mean.x - 0.5).abs() < 1e-4 && (a - 1.0).abs() < 1e-9,
            "{mean} {a}"
        );
        // The centre of texel (0, 0) is white, of texel (1, 0) black.
        let (c, _) = img.bilinear(DVec2::new(0.5 / 8.0, 0.5 / 8.0), [Wrap::Repeat; 2]);
        assert!((c.x - 1.0).abs() < 1e-9);
        let (c, _) = img.bilinear(DVec2::new(1.5 / 8.0, 0.5 / 8.0), [Wrap::Repeat; 2]);
        assert!(c.x.abs() < 1e-9);
    }

    #[test]
    fn the_transform_is_translation_rotation_scale() {
        let t = TextureRef {
            image: 0,
            tex_coord: 0,
            wrap: [Wrap::Repeat; 2],
            transform: TextureRef::transform_of(
                DVec2::new(0.5, 0.25),
                std::f64::consts::FRAC_PI_2,
                DVec2::new(2.0, 3.0),
            ),
        };
        // Scale (1, 0) to (2, 0); rotate by 90 degrees as the extension's matrix does, to
        // (0, -2); translate to (0.5, -1.75).
        let uv = t.apply(DVec2::new(1.0, 0.0));
        assert!((uv - DVec2::new(0.5, -1.75)).length() < 1e-12, "{uv}");
    }
}
