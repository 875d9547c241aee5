//! The images a bake writes: 8-bit PNG pages and float OpenEXR pages.

use crate::error::{Error, Result};

/// Encodes 8-bit RGB as PNG.
pub(crate) fn png_bytes(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>> {
    encode_png(rgb, width, height, image::ExtendedColorType::Rgb8)
}

/// Encodes 8-bit grey texels (row-major, `width x height`) as PNG.
pub(crate) fn grey_png_bytes(grey: &[u8], width: u32, height: u32) -> Result<Vec<u8>> {
    encode_png(grey, width, height, image::ExtendedColorType::L8)
}

fn encode_png(
    texels: &[u8],
    width: u32,
    height: u32,
    kind: image::ExtendedColorType,
) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(texels, width, height, kind)
        .map_err(|e| Error::Image(format!("PNG encoding failed: {e}")))?;
    Ok(png)
}

/// Encodes float RGB texels (row-major, `width x height`) as OpenEXR.
pub fn exr_bytes(texels: &[glam::DVec3], width: u32, height: u32) -> Result<Vec<u8>> {
    let data: Vec<f32> = texels.iter().flat_map(|t| t.as_vec3().to_array()).collect();
    let img = image::Rgb32FImage::from_raw(width, height, data)
        .ok_or_else(|| Error::Image("EXR image size mismatch".into()))?;
    let mut bytes = std::io::Cursor::new(Vec::new());
    image::DynamicImage::ImageRgb32F(img)
        .write_to(&mut bytes, image::ImageFormat::OpenExr)
        .map_err(|e| Error::Image(format!("EXR encoding failed: {e}")))?;
    Ok(bytes.into_inner())
}
