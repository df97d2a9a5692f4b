//! Pixel formats a GenTL buffer may carry (PFNC values) and their
//! conversion into the grey-value [`Image`] of a ring slot: Mono8 copied,
//! Mono10/12/14/16 widened into a 16-bit image whose saturation level is
//! the format's largest value, the packed variants (PFNC `Mono10p`,
//! `Mono12p`, bit-packed LSB first; GigE Vision `Mono10Packed`,
//! `Mono12Packed`, two pixels in three bytes) unpacked, and 8-bit colour
//! (`RGB8`, `BGR8`, `RGBa8`, `BGRa8`) turned into grey with the ITU-R
//! BT.601 luma weights in 1/256 (R 77, G 150, B 29; alpha ignored). Any
//! other format is refused, naming its PFNC value.
//!
//! One pass over the payload, no allocation unless the slot's image has
//! another size or depth.

use photopose_frame::{Image, Pixels};
use thiserror::Error;

/// A pixel format this source understands (PFNC values).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormat {
    /// `Mono8`, 0x01080001.
    Mono8,
    /// `Mono10`, 0x01100003 (16 bits a pixel, little-endian).
    Mono10,
    /// `Mono12`, 0x01100005.
    Mono12,
    /// `Mono14`, 0x01100025.
    Mono14,
    /// `Mono16`, 0x01100007.
    Mono16,
    /// `Mono10p`, 0x010A0046 (10 bits a pixel, packed LSB first).
    Mono10p,
    /// `Mono12p`, 0x010C0047 (12 bits a pixel, packed LSB first).
    Mono12p,
    /// `Mono10Packed` (GigE Vision), 0x010C0004: two pixels in three bytes.
    Mono10Packed,
    /// `Mono12Packed` (GigE Vision), 0x010C0006: two pixels in three bytes.
    Mono12Packed,
    /// `RGB8`, 0x02180014.
    Rgb8,
    /// `BGR8`, 0x02180015.
    Bgr8,
    /// `RGBa8`, 0x02200016.
    Rgba8,
    /// `BGRa8`, 0x02200017.
    Bgra8,
}

/// The PFNC values of [`PixelFormat`].
pub mod pfnc {
    /// `Mono8`.
    pub const MONO8: u64 = 0x0108_0001;
    /// `Mono10`.
    pub const MONO10: u64 = 0x0110_0003;
    /// `Mono12`.
    pub const MONO12: u64 = 0x0110_0005;
    /// `Mono14`.
    pub const MONO14: u64 = 0x0110_0025;
    /// `Mono16`.
    pub const MONO16: u64 = 0x0110_0007;
    /// `Mono10p`.
    pub const MONO10P: u64 = 0x010A_0046;
    /// `Mono12p`.
    pub const MONO12P: u64 = 0x010C_0047;
    /// `Mono10Packed` (GigE Vision).
    pub const MONO10_PACKED: u64 = 0x010C_0004;
    /// `Mono12Packed` (GigE Vision).
    pub const MONO12_PACKED: u64 = 0x010C_0006;
    /// `RGB8`.
    pub const RGB8: u64 = 0x0218_0014;
    /// `BGR8`.
    pub const BGR8: u64 = 0x0218_0015;
    /// `RGBa8`.
    pub const RGBA8: u64 = 0x0220_0016;
    /// `BGRa8`.
    pub const BGRA8: u64 = 0x0220_0017;
}

/// Why a payload could not become an image.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum ConvertError {
    /// A pixel format photopose does not convert.
    #[error("pixel format {pfnc:#010x} is not supported (Mono8/10/12/14/16, Mono10p/12p, Mono10Packed/12Packed, RGB8, BGR8, RGBa8, BGRa8 are)")]
    Unsupported {
        /// The PFNC value the producer gave.
        pfnc: u64,
    },
    /// The payload is shorter than its width, height and format need.
    #[error("payload of {got} bytes is shorter than the {need} bytes a {width}×{height} {} image needs", format.name())]
    Short {
        /// The format.
        format: PixelFormat,
        /// Width, pixels.
        width: u32,
        /// Height, pixels.
        height: u32,
        /// Bytes needed.
        need: usize,
        /// Bytes delivered.
        got: usize,
    },
    /// No pixels (width or height 0).
    #[error("empty image ({width}×{height})")]
    Empty {
        /// Width, pixels.
        width: u32,
        /// Height, pixels.
        height: u32,
    },
}

