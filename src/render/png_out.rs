//! PNG encoding of rendered images.

use super::{RenderError, RgbImage};

/// Encodes `image` as an 8-bit RGB PNG.
pub fn encode_png(image: &RgbImage) -> Result<Vec<u8>, RenderError> {
    let expected = 3 * image.width as usize * image.height as usize;
    if image.pixels.len() != expected {
        return Err(RenderError::Png(format!(
            "{} bytes for a {}×{} RGB image (expected {expected})",
            image.pixels.len(),
            image.width,
            image.height
        )));
    }
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, image.width, image.height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::High);
    let mut writer = encoder
        .write_header()
        .map_err(|e| RenderError::Png(e.to_string()))?;
    writer
        .write_image_data(&image.pixels)
        .map_err(|e| RenderError::Png(e.to_string()))?;
    writer
        .finish()
        .map_err(|e| RenderError::Png(e.to_string()))?;
    Ok(out)
}
