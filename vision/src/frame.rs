//! Radiometric thermal frames (paper 003 Sec. 2.3, DESIGN §4 `thermal-sequence`).
//!
//! A frame is a 16-bit grayscale PNG of 160 × 120 px whose pixel value is the temperature
//! in kelvin × 100 (centi-kelvin), the radiometric output of a FLIR Lepton 3.5. Value 0
//! means "no reading" and becomes NaN. Decoding goes through kornia-io; every bad-frame
//! case (unreadable or truncated PNG, wrong size, wrong bit depth or channel count, no
//! valid pixel at all) is a typed [`FrameError`], never a panic, so one bad frame becomes
//! a diagnostic next to the results instead of aborting the sequence.

use std::path::Path;

use kornia_image::{ImageSize, PixelFormat};
use kornia_io::png::{decode_image_png_layout, decode_image_png_mono16, encode_image_png_gray16_slice};

/// Frame width of the Lepton 3.5 (pixels).
pub const LEPTON_WIDTH_PX: usize = 160;
/// Frame height of the Lepton 3.5 (pixels).
pub const LEPTON_HEIGHT_PX: usize = 120;
/// 0 °C in kelvin.
const ZERO_C_IN_K: f32 = 273.15;

/// Why a frame could not be used.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum FrameError {
    /// The bytes are not a decodable PNG (bad signature, truncated, corrupt data, I/O error).
    #[error("unreadable PNG: {0}")]
    Unreadable(String),
    /// The PNG decodes but has the wrong pixel dimensions.
    #[error("wrong size: expected {expected_width}×{expected_height}, found {found_width}×{found_height}")]
    WrongSize {
        /// Expected width (px).
        expected_width: usize,
        /// Expected height (px).
        expected_height: usize,
        /// Width found in the file (px).
        found_width: usize,
        /// Height found in the file (px).
        found_height: usize,
    },
    /// The PNG is not 16 bits per sample.
    #[error("wrong bit depth: expected 16-bit grayscale, found {found}")]
    WrongBitDepth {
        /// What the file holds, e.g. "8-bit" or "1/2/4-bit".
        found: String,
    },
    /// The PNG is not single-channel grayscale.
    #[error("wrong channel count: expected 1 (grayscale), found {found}")]
    WrongChannels {
        /// Number of channels in the file.
        found: u8,
    },
    /// Every pixel is 0 ("no reading"): the frame is all-NaN.
    #[error("all pixels invalid (all-NaN)")]
    AllInvalid,
    /// The pixel buffer does not match the stated dimensions.
    #[error("pixel buffer holds {found} values, expected {expected}")]
    BufferSize {
        /// width × height.
        expected: usize,
        /// Values supplied.
        found: usize,
    },
}

/// One thermal frame in °C, row-major, NaN where the camera gave no reading.
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalFrame {
    /// Width (columns, px).
    pub width: usize,
    /// Height (rows, px).
    pub height: usize,
    /// Temperature per pixel (°C), index `v * width + u`.
    pub temp_c: Vec<f32>,
}

impl ThermalFrame {
    /// A frame of the given size filled with `temp_c`.
    pub fn filled(width: usize, height: usize, temp_c: f32) -> Self {
        Self { width, height, temp_c: vec![temp_c; width * height] }
    }

    /// Decodes a Lepton 3.5 frame (160 × 120, 16-bit centi-kelvin) from PNG bytes.
    pub fn from_png_bytes(bytes: &[u8]) -> Result<Self, FrameError> {
        Self::from_png_bytes_sized(bytes, LEPTON_WIDTH_PX, LEPTON_HEIGHT_PX)
    }