impl PixelFormat {
    /// The format's PFNC name (`Mono8`, `Mono12p`, `RGBa8` …).
    pub fn name(self) -> &'static str {
        use PixelFormat::*;
        match self {
            Mono8 => "Mono8",
            Mono10 => "Mono10",
            Mono12 => "Mono12",
            Mono14 => "Mono14",
            Mono16 => "Mono16",
            Mono10p => "Mono10p",
            Mono12p => "Mono12p",
            Mono10Packed => "Mono10Packed",
            Mono12Packed => "Mono12Packed",
            Rgb8 => "RGB8",
            Bgr8 => "BGR8",
            Rgba8 => "RGBa8",
            Bgra8 => "BGRa8",
        }
    }

    /// The format of a PFNC value, or `None` when not supported.
    pub fn from_pfnc(value: u64) -> Option<PixelFormat> {
        use PixelFormat::*;
        Some(match value {
            pfnc::MONO8 => Mono8,
            pfnc::MONO10 => Mono10,
            pfnc::MONO12 => Mono12,
            pfnc::MONO14 => Mono14,
            pfnc::MONO16 => Mono16,
            pfnc::MONO10P => Mono10p,
            pfnc::MONO12P => Mono12p,
            pfnc::MONO10_PACKED => Mono10Packed,
            pfnc::MONO12_PACKED => Mono12Packed,
            pfnc::RGB8 => Rgb8,
            pfnc::BGR8 => Bgr8,
            pfnc::RGBA8 => Rgba8,
            pfnc::BGRA8 => Bgra8,
            _ => return None,
        })
    }

    /// Bits a pixel takes in the payload.
    pub fn bits_per_pixel(self) -> usize {
        use PixelFormat::*;
        match self {
            Mono8 => 8,
            Mono10 | Mono12 | Mono14 | Mono16 => 16,
            Mono10p => 10,
            Mono12p | Mono10Packed | Mono12Packed => 12,
            Rgb8 | Bgr8 => 24,
            Rgba8 | Bgra8 => 32,
        }
    }

    /// The largest grey value of the converted image: 255 for 8-bit
    /// output, `2^bits − 1` for the deeper mono formats.
    pub fn max_value(self) -> u16 {
        use PixelFormat::*;
        match self {
            Mono8 | Rgb8 | Bgr8 | Rgba8 | Bgra8 => 255,
            Mono10 | Mono10p | Mono10Packed => 1023,
            Mono12 | Mono12p | Mono12Packed => 4095,
            Mono14 => 16383,
            Mono16 => u16::MAX,
        }
    }

    /// Whether the converted image is 8-bit.
    pub fn is_8bit(self) -> bool {
        self.max_value() == 255
    }

    /// Bytes one line takes in the payload (without padding), rounded up.
    pub fn line_bytes(self, width: u32) -> usize {
        (width as usize * self.bits_per_pixel()).div_ceil(8)
    }
}

/// Where the pixels are inside a payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Bytes of padding at the end of each line.
    pub x_padding: usize,
}

impl Layout {
    /// Bytes from one line's start to the next's, and the bytes the payload
    /// must hold.
    fn sizes(&self, format: PixelFormat) -> (usize, usize) {
        let line = format.line_bytes(self.width);
        let stride = line + self.x_padding;
        let need = if self.height == 0 {
            0
        } else {
            stride * (self.height as usize - 1) + line
        };
        (stride, need)
    }
}

/// Converts `payload` (pixels of `format` laid out as `layout`) into
/// `image`, replacing the image only if its size or depth differ; returns
/// whether it was replaced.
pub fn convert(
    format: PixelFormat,
    layout: Layout,
    payload: &[u8],
    image: &mut Image,
) -> Result<bool, ConvertError> {
    let Layout { width, height, .. } = layout;
    if width == 0 || height == 0 {
        return Err(ConvertError::Empty { width, height });
    }
    let (stride, need) = layout.sizes(format);
    if payload.len() < need {
        return Err(ConvertError::Short {
            format,
            width,
            height,
            need,
            got: payload.len(),
        });
    }
    let max = format.max_value();
    let fits = image.width() == width
        && image.height() == height
        && image.max_value() == max
        && matches!(
            (image.pixels(), format.is_8bit()),
            (Pixels::Mono8(_), true) | (Pixels::Mono16(_), false)
        );
    if !fits {
        *image = if format.is_8bit() {
            Image::new_mono8(width, height)
        } else {
            Image::new_mono16(width, height, max)
        };
    }
    let w = width as usize;
    let line_bytes = format.line_bytes(width);
    match image.pixels_mut() {
        Pixels::Mono8(dst) => {
            for (row, out) in dst.chunks_exact_mut(w).enumerate() {
                let line = &payload[row * stride..row * stride + line_bytes];
                grey8(format, line, out);
            }
        }
        Pixels::Mono16(dst) => {
            for (row, out) in dst.chunks_exact_mut(w).enumerate() {
                let start = row * stride;
                mono16(format, payload, start, out);
            }
        }
    }
    Ok(!fits)
}

