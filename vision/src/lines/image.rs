//! A gray photo in linear 0..1 floats, decoded from an 8- or 16-bit PNG through kornia-io.
//!
//! The header is read first (kornia-io's `decode_image_png_layout`) and its size checked
//! against the caller's pixel limit before any pixel buffer is allocated. Grayscale PNGs
//! decode directly; RGB and RGBA become Rec. 601 luma (alpha ignored). Palette and
//! gray+alpha PNGs, 1/2/4-bit depths, truncated or corrupt data are [`LineError::Unreadable`],
//! never a panic.

use kornia_image::{ImageSize, PixelFormat};
use kornia_io::png::{
    decode_image_png_layout, decode_image_png_mono16, decode_image_png_mono8, decode_image_png_rgb16,
    decode_image_png_rgb8, decode_image_png_rgba16, decode_image_png_rgba8,
};

use super::errors::LineError;

/// Colour type byte of a PNG IHDR chunk for palette images.
const PNG_COLOUR_PALETTE: u8 = 3;
/// Offset of the colour type byte in a PNG file (signature 8, length 4, "IHDR" 4, w/h 8, depth 1).
const PNG_COLOUR_TYPE_OFFSET: usize = 25;
/// Rec. 601 luma weights of R, G, B.
const LUMA: [f32; 3] = [0.299, 0.587, 0.114];

/// A gray image, row-major, values in 0..1 (index `row * width + column`).
#[derive(Debug, Clone, PartialEq)]
pub struct GrayImage {
    /// Columns (px).
    pub width: usize,
    /// Rows (px).
    pub height: usize,
    /// Intensity per pixel, 0 (black) to 1 (full scale of the file's bit depth).
    pub pixels: Vec<f32>,
}

impl GrayImage {
    /// An image from its pixels; the buffer must hold `width × height` values.
    pub fn new(width: usize, height: usize, pixels: Vec<f32>) -> Result<Self, LineError> {
        let image = Self { width, height, pixels };
        image.check_buffer()?;
        Ok(image)
    }

    /// Decodes an 8- or 16-bit gray (or RGB/RGBA, as luma) PNG of at most `max_pixels` pixels.
    pub fn from_png_bytes(bytes: &[u8], max_pixels: usize) -> Result<Self, LineError> {
        let layout = decode_image_png_layout(bytes).map_err(|e| LineError::Unreadable(e.to_string()))?;
        let (width, height) = (layout.image_size.width, layout.image_size.height);
        if width.checked_mul(height).is_none_or(|n| n > max_pixels) {
            return Err(LineError::TooLarge { width, height, max_pixels });
        }
        if bytes.get(PNG_COLOUR_TYPE_OFFSET) == Some(&PNG_COLOUR_PALETTE) {
            return Err(LineError::Unreadable("palette PNG: save the photo as 8- or 16-bit grayscale".into()));
        }
        let size = layout.image_size;
        let pixels = match (layout.pixel_format, layout.channels) {
            (PixelFormat::U8, 1) => decode_gray8(bytes, size)?,
            (PixelFormat::U16, 1) => decode_gray16(bytes, size)?,
            (PixelFormat::U8, 3) => luma(&decode_rgb8_samples(bytes, size)?, 3),
            (PixelFormat::U16, 3) => luma(&decode_rgb16_samples(bytes, size)?, 3),
            (PixelFormat::U8, 4) => luma(&decode_rgba8_samples(bytes, size)?, 4),
            (PixelFormat::U16, 4) => luma(&decode_rgba16_samples(bytes, size)?, 4),
            (format, channels) => {
                return Err(LineError::Unreadable(format!(
                    "unsupported PNG layout ({channels} channels, {format:?}): save as 8- or 16-bit grayscale"
                )))
            }
        };
        Self::new(width, height, pixels)
    }

    /// Intensity at pixel (column `i`, row `j`); the caller keeps `i`, `j` inside.
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> f32 {
        self.pixels[j * self.width + i]
    }

    /// Checks that the buffer matches the size.
    pub(crate) fn check_buffer(&self) -> Result<(), LineError> {
        if self.width.checked_mul(self.height) != Some(self.pixels.len()) {
            return Err(self.bad("the pixel buffer does not hold width × height values"));
        }
        Ok(())
    }

    /// A [`LineError::BadImage`] about this image.
    pub(crate) fn bad(&self, reason: &str) -> LineError {
        LineError::BadImage {
            width: self.width,
            height: self.height,
            pixels: self.pixels.len(),
            reason: reason.to_string(),
        }
    }
}