    /// Decodes a 16-bit centi-kelvin PNG that must be `width` × `height`.
    pub fn from_png_bytes_sized(bytes: &[u8], width: usize, height: usize) -> Result<Self, FrameError> {
        check_layout(bytes, width, height)?;
        let size = ImageSize { width, height };
        let mut gray = kornia_image::color_spaces::Gray16::from_size_val(size, 0)
            .map_err(|e| FrameError::Unreadable(e.to_string()))?;
        decode_image_png_mono16(bytes, &mut gray).map_err(|e| FrameError::Unreadable(e.to_string()))?;
        Self::from_centikelvin(width, height, gray.0.as_slice())
    }

    /// Reads and decodes a Lepton 3.5 frame file (e.g. `frames/L03_F0042.png`).
    pub fn from_png_file(path: impl AsRef<Path>) -> Result<Self, FrameError> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| FrameError::Unreadable(format!("{}: {e}", path.display())))?;
        Self::from_png_bytes(&bytes)
    }

    /// Converts raw centi-kelvin values (0 = no reading) into a frame in °C.
    pub fn from_centikelvin(width: usize, height: usize, centi_k: &[u16]) -> Result<Self, FrameError> {
        if centi_k.len() != width * height {
            return Err(FrameError::BufferSize { expected: width * height, found: centi_k.len() });
        }
        if centi_k.iter().all(|&v| v == 0) {
            return Err(FrameError::AllInvalid);
        }
        let temp_c = centi_k.iter().map(|&v| centikelvin_to_c(v)).collect();
        Ok(Self { width, height, temp_c })
    }

    /// Temperature at integer pixel (u, v), NaN outside the frame.
    #[inline]
    pub fn at(&self, u: usize, v: usize) -> f32 {
        if u < self.width && v < self.height {
            self.temp_c[v * self.width + u]
        } else {
            f32::NAN
        }
    }

    /// Number of pixels with a reading.
    pub fn valid_count(&self) -> usize {
        self.temp_c.iter().filter(|t| t.is_finite()).count()
    }
}

/// Converts one centi-kelvin sample to °C (0 → NaN).
#[inline]
pub fn centikelvin_to_c(value: u16) -> f32 {
    if value == 0 {
        f32::NAN
    } else {
        value as f32 / 100.0 - ZERO_C_IN_K
    }
}

/// Converts °C to the nearest centi-kelvin sample (NaN → 0, clamped to the u16 range).
#[inline]
pub fn c_to_centikelvin(temp_c: f32) -> u16 {
    if temp_c.is_finite() {
        ((temp_c + ZERO_C_IN_K) * 100.0).round().clamp(1.0, u16::MAX as f32) as u16
    } else {
        0
    }
}

/// Encodes centi-kelvin samples as a 16-bit grayscale PNG (the frame file format).
pub fn encode_centikelvin_png(width: usize, height: usize, centi_k: &[u16]) -> Result<Vec<u8>, FrameError> {
    if centi_k.len() != width * height {
        return Err(FrameError::BufferSize { expected: width * height, found: centi_k.len() });
    }
    let mut out = Vec::new();
    encode_image_png_gray16_slice(centi_k, ImageSize { width, height }, &mut out, Some(1))
        .map_err(|e| FrameError::Unreadable(e.to_string()))?;
    Ok(out)
}

