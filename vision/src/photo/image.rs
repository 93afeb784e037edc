//! A colour photo in linear-scale 0..1 floats, decoded from JPEG or PNG by the `image`
//! crate (8- or 16-bit, grey, grey+alpha, RGB or RGBA; grey becomes three equal channels,
//! alpha is ignored). The header is read first and the size checked against the caller's
//! pixel limit before any pixel buffer is allocated; a truncated or corrupt file is
//! [`PhotoError::Unreadable`], never a panic. The JPEG decoder fills a truncated file's
//! missing rows without a word (measured: a photo cut to a third decoded as a whole), so a
//! JPEG must hold an end-of-image marker (FF D9) after its last start-of-scan (FF DA);
//! an EXIF thumbnail's markers come before the main image's scans.

use std::io::Cursor;

use super::PhotoError;

/// A colour image, row-major (index `row * width + column`), channels R, G, B in 0..1.
#[derive(Debug, Clone, PartialEq)]
pub struct ColourImage {
    /// Columns (px).
    pub width: usize,
    /// Rows (px).
    pub height: usize,
    /// R, G, B per pixel.
    pub pixels: Vec<[f32; 3]>,
}

impl ColourImage {
    /// An image from its pixels; the buffer must hold `width × height` values.
    pub fn new(width: usize, height: usize, pixels: Vec<[f32; 3]>) -> Result<Self, PhotoError> {
        if width < 8 || height < 8 || width.checked_mul(height) != Some(pixels.len()) {
            return Err(PhotoError::BadImage(format!(
                "{width}×{height} px with {} values: expected at least 8 × 8 px and one value per pixel",
                pixels.len()
            )));
        }
        Ok(Self { width, height, pixels })
    }

    /// Decodes a JPEG or PNG of at most `max_pixels` pixels.
    pub fn decode(bytes: &[u8], max_pixels: usize) -> Result<Self, PhotoError> {
        let unreadable = |e: image::ImageError| PhotoError::Unreadable(e.to_string());
        let reader = image::ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| PhotoError::Unreadable(e.to_string()))?;
        let is_jpeg = reader.format() == Some(image::ImageFormat::Jpeg);
        let (width, height) = reader.into_dimensions().map_err(unreadable)?;
        if is_jpeg && !jpeg_is_complete(bytes) {
            return Err(PhotoError::Unreadable("truncated JPEG: no end-of-image marker after the last scan".into()));
        }
        let (width, height) = (width as usize, height as usize);
        if width.checked_mul(height).is_none_or(|n| n > max_pixels) {
            return Err(PhotoError::TooLarge { width, height, max_pixels });
        }
        let mut reader = image::ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| PhotoError::Unreadable(e.to_string()))?;
        let mut limits = image::Limits::default();
        limits.max_alloc = Some((max_pixels as u64).saturating_mul(32));
        reader.limits(limits);
        let rgb = reader.decode().map_err(unreadable)?.into_rgb32f();
        let pixels = rgb.pixels().map(|p| p.0).collect();
        Self::new(width, height, pixels)
    }

    /// R, G, B at pixel (column `i`, row `j`).
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> [f32; 3] {
        self.pixels[j * self.width + i]
    }
}

/// Whether a JPEG's last scan (FF DA) is followed by an end-of-image marker (FF D9).
fn jpeg_is_complete(bytes: &[u8]) -> bool {
    let last = |marker: u8| bytes.windows(2).rposition(|w| w[0] == 0xFF && w[1] == marker);
    match (last(0xDA), last(0xD9)) {
        (Some(scan), Some(end)) => end > scan,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encoded(format: image::ImageFormat) -> Vec<u8> {
        let img = image::RgbImage::from_fn(16, 12, |x, y| image::Rgb([(x * 10) as u8, (y * 20) as u8, 200]));
        let mut bytes = Vec::new();
        img.write_to(&mut Cursor::new(&mut bytes), format).unwrap();
        bytes
    }

    #[test]
    fn png_decodes_exactly_and_jpeg_closely() {
        let png = ColourImage::decode(&encoded(image::ImageFormat::Png), 1000).unwrap();
        assert_eq!((png.width, png.height), (16, 12));
        assert_eq!(png.at(3, 2), [30.0 / 255.0, 40.0 / 255.0, 200.0 / 255.0]);
        let jpeg = ColourImage::decode(&encoded(image::ImageFormat::Jpeg), 1000).unwrap();
        let [r, g, b] = jpeg.at(8, 6);
        assert!(
            (r - 80.0 / 255.0).abs() < 0.06 && (g - 120.0 / 255.0).abs() < 0.06 && (b - 200.0 / 255.0).abs() < 0.06
        );
    }

    #[test]
    fn oversized_and_truncated_files_are_refused() {
        let png = encoded(image::ImageFormat::Png);
        assert!(matches!(ColourImage::decode(&png, 100), Err(PhotoError::TooLarge { width: 16, height: 12, .. })));
        let jpeg = encoded(image::ImageFormat::Jpeg);
        assert!(matches!(ColourImage::decode(&jpeg[..jpeg.len() / 2], 1000), Err(PhotoError::Unreadable(_))));
        // cut just before its end-of-image marker, the decoder alone would accept it
        assert!(
            matches!(ColourImage::decode(&jpeg[..jpeg.len() - 2], 1000), Err(PhotoError::Unreadable(e)) if e.contains("truncated JPEG"))
        );
        assert!(matches!(ColourImage::decode(b"not an image", 1000), Err(PhotoError::Unreadable(_))));
    }
}