fn unreadable(e: impl std::fmt::Display) -> LineError {
    LineError::Unreadable(e.to_string())
}

/// Decodes into kornia's colour-space image `$space` and scales its samples to 0..1.
macro_rules! decode_as {
    ($name:ident, $space:ident, $decode:ident, $full_scale:expr) => {
        fn $name(bytes: &[u8], size: ImageSize) -> Result<Vec<f32>, LineError> {
            let mut img = kornia_image::color_spaces::$space::from_size_val(size, 0).map_err(unreadable)?;
            $decode(bytes, &mut img).map_err(unreadable)?;
            Ok(img.0.as_slice().iter().map(|&v| f32::from(v) / $full_scale).collect())
        }
    };
}

decode_as!(decode_gray8, Gray8, decode_image_png_mono8, 255.0);
decode_as!(decode_gray16, Gray16, decode_image_png_mono16, 65535.0);
decode_as!(decode_rgb8_samples, Rgb8, decode_image_png_rgb8, 255.0);
decode_as!(decode_rgb16_samples, Rgb16, decode_image_png_rgb16, 65535.0);
decode_as!(decode_rgba8_samples, Rgba8, decode_image_png_rgba8, 255.0);
decode_as!(decode_rgba16_samples, Rgba16, decode_image_png_rgba16, 65535.0);

/// Rec. 601 luma of interleaved samples with `channels` per pixel (R, G, B first).
fn luma(samples: &[f32], channels: usize) -> Vec<f32> {
    samples.chunks_exact(channels).map(|px| LUMA[0] * px[0] + LUMA[1] * px[1] + LUMA[2] * px[2]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gray8_png(width: usize, height: usize, value: u8) -> Vec<u8> {
        let img = kornia_image::Image::<u8, 1>::from_size_val(ImageSize { width, height }, value).unwrap();
        let mut png = Vec::new();
        kornia_io::png::encode_image_png_gray8(&img, &mut png, None).unwrap();
        png
    }

    #[test]
    fn eight_and_sixteen_bit_gray_scale_to_unit_range() {
        let img = GrayImage::from_png_bytes(&gray8_png(5, 3, 51), 100).unwrap();
        assert_eq!((img.width, img.height), (5, 3));
        assert!(img.pixels.iter().all(|&v| (v - 0.2).abs() < 1e-6), "51/255 = 0.2");
        let mut png = Vec::new();
        kornia_io::png::encode_image_png_gray16_slice(&[13107; 6], ImageSize { width: 3, height: 2 }, &mut png, None)
            .unwrap();
        let img = GrayImage::from_png_bytes(&png, 100).unwrap();
        assert!(img.pixels.iter().all(|&v| (v - 0.2).abs() < 1e-6), "13107/65535 = 0.2");
    }

    #[test]
    fn rgb_becomes_luma() {
        let mut img = kornia_image::Image::<u8, 3>::from_size_val(ImageSize { width: 2, height: 2 }, 0).unwrap();
        for px in img.as_slice_mut().chunks_exact_mut(3) {
            px.copy_from_slice(&[255, 0, 0]);
        }
        let mut png = Vec::new();
        kornia_io::png::encode_image_png_rgb8(&img, &mut png, None).unwrap();
        let gray = GrayImage::from_png_bytes(&png, 100).unwrap();
        assert!(gray.pixels.iter().all(|&v| (v - 0.299).abs() < 1e-6), "pure red has luma 0.299");
    }

    #[test]
    fn size_is_checked_against_the_limit_before_decoding() {
        let err = GrayImage::from_png_bytes(&gray8_png(40, 30, 9), 1199).unwrap_err();
        assert_eq!(err, LineError::TooLarge { width: 40, height: 30, max_pixels: 1199 });
        assert!(GrayImage::from_png_bytes(&gray8_png(40, 30, 9), 1200).is_ok());
    }

    #[test]
    fn truncated_and_garbage_bytes_are_unreadable() {
        let png = gray8_png(64, 48, 100);
        for cut in [0, 7, 20, 33, png.len() / 2, png.len() - 13] {
            let err = GrayImage::from_png_bytes(&png[..cut], 1 << 20).unwrap_err();
            assert!(matches!(err, LineError::Unreadable(_)), "cut at {cut}: {err:?}");
        }
        assert!(matches!(GrayImage::from_png_bytes(b"GIF89a....", 1 << 20), Err(LineError::Unreadable(_))));
    }

    #[test]
    fn a_buffer_of_the_wrong_length_is_a_bad_image() {
        assert!(matches!(GrayImage::new(3, 3, vec![0.0; 8]), Err(LineError::BadImage { .. })));
    }
}