/// One line of an 8-bit output format.
fn grey8(format: PixelFormat, line: &[u8], out: &mut [u8]) {
    // BT.601 luma in 1/256: 77 + 150 + 29 = 256, so white stays 255.
    let luma = |r: u8, g: u8, b: u8| {
        ((77 * u32::from(r) + 150 * u32::from(g) + 29 * u32::from(b) + 128) >> 8) as u8
    };
    match format {
        PixelFormat::Mono8 => out.copy_from_slice(line),
        PixelFormat::Rgb8 => {
            for (o, p) in out.iter_mut().zip(line.chunks_exact(3)) {
                *o = luma(p[0], p[1], p[2]);
            }
        }
        PixelFormat::Bgr8 => {
            for (o, p) in out.iter_mut().zip(line.chunks_exact(3)) {
                *o = luma(p[2], p[1], p[0]);
            }
        }
        PixelFormat::Rgba8 => {
            for (o, p) in out.iter_mut().zip(line.chunks_exact(4)) {
                *o = luma(p[0], p[1], p[2]);
            }
        }
        PixelFormat::Bgra8 => {
            for (o, p) in out.iter_mut().zip(line.chunks_exact(4)) {
                *o = luma(p[2], p[1], p[0]);
            }
        }
        // Deeper formats go through `mono16`.
        _ => {}
    }
}

