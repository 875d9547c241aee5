//! Colour: the sRGB transfer curves (IEC 61966-2-1), used to encode the lightmap PNGs and the
//! rendered pictures and to decode base-colour textures and lightmaps.

/// The sRGB opto-electronic transfer function: linear value in \[0, 1\] to encoded value.
pub(crate) fn linear_to_srgb(c: f64) -> f64 {
    if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// The sRGB electro-optical transfer function, the inverse of [`linear_to_srgb`]: encoded value
/// in \[0, 1\] to linear.
pub fn srgb_to_linear(e: f64) -> f64 {
    if e <= 0.04045 {
        e / 12.92
    } else {
        ((e + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_curves_are_inverse_and_continuous_at_their_joints() {
        for i in 0..=1000 {
            let v = i as f64 / 1000.0;
            assert!((srgb_to_linear(linear_to_srgb(v)) - v).abs() < 1e-12, "{v}");
        }
        // The linear segment and the power segment meet (to the precision of the standard's
        // rounded constants).
        assert!((12.92 * 0.0031308 - (1.055 * 0.0031308f64.powf(1.0 / 2.4) - 0.055)).abs() < 1e-7);
        assert!((linear_to_srgb(1.0) - 1.0).abs() < 1e-15);
        assert_eq!(srgb_to_linear(0.0), 0.0);
    }
}