/// Checks size, bit depth and channel count from the PNG header before decoding.
fn check_layout(bytes: &[u8], width: usize, height: usize) -> Result<(), FrameError> {
    let layout = decode_image_png_layout(bytes).map_err(|e| {
        let msg = e.to_string();
        if msg.contains("bit depth") {
            FrameError::WrongBitDepth { found: "1/2/4-bit".into() }
        } else {
            FrameError::Unreadable(msg)
        }
    })?;
    let found = layout.image_size;
    if found.width != width || found.height != height {
        return Err(FrameError::WrongSize {
            expected_width: width,
            expected_height: height,
            found_width: found.width,
            found_height: found.height,
        });
    }
    if layout.pixel_format != PixelFormat::U16 {
        return Err(FrameError::WrongBitDepth { found: "8-bit".into() });
    }
    if layout.channels != 1 {
        return Err(FrameError::WrongChannels { found: layout.channels });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp_centikelvin() -> Vec<u16> {
        (0..LEPTON_WIDTH_PX * LEPTON_HEIGHT_PX).map(|i| 33_315 + (i % 1000) as u16).collect()
    }

    #[test]
    fn png_round_trip_recovers_temperatures_to_the_centikelvin() {
        let mut raw = ramp_centikelvin();
        raw[5] = 0; // one "no reading" pixel
        let png = encode_centikelvin_png(LEPTON_WIDTH_PX, LEPTON_HEIGHT_PX, &raw).unwrap();
        let frame = ThermalFrame::from_png_bytes(&png).unwrap();
        assert_eq!((frame.width, frame.height), (160, 120));
        assert!(frame.temp_c[5].is_nan());
        // 33315 cK = 333.15 K = 60 °C.
        assert!((frame.temp_c[0] - 60.0).abs() < 1e-3);
        for (i, (&t, &r)) in frame.temp_c.iter().zip(&raw).enumerate() {
            if r != 0 {
                assert_eq!(c_to_centikelvin(t), r, "pixel {i}");
            }
        }
    }

    #[test]
    fn truncated_png_is_unreadable_not_a_panic() {
        let png = encode_centikelvin_png(LEPTON_WIDTH_PX, LEPTON_HEIGHT_PX, &ramp_centikelvin()).unwrap();
        for cut in [0, 8, 30, png.len() / 2, png.len() - 13] {
            let err = ThermalFrame::from_png_bytes(&png[..cut]).unwrap_err();
            assert!(matches!(err, FrameError::Unreadable(_)), "cut {cut}: {err:?}");
        }
        assert!(matches!(ThermalFrame::from_png_bytes(b"not a png"), Err(FrameError::Unreadable(_))));
    }

    #[test]
    fn wrong_size_names_both_sizes() {
        let png = encode_centikelvin_png(80, 60, &vec![30_000; 80 * 60]).unwrap();
        let err = ThermalFrame::from_png_bytes(&png).unwrap_err();
        assert_eq!(
            err,
            FrameError::WrongSize { expected_width: 160, expected_height: 120, found_width: 80, found_height: 60 }
        );
        assert!(err.to_string().contains("expected 160×120, found 80×60"));
    }

    #[test]
    fn eight_bit_png_is_wrong_bit_depth() {
        let size = ImageSize { width: 160, height: 120 };
        let img = kornia_image::Image::<u8, 1>::from_size_val(size, 7).unwrap();
        let mut png = Vec::new();
        kornia_io::png::encode_image_png_gray8(&img, &mut png, None).unwrap();
        assert!(matches!(ThermalFrame::from_png_bytes(&png), Err(FrameError::WrongBitDepth { .. })));
    }

    #[test]
    fn rgb16_png_is_wrong_channel_count() {
        let size = ImageSize { width: 160, height: 120 };
        let img = kornia_image::Image::<u16, 3>::from_size_val(size, 30_000).unwrap();
        let mut png = Vec::new();
        kornia_io::png::encode_image_png_rgb16(&img, &mut png, None).unwrap();
        assert_eq!(ThermalFrame::from_png_bytes(&png), Err(FrameError::WrongChannels { found: 3 }));
    }

    #[test]
    fn all_zero_frame_is_all_nan() {
        let png = encode_centikelvin_png(160, 120, &vec![0; 160 * 120]).unwrap();
        assert_eq!(ThermalFrame::from_png_bytes(&png), Err(FrameError::AllInvalid));
    }

    #[test]
    fn missing_file_is_unreadable() {
        let err = ThermalFrame::from_png_file("/nonexistent/frames/L00_F0000.png").unwrap_err();
        assert!(matches!(err, FrameError::Unreadable(m) if m.contains("L00_F0000.png")));
    }
}