/// One line of a 16-bit output format, starting at byte `start`.
fn mono16(format: PixelFormat, payload: &[u8], start: usize, out: &mut [u16]) {
    match format {
        PixelFormat::Mono10 | PixelFormat::Mono12 | PixelFormat::Mono14 | PixelFormat::Mono16 => {
            let max = format.max_value();
            let line = &payload[start..start + 2 * out.len()];
            for (o, p) in out.iter_mut().zip(line.chunks_exact(2)) {
                *o = u16::from_le_bytes([p[0], p[1]]).min(max);
            }
        }
        PixelFormat::Mono10p | PixelFormat::Mono12p => {
            let bits = format.bits_per_pixel();
            let mask = (1u32 << bits) - 1;
            for (col, o) in out.iter_mut().enumerate() {
                // LSB first: pixel `col` occupies bits [col·bits, col·bits + bits).
                let bit = col * bits;
                let byte = start + bit / 8;
                let b0 = u32::from(payload[byte]);
                let b1 = payload.get(byte + 1).copied().map_or(0, u32::from);
                let b2 = payload.get(byte + 2).copied().map_or(0, u32::from);
                let word = b0 | (b1 << 8) | (b2 << 16);
                *o = ((word >> (bit % 8)) & mask) as u16;
            }
        }
        PixelFormat::Mono10Packed | PixelFormat::Mono12Packed => {
            let ten = format == PixelFormat::Mono10Packed;
            for (col, o) in out.iter_mut().enumerate() {
                let group = start + 3 * (col / 2);
                let low_bits = payload[group + 1];
                let (high, low) = if col % 2 == 0 {
                    (payload[group], low_bits & 0x0F)
                } else {
                    (payload[group + 2], low_bits >> 4)
                };
                *o = if ten {
                    (u16::from(high) << 2) | u16::from(low & 0x03)
                } else {
                    (u16::from(high) << 4) | u16::from(low)
                };
            }
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout(width: u32, height: u32) -> Layout {
        Layout {
            width,
            height,
            x_padding: 0,
        }
    }

    fn mono16_of(image: &Image) -> Vec<u16> {
        match image.pixels() {
            Pixels::Mono16(v) => v.clone(),
            Pixels::Mono8(_) => panic!("16-bit image expected"),
        }
    }

    #[test]
    fn every_supported_pfnc_value_maps_back() {
        for v in [
            pfnc::MONO8,
            pfnc::MONO10,
            pfnc::MONO12,
            pfnc::MONO14,
            pfnc::MONO16,
            pfnc::MONO10P,
            pfnc::MONO12P,
            pfnc::MONO10_PACKED,
            pfnc::MONO12_PACKED,
            pfnc::RGB8,
            pfnc::BGR8,
            pfnc::RGBA8,
            pfnc::BGRA8,
        ] {
            let f = PixelFormat::from_pfnc(v).unwrap();
            // The PFNC value's bits 16..24 give the bits per pixel.
            assert_eq!(((v >> 16) & 0xFF) as usize, f.bits_per_pixel(), "{f:?}");
        }
        // BayerRG8 is refused.
        assert_eq!(PixelFormat::from_pfnc(0x0108_0009), None);
    }

    #[test]
    fn mono8_is_copied_and_padding_skipped() {
        let payload = [1, 2, 3, 99, 4, 5, 6];
        let mut image = Image::new_mono8(1, 1);
        let lay = Layout {
            width: 3,
            height: 2,
            x_padding: 1,
        };
        assert!(convert(PixelFormat::Mono8, lay, &payload, &mut image).unwrap());
        assert_eq!(image.pixels(), &Pixels::Mono8(vec![1, 2, 3, 4, 5, 6]));
        // Same size again: the image is kept.
        assert!(!convert(PixelFormat::Mono8, lay, &payload, &mut image).unwrap());
    }

    #[test]
    fn colour_becomes_grey_with_bt601_weights() {
        let mut image = Image::new_mono8(4, 1);
        // white, red, green, blue
        let rgba = [255, 255, 255, 0, 255, 0, 0, 7, 0, 255, 0, 7, 0, 0, 255, 7u8];
        convert(PixelFormat::Rgba8, layout(4, 1), &rgba, &mut image).unwrap();
        assert_eq!(image.pixels(), &Pixels::Mono8(vec![255, 77, 149, 29]));
        let bgr = [255, 0, 0, 0, 0, 255u8];
        let mut image = Image::new_mono8(2, 1);
        convert(PixelFormat::Bgr8, layout(2, 1), &bgr, &mut image).unwrap();
        assert_eq!(image.pixels(), &Pixels::Mono8(vec![29, 77]));
    }

    #[test]
    fn deep_mono_is_widened_with_its_saturation_level() {
        let mut image = Image::new_mono8(2, 1);
        let p = [0xFF, 0x03, 0x34, 0x12u8];
        convert(PixelFormat::Mono10, layout(2, 1), &p, &mut image).unwrap();
        assert_eq!(image.max_value(), 1023);
        // Out-of-range bits are clipped to the format's maximum.
        assert_eq!(mono16_of(&image), vec![1023, 1023]);
        convert(PixelFormat::Mono16, layout(2, 1), &p, &mut image).unwrap();
        assert_eq!(image.max_value(), u16::MAX);
        assert_eq!(mono16_of(&image), vec![0x03FF, 0x1234]);
    }

    #[test]
    fn packed_formats_unpack() {
        // Mono12p: pixels 0xABC, 0x123 → bytes BC, 3A, 12.
        let mut image = Image::new_mono8(1, 1);
        convert(
            PixelFormat::Mono12p,
            layout(2, 1),
            &[0xBC, 0x3A, 0x12],
            &mut image,
        )
        .unwrap();
        assert_eq!(mono16_of(&image), vec![0xABC, 0x123]);
        // Mono10p: pixels 1, 2, 3, 1023 → the 40-bit word
        // 1 | 2<<10 | 3<<20 | 1023<<30, little-endian.
        let word: u64 = 1 | (2 << 10) | (3 << 20) | (1023 << 30);
        let bytes = word.to_le_bytes();
        convert(PixelFormat::Mono10p, layout(4, 1), &bytes[..5], &mut image).unwrap();
        assert_eq!(mono16_of(&image), vec![1, 2, 3, 1023]);
        // Mono12Packed (GigE): 0xABC, 0x123 → AB, 3C (low nibbles), 12.
        convert(
            PixelFormat::Mono12Packed,
            layout(2, 1),
            &[0xAB, 0x3C, 0x12],
            &mut image,
        )
        .unwrap();
        assert_eq!(mono16_of(&image), vec![0xABC, 0x123]);
        // Mono10Packed (GigE): 0x2F1 (1011110001), 0x0E6 (0011100110)
        // → high bytes 0xBC, 0x39; low bits 01 and 10 → byte 0x21.
        convert(
            PixelFormat::Mono10Packed,
            layout(2, 1),
            &[0xBC, 0x21, 0x39],
            &mut image,
        )
        .unwrap();
        assert_eq!(mono16_of(&image), vec![0x2F1, 0x0E6]);
    }

    #[test]
    fn short_and_empty_payloads_are_errors_not_panics() {
        let mut image = Image::new_mono8(1, 1);
        let e = convert(PixelFormat::Rgba8, layout(4, 4), &[0; 63], &mut image).unwrap_err();
        assert!(
            matches!(
                e,
                ConvertError::Short {
                    need: 64,
                    got: 63,
                    ..
                }
            ),
            "{e}"
        );
        let e = convert(PixelFormat::Mono8, layout(0, 4), &[], &mut image).unwrap_err();
        assert!(matches!(e, ConvertError::Empty { .. }));
        let e = ConvertError::Unsupported { pfnc: 0x0108_0009 };
        assert!(e.to_string().contains("0x01080009"), "{e}");
    }
}
