//! The light probes (`--probes`) in the written file.

use super::{Bin, array_mut, png_bytes, push_view};
use crate::error::{Error, Result};
use crate::probes::Probes;
use serde_json::{Value, json};

/// The light probes in the root's `extras.penumbra_probes` (see [`crate::probes`]): the grid,
/// per probe its nine RGB radiance coefficients (three.js's `SphericalHarmonics3` order,
/// W/(m² sr)) and its ambient cube (irradiance facing ±x, ±y, ±z, W/m²), the probes inside
/// geometry; and the ambient cubes as Bevy's irradiance-volume texture, an image of the 3D
/// texture's slices stacked top to bottom (8-bit sRGB, times `scale` for W/m²).
pub(super) fn write(root: &mut Value, bin: &mut Bin, probes: &Probes) -> Result<()> {
    let [nx, ny, nz] = probes.counts;
    // Bevy's layout: (nx, 2 ny, 3 nz); texel (x, y + ny if the face is positive, z + nz x the
    // axis) holds the face's irradiance.
    let (w, h, d) = (nx, 2 * ny, 3 * nz);
    let scale = probes
        .cube
        .iter()
        .flatten()
        .map(|e| e.max_element())
        .fold(0.0, f64::max);
    let scale = if scale > 0.0 { scale } else { 1.0 };
    let mut rgb = vec![0u8; 3 * w * h * d];
    for (i, cube) in probes.cube.iter().enumerate() {
        let (x, y, z) = (i % nx, i / nx % ny, i / (nx * ny));
        for (face, e) in cube.iter().enumerate() {
            let (axis, positive) = (face / 2, face % 2 == 0);
            let (t, p) = (y + if positive { ny } else { 0 }, z + axis * nz);
            let at = 3 * ((p * h + t) * w + x);
            for c in 0..3 {
                let v = crate::color::linear_to_srgb((e[c] / scale).clamp(0.0, 1.0));
                rgb[at + c] = (v * 255.0).round() as u8;
            }
        }
    }
    let png = png_bytes(&rgb, w as u32, (h * d) as u32)?;
    let view = push_view(root, bin, &png, None, None);
    let images = array_mut(root, "images");
    images.push(json!({
        "name": "penumbra irradiance volume",
        "bufferView": view,
        "mimeType": "image/png",
    }));
    let image = images.len() - 1;
    let round = |v: f64| (v as f32) as f64;
    let value = json!({
        "origin": probes.origin.to_array(),
        "spacing": probes.spacing,
        "counts": probes.counts,
        "order": "x fastest, then y, then z",
        "sh": probes.sh.iter().map(|c| c.iter().flat_map(|v| v.to_array().map(round)).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "cube": probes.cube.iter().map(|c| c.iter().flat_map(|v| v.to_array().map(round)).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "inside": probes.inside.iter().enumerate().filter(|(_, i)| **i).map(|(k, _)| k).collect::<Vec<_>>(),
        "irradiance_volume": {
            "image": image,
            "size": [w, h, d],
            "encoding": "srgb",
            "scale": scale,
        },
    });
    let obj = root.as_object_mut().expect("glTF root is an object");
    let extras = obj.entry("extras").or_insert_with(|| json!({}));
    if !extras.is_object() {
        return Err(Error::Output {
            what: "glb",
            reason: "the file's root `extras` is not an object, so the probes have no place in it"
                .into(),
        });
    }
    extras["penumbra_probes"] = value;
    Ok(())
}
