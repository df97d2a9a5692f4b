//! Grey-value image files: binary PGM (`P5`, 8- and 16-bit) and PNG
//! (greyscale, 1–16 bit), read into and written from the shared
//! [`photopose_frame::Image`].
//!
//! - **PGM**: the header's `maxval` becomes [`Image::max_value`] and is written
//!   back as such; `maxval < 256` means one byte a sample (an 8-bit image),
//!   otherwise two bytes, big-endian (a 16-bit image). Comments in the header
//!   are skipped; bytes after the raster (a second image) are ignored.
//! - **PNG**: only the greyscale colour type (with bit depths below 8
//!   expanded to 8-bit); colour, palette and alpha images are refused. PNG has
//!   no `maxval`: the writer stores a 16-bit image's saturation level in a
//!   `tEXt` chunk with the keyword `max_value`, which the reader honours
//!   (default: the bit depth's full range). Samples are never rescaled.
//!
//! Files are recognised by their content when read and chosen by their
//! extension (`.pgm`, `.png`, any case) when written. Every error names the
//! file and what is wrong with it.
//!
//! Reading is bounded: the file is read with a size limit ([`crate::file`]),
//! and the width × height its header declares is checked against the
//! camera's sensor (or [`ImageLimits::Any`]'s hard maximum) before a pixel
//! is allocated or decoded, so a tiny file declaring a huge image costs
//! nothing.

use crate::file::{read_bytes_limited, FileKind};
use crate::FormatError;
use photopose_frame::{Image, Pixels};
use photopose_geometry::Camera;
use std::path::Path;

/// The image file types.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    /// Binary portable grey map (`P5`).
    Pgm,
    /// Portable network graphics, greyscale.
    Png,
}

const PNG_MAGIC: &[u8] = b"\x89PNG\r\n\x1a\n";
/// `tEXt` keyword carrying a PNG's saturation level.
const MAX_VALUE_KEY: &str = "max_value";

impl ImageFormat {
    /// The format a path's extension asks for (`.pgm`, `.png`, any case).
    pub fn from_path(path: &Path) -> Result<Self, FormatError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("pgm") => Ok(ImageFormat::Pgm),
            Some("png") => Ok(ImageFormat::Png),
            other => Err(FormatError::UnsupportedImage {
                origin: path.display().to_string(),
                what: format!(
                    "extension {} (use .pgm or .png)",
                    other.map_or("<none>".to_string(), |e| format!(".{e}"))
                ),
            }),
        }
    }

    /// The format of a file's content, from its first bytes.
    pub fn sniff(bytes: &[u8], origin: &str) -> Result<Self, FormatError> {
        let unsupported = |what: &str| {
            Err(FormatError::UnsupportedImage {
                origin: origin.into(),
                what: what.into(),
            })
        };
        if bytes.starts_with(b"P5") {
            Ok(ImageFormat::Pgm)
        } else if bytes.starts_with(PNG_MAGIC) {
            Ok(ImageFormat::Png)
        } else if bytes.starts_with(b"P2") {
            unsupported("plain (ASCII) PGM `P2`; only binary PGM `P5` is read")
        } else if bytes.starts_with(b"P3") || bytes.starts_with(b"P6") {
            unsupported("a colour PPM; grey images only (PGM `P5` or greyscale PNG)")
        } else if bytes.starts_with(b"P1") || bytes.starts_with(b"P4") {
            unsupported("a bitmap PBM; grey images only (PGM `P5` or greyscale PNG)")
        } else if bytes.len() < 2 || PNG_MAGIC.starts_with(bytes) {
            Err(FormatError::Truncated {
                origin: origin.into(),
                what: "the file signature".into(),
                expected: if bytes.starts_with(b"\x89") { 8 } else { 2 },
                found: bytes.len(),
            })
        } else {
            unsupported("neither a PGM (`P5`) nor a PNG file")
        }
    }
}

/// The largest image side read without a camera, px (a camera file's
/// largest sensor side).
pub const MAX_IMAGE_SIDE: u32 = 65_535;
/// The most pixels an image read without a camera may have (256 Mpx:
/// 512 MiB of 16-bit samples).
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// What an image file may declare, checked against its header before any
/// pixel is allocated or decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageLimits {
    /// Exactly the camera's sensor size.
    Sensor {
        /// Sensor width, px.
        width: u32,
        /// Sensor height, px.
        height: u32,
    },
    /// Any size up to [`MAX_IMAGE_SIDE`] per side and [`MAX_IMAGE_PIXELS`].
    Any,
}

impl ImageLimits {
    /// The camera's sensor size.
    pub fn of(camera: &Camera) -> Self {
        ImageLimits::Sensor {
            width: camera.sensor.width,
            height: camera.sensor.height,
        }
    }

    /// The largest image file read under these limits, bytes: twice the
    /// 16-bit raster (room for any sane PNG) plus 1 MiB of headers, at most
    /// the image kind's limit.
    pub fn file_limit(self) -> u64 {
        let kind = FileKind::Image.limit();
        match self {
            ImageLimits::Sensor { width, height } => (4 * width as u64 * height as u64)
                .saturating_add(1 << 20)
                .min(kind),
            ImageLimits::Any => kind,
        }
    }

    /// Checks a header's declared size; the error names the file.
    pub fn check(self, width: u32, height: u32, origin: &str) -> Result<(), FormatError> {
        match self {
            ImageLimits::Sensor {
                width: camera_width,
                height: camera_height,
            } if (width, height) != (camera_width, camera_height) => Err(FormatError::ImageSize {
                origin: origin.into(),
                width,
                height,
                camera_width,
                camera_height,
            }),
            ImageLimits::Any
                if width > MAX_IMAGE_SIDE
                    || height > MAX_IMAGE_SIDE
                    || width as u64 * height as u64 > MAX_IMAGE_PIXELS =>
            {
                Err(FormatError::ImageHeader {
                    origin: origin.into(),
                    what: format!(
                        "{width}×{height} is larger than an image is read \
                         ({MAX_IMAGE_SIDE} px per side, {MAX_IMAGE_PIXELS} pixels at most)"
                    ),
                })
            }
            _ => Ok(()),
        }
    }
}

/// Reads an image file (PGM or PNG, recognised by content) of any size up
/// to [`ImageLimits::Any`].
pub fn load_image(path: &Path) -> Result<Image, FormatError> {
    load_with(path, ImageLimits::Any)
}

/// Reads an image file for `camera`: the file is refused when larger than
/// the sensor's image can be, and the header's width × height must be the
/// sensor's before any pixel is decoded.
pub fn load_image_for(path: &Path, camera: &Camera) -> Result<Image, FormatError> {
    load_with(path, ImageLimits::of(camera))
}

fn load_with(path: &Path, limits: ImageLimits) -> Result<Image, FormatError> {
    let bytes = read_bytes_limited(path, FileKind::Image, limits.file_limit())?;
    decode_image_for(&bytes, &path.display().to_string(), limits)
}

/// Reads many image files of one camera with reused buffers: the file's
/// bytes go into one buffer kept from file to file, and a PGM's raster into
/// the pixel buffer of an image handed back with [`ImageReader::recycle`],
/// so that a batch of frames costs no fresh pages per frame. The checks
/// and errors are those of [`load_image_for`].
#[derive(Debug)]
pub struct ImageReader {
    limits: ImageLimits,
    bytes: Vec<u8>,
    spare: Option<Pixels>,
}

impl ImageReader {
    /// A reader for images of `camera`'s sensor size.
    pub fn for_camera(camera: &Camera) -> Self {
        ImageReader {
            limits: ImageLimits::of(camera),
            bytes: Vec::new(),
            spare: None,
        }
    }

    /// Reads an image file (as [`load_image_for`] does).
    pub fn load(&mut self, path: &Path) -> Result<Image, FormatError> {
        crate::file::read_bytes_into(
            path,
            FileKind::Image,
            self.limits.file_limit(),
            &mut self.bytes,
        )?;
        let origin = path.display().to_string();
        match ImageFormat::sniff(&self.bytes, &origin)? {
            ImageFormat::Pgm => pgm_into(&self.bytes, &origin, self.limits, self.spare.take()),
            ImageFormat::Png => png_with(&self.bytes, &origin, self.limits),
        }
    }

    /// Hands an image's pixel buffer back for the next file.
    pub fn recycle(&mut self, image: Image) {
        self.spare = Some(image.into_pixels());
    }
}

/// Writes an image file, PGM or PNG by the path's extension.
pub fn save_image(path: &Path, image: &Image) -> Result<(), FormatError> {
    let name = path.display().to_string();
    let mut bytes = Vec::new();
    match ImageFormat::from_path(path)? {
        ImageFormat::Pgm => encode_pgm(image, &name, &mut bytes)?,
        ImageFormat::Png => encode_png(image, &name, &mut bytes)?,
    }
    std::fs::write(path, &bytes).map_err(|source| FormatError::Write { path: name, source })
}

/// Decodes PGM or PNG bytes of any size up to [`ImageLimits::Any`];
/// `origin` names the file in errors.
pub fn decode_image(bytes: &[u8], origin: &str) -> Result<Image, FormatError> {
    decode_image_for(bytes, origin, ImageLimits::Any)
}

/// Decodes PGM or PNG bytes whose header must pass `limits` (checked before
/// any pixel is allocated); `origin` names the file in errors.
pub fn decode_image_for(
    bytes: &[u8],
    origin: &str,
    limits: ImageLimits,
) -> Result<Image, FormatError> {
    match ImageFormat::sniff(bytes, origin)? {
        ImageFormat::Pgm => pgm_with(bytes, origin, limits),
        ImageFormat::Png => png_with(bytes, origin, limits),
    }
}

/// Checks that an image has the camera's sensor size.
pub fn check_size(image: &Image, camera: &Camera, origin: &str) -> Result<(), FormatError> {
    let (w, h) = (camera.sensor.width, camera.sensor.height);
    if (image.width(), image.height()) == (w, h) {
        Ok(())
    } else {
        Err(FormatError::ImageSize {
            origin: origin.into(),
            width: image.width(),
            height: image.height(),
            camera_width: w,
            camera_height: h,
        })
    }
}

/// Cursor over a PGM header.
struct Header<'a> {
    bytes: &'a [u8],
    at: usize,
    origin: &'a str,
}

impl Header<'_> {
    fn truncated(&self, what: &str) -> FormatError {
        FormatError::Truncated {
            origin: self.origin.into(),
            what: format!("the PGM header ({what})"),
            expected: self.bytes.len() + 1,
            found: self.bytes.len(),
        }
    }

    fn header(&self, what: String) -> FormatError {
        FormatError::ImageHeader {
            origin: self.origin.into(),
            what,
        }
    }

    /// Skips whitespace and `#` comments.
    fn skip_space(&mut self) {
        while self.at < self.bytes.len() {
            match self.bytes[self.at] {
                b' ' | b'\t' | b'\n' | b'\r' | 0x0b | 0x0c => self.at += 1,
                b'#' => {
                    while self.at < self.bytes.len()
                        && self.bytes[self.at] != b'\n'
                        && self.bytes[self.at] != b'\r'
                    {
                        self.at += 1;
                    }
                }
                _ => break,
            }
        }
    }

    /// A decimal number in `1..=max`.
    fn number(&mut self, name: &str, max: u64) -> Result<u64, FormatError> {
        self.skip_space();
        let start = self.at;
        while self.at < self.bytes.len() && self.bytes[self.at].is_ascii_digit() {
            self.at += 1;
        }
        if start == self.at {
            if self.at == self.bytes.len() {
                return Err(self.truncated(name));
            }
            let c = self.bytes[self.at];
            return Err(self.header(format!(
                "{name}: expected a decimal number, found {}",
                if c.is_ascii_graphic() {
                    format!("`{}`", c as char)
                } else {
                    format!("byte 0x{c:02x}")
                }
            )));
        }
        let text = std::str::from_utf8(&self.bytes[start..self.at]).unwrap_or("");
        match text.parse::<u64>() {
            Ok(v) if (1..=max).contains(&v) => Ok(v),
            _ => Err(self.header(format!("{name} = {text} is not in 1..={max}"))),
        }
    }
}

/// Decodes a binary PGM (`P5`) of any size up to [`ImageLimits::Any`].
pub fn decode_pgm(bytes: &[u8], origin: &str) -> Result<Image, FormatError> {
    pgm_with(bytes, origin, ImageLimits::Any)
}

fn pgm_with(bytes: &[u8], origin: &str, limits: ImageLimits) -> Result<Image, FormatError> {
    pgm_into(bytes, origin, limits, None)
}

/// [`pgm_with`] into the buffer of an earlier image (`reuse`) when there
/// is one: one copy of the raster into memory that is already mapped.
fn pgm_into(
    bytes: &[u8],
    origin: &str,
    limits: ImageLimits,
    reuse: Option<Pixels>,
) -> Result<Image, FormatError> {
    if !bytes.starts_with(b"P5") {
        return ImageFormat::sniff(bytes, origin).and(Err(FormatError::UnsupportedImage {
            origin: origin.into(),
            what: "not a binary PGM (`P5`)".into(),
        }));
    }
    let mut h = Header {
        bytes,
        at: 2,
        origin,
    };
    if h.at < bytes.len() && !bytes[h.at].is_ascii_whitespace() && bytes[h.at] != b'#' {
        return Err(h.header("the magic `P5` is not followed by whitespace".into()));
    }
    let width = h.number("width", u32::MAX as u64)? as u32;
    let height = h.number("height", u32::MAX as u64)? as u32;
    let maxval = h.number("maxval", 65535)? as u16;
    limits.check(width, height, origin)?;
    // Exactly one whitespace byte separates maxval from the raster.
    match bytes.get(h.at) {
        None => return Err(h.truncated("the pixel data")),
        Some(c) if c.is_ascii_whitespace() => h.at += 1,
        Some(_) => return Err(h.header("maxval is not followed by whitespace".into())),
    }
    let data = &bytes[h.at..];
    let sample = if maxval < 256 { 1 } else { 2 };
    let n = width as usize * height as usize;
    let need = n.checked_mul(sample).ok_or_else(|| {
        h.header(format!(
            "{width}×{height} is too large an image for this machine"
        ))
    })?;
    if data.len() < need {
        return Err(FormatError::Truncated {
            origin: origin.into(),
            what: format!(
                "{width}×{height} {}-bit pixels after a {}-byte header",
                8 * sample,
                h.at
            ),
            expected: h.at + need,
            found: bytes.len(),
        });
    }
    let over = |i: usize, v: u16| FormatError::ImageData {
        origin: origin.into(),
        what: format!(
            "pixel ({}, {}) = {v} exceeds maxval {maxval}",
            i % width as usize,
            i / width as usize
        ),
    };
    let (mut v8, mut v16) = match reuse {
        Some(Pixels::Mono8(v)) => (v, Vec::new()),
        Some(Pixels::Mono16(v)) => (Vec::new(), v),
        None => (Vec::new(), Vec::new()),
    };
    let pixels = if sample == 1 {
        v8.clear();
        v8.extend_from_slice(&data[..need]);
        let v = v8;
        // (Every byte is ≤ 255: only a lower maxval needs the scan.)
        if maxval < 255 {
            if let Some(i) = v.iter().position(|&p| p as u16 > maxval) {
                return Err(over(i, v[i] as u16));
            }
        }
        Pixels::Mono8(v)
    } else {
        v16.clear();
        v16.extend(
            data[..need]
                .chunks_exact(2)
                .map(|b| u16::from_be_bytes([b[0], b[1]])),
        );
        let v = v16;
        if let Some(i) = v.iter().position(|&p| p > maxval) {
            return Err(over(i, v[i]));
        }
        Pixels::Mono16(v)
    };
    Image::from_pixels(width, height, maxval, pixels).map_err(|e| FormatError::ImageHeader {
        origin: origin.into(),
        what: e.to_string(),
    })
}

/// An image that cannot be written as it is.
fn not_encodable(origin: &str, what: String) -> FormatError {
    FormatError::Write {
        path: origin.into(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidData, what),
    }
}

/// If a PNG's chunk sequence runs past the end of the file (or stops
/// before `IEND`), the length the file needs at least.
fn png_needs(bytes: &[u8]) -> Option<usize> {
    let mut at = PNG_MAGIC.len();
    loop {
        if at + 12 > bytes.len() {
            return Some(at + 12);
        }
        let len = u32::from_be_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
        let end = at.checked_add(12 + len as usize)?;
        if end > bytes.len() {
            return Some(end);
        }
        if &bytes[at + 4..at + 8] == b"IEND" {
            return None;
        }
        at = end;
    }
}

/// Checks that no pixel exceeds the image's saturation level.
fn check_values(image: &Image, origin: &str) -> Result<(), FormatError> {
    let max = image.max_value();
    let first = match image.pixels() {
        Pixels::Mono8(v) => v.iter().position(|&p| p as u16 > max),
        Pixels::Mono16(v) => v.iter().position(|&p| p > max),
    };
    match first {
        None => Ok(()),
        Some(i) => {
            let w = image.width() as usize;
            let (c, r) = ((i % w) as u32, (i / w) as u32);
            Err(not_encodable(
                origin,
                format!(
                    "pixel ({c}, {r}) = {} exceeds the image's max_value {max}",
                    image.get(c, r)
                ),
            ))
        }
    }
}

/// Encodes an image as binary PGM (appending to `out`): `maxval` is the
/// image's `max_value`; an 8-bit image is written one byte a sample, a
/// 16-bit image two bytes big-endian (one byte if its `max_value` < 256,
/// as the format demands).
pub fn encode_pgm(image: &Image, origin: &str, out: &mut Vec<u8>) -> Result<(), FormatError> {
    check_values(image, origin)?;
    let max = image.max_value();
    out.extend_from_slice(
        format!("P5\n{} {}\n{}\n", image.width(), image.height(), max).as_bytes(),
    );
    match image.pixels() {
        Pixels::Mono8(v) => out.extend_from_slice(v),
        Pixels::Mono16(v) if max < 256 => out.extend(v.iter().map(|&p| p as u8)),
        Pixels::Mono16(v) => {
            out.reserve(2 * v.len());
            for p in v {
                out.extend_from_slice(&p.to_be_bytes());
            }
        }
    }
    Ok(())
}

/// Maps a PNG decoding error onto the image errors (truncation is found
/// beforehand from the chunk lengths).
fn png_error(origin: &str, e: png::DecodingError, header: bool) -> FormatError {
    let what = e.to_string();
    if header {
        FormatError::ImageHeader {
            origin: origin.into(),
            what,
        }
    } else {
        FormatError::ImageData {
            origin: origin.into(),
            what,
        }
    }
}

/// Decodes a greyscale PNG of any size up to [`ImageLimits::Any`].
pub fn decode_png(bytes: &[u8], origin: &str) -> Result<Image, FormatError> {
    png_with(bytes, origin, ImageLimits::Any)
}

fn png_with(bytes: &[u8], origin: &str, limits: ImageLimits) -> Result<Image, FormatError> {
    if !bytes.starts_with(PNG_MAGIC) {
        return ImageFormat::sniff(bytes, origin).and(Err(FormatError::UnsupportedImage {
            origin: origin.into(),
            what: "not a PNG file".into(),
        }));
    }
    if let Some(expected) = png_needs(bytes) {
        return Err(FormatError::Truncated {
            origin: origin.into(),
            what: "the PNG chunks up to IEND".into(),
            expected,
            found: bytes.len(),
        });
    }
    let mut decoder = png::Decoder::new(bytes);
    // Expands 1-, 2- and 4-bit grey to 8-bit (scaled to 0..=255).
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder
        .read_info()
        .map_err(|e| png_error(origin, e, true))?;
    let info = reader.info();
    let (width, height) = (info.width, info.height);
    let colour = info.color_type;
    if colour != png::ColorType::Grayscale {
        return Err(FormatError::UnsupportedImage {
            origin: origin.into(),
            what: format!(
                "PNG colour type {}; only greyscale images are read (convert to grey first)",
                match colour {
                    png::ColorType::Grayscale => "grey",
                    png::ColorType::Rgb => "RGB",
                    png::ColorType::Indexed => "indexed (palette)",
                    png::ColorType::GrayscaleAlpha => "grey with alpha",
                    png::ColorType::Rgba => "RGBA",
                }
            ),
        });
    }
    let (out_colour, depth) = reader.output_color_type();
    if out_colour != png::ColorType::Grayscale {
        return Err(FormatError::UnsupportedImage {
            origin: origin.into(),
            what: "greyscale PNG with a transparency (tRNS) chunk; grey images without alpha only"
                .into(),
        });
    }
    // Size and depth from the header, before the pixel buffer exists.
    if !matches!(depth, png::BitDepth::Eight | png::BitDepth::Sixteen) {
        return Err(FormatError::UnsupportedImage {
            origin: origin.into(),
            what: format!("PNG bit depth {} bits per sample", depth as u8),
        });
    }
    limits.check(width, height, origin)?;
    let mut buf = vec![0; reader.output_buffer_size()];
    reader
        .next_frame(&mut buf)
        .map_err(|e| png_error(origin, e, false))?;
    let n = width as usize * height as usize;
    let stored_max = reader
        .info()
        .uncompressed_latin1_text
        .iter()
        .find(|t| t.keyword == MAX_VALUE_KEY)
        .and_then(|t| t.text.trim().parse::<u16>().ok())
        .filter(|&m| m > 0);
    let (pixels, max) = match depth {
        png::BitDepth::Sixteen => {
            let v: Vec<u16> = buf[..2 * n]
                .chunks_exact(2)
                .map(|b| u16::from_be_bytes([b[0], b[1]]))
                .collect();
            (Pixels::Mono16(v), stored_max.unwrap_or(65535))
        }
        png::BitDepth::Eight => {
            buf.truncate(n);
            (Pixels::Mono8(buf), stored_max.unwrap_or(255).min(255))
        }
        other => {
            return Err(FormatError::UnsupportedImage {
                origin: origin.into(),
                what: format!("PNG bit depth {} bits per sample", other as u8),
            })
        }
    };
    let image =
        Image::from_pixels(width, height, max, pixels).map_err(|e| FormatError::ImageHeader {
            origin: origin.into(),
            what: e.to_string(),
        })?;
    // A stored max_value that the samples exceed is not ours: fall back to
    // the full range rather than hand on an inconsistent image.
    if check_values(&image, origin).is_err() {
        let full = if depth == png::BitDepth::Sixteen {
            65535
        } else {
            255
        };
        let (w, h) = (image.width(), image.height());
        let pixels = match image.pixels() {
            Pixels::Mono8(v) => Pixels::Mono8(v.clone()),
            Pixels::Mono16(v) => Pixels::Mono16(v.clone()),
        };
        return Image::from_pixels(w, h, full, pixels).map_err(|e| FormatError::ImageHeader {
            origin: origin.into(),
            what: e.to_string(),
        });
    }
    Ok(image)
}

/// Encodes an image as greyscale PNG (appending to `out`); a 16-bit image's
/// `max_value` below 65535 goes into a `tEXt` chunk `max_value`.
pub fn encode_png(image: &Image, origin: &str, out: &mut Vec<u8>) -> Result<(), FormatError> {
    check_values(image, origin)?;
    let invalid = |e: png::EncodingError| not_encodable(origin, e.to_string());
    let mut enc = png::Encoder::new(&mut *out, image.width(), image.height());
    enc.set_color(png::ColorType::Grayscale);
    let full = match image.pixels() {
        Pixels::Mono8(_) => {
            enc.set_depth(png::BitDepth::Eight);
            255
        }
        Pixels::Mono16(_) => {
            enc.set_depth(png::BitDepth::Sixteen);
            65535
        }
    };
    if image.max_value() != full {
        enc.add_text_chunk(MAX_VALUE_KEY.into(), image.max_value().to_string())
            .map_err(invalid)?;
    }
    let mut writer = enc.write_header().map_err(invalid)?;
    match image.pixels() {
        Pixels::Mono8(v) => writer.write_image_data(v).map_err(invalid)?,
        Pixels::Mono16(v) => {
            let bytes: Vec<u8> = v.iter().flat_map(|p| p.to_be_bytes()).collect();
            writer.write_image_data(&bytes).map_err(invalid)?
        }
    }
    writer.finish().map_err(invalid)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp8(w: u32, h: u32) -> Image {
        let v = (0..w * h).map(|i| (i * 7 % 256) as u8).collect();
        Image::from_pixels(w, h, 255, Pixels::Mono8(v)).unwrap()
    }

    fn ramp16(w: u32, h: u32, max: u16) -> Image {
        let v = (0..w * h)
            .map(|i| (i * 977 % (max as u32 + 1)) as u16)
            .collect();
        Image::from_pixels(w, h, max, Pixels::Mono16(v)).unwrap()
    }

    fn pgm(image: &Image) -> Vec<u8> {
        let mut out = Vec::new();
        encode_pgm(image, "t.pgm", &mut out).unwrap();
        out
    }

    fn png_bytes(image: &Image) -> Vec<u8> {
        let mut out = Vec::new();
        encode_png(image, "t.png", &mut out).unwrap();
        out
    }

    #[test]
    fn pgm_round_trips_8_and_16_bit_with_maxval() {
        for img in [ramp8(7, 5), ramp16(6, 4, 65535), ramp16(9, 3, 4095)] {
            let back = decode_image(&pgm(&img), "t.pgm").unwrap();
            assert_eq!(back, img);
        }
        // 16-bit samples are big-endian.
        let one = Image::from_pixels(1, 1, 65535, Pixels::Mono16(vec![0x1234])).unwrap();
        assert!(pgm(&one).ends_with(&[0x12, 0x34]));
        assert!(pgm(&ramp16(2, 2, 4095)).starts_with(b"P5\n2 2\n4095\n"));
    }

    #[test]
    fn pgm_header_with_comments_and_low_maxval() {
        let mut bytes = b"P5 # made by hand\n# size\n3 2\n# max\n100\n".to_vec();
        bytes.extend_from_slice(&[0, 10, 20, 30, 40, 100]);
        let img = decode_pgm(&bytes, "h.pgm").unwrap();
        assert_eq!((img.width(), img.height(), img.max_value()), (3, 2, 100));
        assert_eq!(img.get(2, 1), 100);
    }

    #[test]
    fn png_round_trips_8_and_16_bit_with_max_value() {
        for img in [ramp8(7, 5), ramp16(6, 4, 65535), ramp16(9, 3, 4095)] {
            let back = decode_image(&png_bytes(&img), "t.png").unwrap();
            assert_eq!(back, img);
        }
    }

    #[test]
    fn truncated_files_say_so() {
        let full = pgm(&ramp16(8, 8, 65535));
        for cut in [full.len() - 1, 20, 9, 1] {
            let e = decode_image(&full[..cut], "cut.pgm").unwrap_err();
            assert!(
                matches!(e, FormatError::Truncated { .. }),
                "cut at {cut}: {e}"
            );
            assert!(e.to_string().starts_with("cut.pgm: truncated"), "{e}");
        }
        let full = png_bytes(&ramp8(40, 30));
        for cut in [full.len() - 13, full.len() / 2, 30, 4] {
            let e = decode_image(&full[..cut], "cut.png").unwrap_err();
            assert!(
                matches!(e, FormatError::Truncated { .. }),
                "cut at {cut}: {e}"
            );
        }
    }

    #[test]
    fn corrupt_headers_and_data_are_named() {
        let cases: [(&[u8], &str); 6] = [
            (
                b"P5\n3 x\n255\n",
                "height: expected a decimal number, found `x`",
            ),
            (b"P5\n0 2\n255\n", "width = 0 is not in 1..="),
            (b"P5\n2 2\n70000\n", "maxval = 70000 is not in 1..=65535"),
            (b"P5x\n2 2\n255\n", "not followed by whitespace"),
            (
                b"P5\n1 1\n100\n\xc8",
                "pixel (0, 0) = 200 exceeds maxval 100",
            ),
            (b"P2\n1 1\n255\n0", "plain (ASCII) PGM"),
        ];
        for (bytes, want) in cases {
            let e = decode_image(bytes, "bad.pgm").unwrap_err().to_string();
            assert!(e.starts_with("bad.pgm: ") && e.contains(want), "{e}");
        }
        let mut png = png_bytes(&ramp8(16, 16));
        // Flip a byte inside the IHDR chunk: its CRC no longer matches.
        png[20] ^= 0x55;
        let e = decode_image(&png, "bad.png").unwrap_err();
        assert!(matches!(e, FormatError::ImageHeader { .. }), "{e}");
        let e = decode_image(b"GIF89a....", "x.gif")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unsupported image"), "{e}");
    }

    #[test]
    fn colour_png_is_refused_clearly() {
        let mut bytes = Vec::new();
        let mut enc = png::Encoder::new(&mut bytes, 2, 2);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().unwrap();
        w.write_image_data(&[0u8; 12]).unwrap();
        w.finish().unwrap();
        let e = decode_image(&bytes, "colour.png").unwrap_err().to_string();
        assert!(
            e.starts_with("colour.png: unsupported image: PNG colour type RGB;"),
            "{e}"
        );
    }

    #[test]
    fn low_bit_grey_png_expands_and_grey_alpha_is_refused() {
        let mut bytes = Vec::new();
        let mut enc = png::Encoder::new(&mut bytes, 8, 1);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::One);
        let mut w = enc.write_header().unwrap();
        w.write_image_data(&[0b1010_0001]).unwrap();
        w.finish().unwrap();
        let img = decode_image(&bytes, "bits.png").unwrap();
        assert_eq!(img.max_value(), 255);
        let row: Vec<u16> = (0..8).map(|c| img.get(c, 0)).collect();
        assert_eq!(row, [255, 0, 255, 0, 0, 0, 0, 255]);

        let mut bytes = Vec::new();
        let mut enc = png::Encoder::new(&mut bytes, 1, 1);
        enc.set_color(png::ColorType::GrayscaleAlpha);
        enc.set_depth(png::BitDepth::Sixteen);
        let mut w = enc.write_header().unwrap();
        w.write_image_data(&[0, 1, 0, 2]).unwrap();
        w.finish().unwrap();
        let e = decode_image(&bytes, "ga.png").unwrap_err().to_string();
        assert!(e.contains("colour type grey with alpha"), "{e}");
    }

    #[test]
    fn files_missing_extension_and_size_check() {
        let dir =
            std::env::temp_dir().join(format!("photopose-formats-image-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let img = ramp16(5, 3, 4095);
        for name in ["a.pgm", "b.PNG"] {
            let p = dir.join(name);
            save_image(&p, &img).unwrap();
            assert_eq!(load_image(&p).unwrap(), img);
        }
        let e = load_image(&dir.join("nope.pgm")).unwrap_err().to_string();
        assert!(
            e.ends_with("nope.pgm: cannot read the image file: no such file"),
            "{e}"
        );
        let e = save_image(&dir.join("c.tif"), &img)
            .unwrap_err()
            .to_string();
        assert!(e.contains("extension .tif (use .pgm or .png)"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();

        let cam = Camera::reference_ideal();
        let e = check_size(&Image::new_mono8(640, 480), &cam, "f.pgm")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "f.pgm: image is 640×480, camera file says 1300×1030");
        check_size(&Image::new_mono8(1300, 1030), &cam, "f.pgm").unwrap();
    }

    #[test]
    fn values_above_max_value_are_not_written() {
        let img = Image::from_pixels(2, 1, 100, Pixels::Mono8(vec![5, 101])).unwrap();
        let e = encode_pgm(&img, "o.pgm", &mut Vec::new())
            .unwrap_err()
            .to_string();
        assert!(e.contains("pixel (1, 0) = 101 exceeds"), "{e}");
    }

    /// A hand-made 62-byte greyscale PNG whose header declares
    /// `width × height` pixels of `depth` bits.
    pub(crate) fn tiny_png(width: u32, height: u32, depth: u8) -> Vec<u8> {
        fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
            out.extend_from_slice(&(data.len() as u32).to_be_bytes());
            let start = out.len();
            out.extend_from_slice(kind);
            out.extend_from_slice(data);
            let crc = crc32fast::hash(&out[start..]);
            out.extend_from_slice(&crc.to_be_bytes());
        }
        let mut out = PNG_MAGIC.to_vec();
        let mut ihdr = Vec::new();
        ihdr.extend_from_slice(&width.to_be_bytes());
        ihdr.extend_from_slice(&height.to_be_bytes());
        ihdr.extend_from_slice(&[depth, 0, 0, 0, 0]); // grey, deflate, no filter, no interlace
        chunk(&mut out, b"IHDR", &ihdr);
        // The start of a zlib stream; never decoded.
        chunk(&mut out, b"IDAT", &[0x78, 0x9c, 0x63, 0x60, 0]);
        chunk(&mut out, b"IEND", &[]);
        out
    }

    fn camera_1300() -> Camera {
        Camera::reference_ideal()
    }

    #[test]
    fn the_reader_reuses_its_buffers_and_reads_as_load_image_for_does() {
        let dir =
            std::env::temp_dir().join(format!("photopose-formats-reader-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cam = camera_1300();
        let mut a = Image::new_mono8(1300, 1030);
        if let Pixels::Mono8(v) = a.pixels_mut() {
            v.iter_mut()
                .enumerate()
                .for_each(|(i, p)| *p = (i * 7 % 251) as u8);
        }
        let mut b = ramp16(1300, 1030, 4095);
        if let Pixels::Mono16(v) = b.pixels_mut() {
            v[5] = 4095;
        }
        let low = Image::from_pixels(1300, 1030, 100, Pixels::Mono8(vec![3; 1300 * 1030])).unwrap();
        let files = [
            ("a.pgm", &a),
            ("b.pgm", &b),
            ("c.png", &a),
            ("d.pgm", &ramp8(7, 5)),
        ];
        for (name, img) in files {
            save_image(&dir.join(name), img).unwrap();
        }
        // A raster value above maxval is named as by load_image_for.
        let mut bytes = Vec::new();
        encode_pgm(&low, "e.pgm", &mut bytes).unwrap();
        let last = bytes.len() - 1;
        bytes[last] = 200;
        std::fs::write(dir.join("e.pgm"), &bytes).unwrap();
        let mut reader = ImageReader::for_camera(&cam);
        // A batch of one kind: the second image lands in the first's memory.
        let first = reader.load(&dir.join("a.pgm")).unwrap();
        let at = |img: &Image| match img.pixels() {
            Pixels::Mono8(v) => v.as_ptr() as usize,
            Pixels::Mono16(v) => v.as_ptr() as usize,
        };
        let first_at = at(&first);
        reader.recycle(first);
        let second = reader.load(&dir.join("a.pgm")).unwrap();
        assert_eq!(at(&second), first_at);
        assert_eq!(second, a);
        reader.recycle(second);
        // Mixed kinds, sizes and failures: what load_image_for gives.
        for _ in 0..2 {
            for name in [
                "a.pgm", "b.pgm", "c.png", "d.pgm", "e.pgm", "a.pgm", "nope.pgm",
            ] {
                let path = dir.join(name);
                let want = load_image_for(&path, &cam).map_err(|e| e.to_string());
                let got = reader.load(&path).map_err(|e| e.to_string());
                assert_eq!(got, want, "{name}");
                if let Ok(img) = got {
                    reader.recycle(img);
                }
            }
        }
        assert!(matches!(
            reader.load(&dir.join("e.pgm")),
            Err(FormatError::ImageData { .. })
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_tiny_png_declaring_a_huge_image_is_refused_before_allocation() {
        for depth in [8, 16] {
            let bytes = tiny_png(100_000, 100_000, depth);
            assert_eq!(bytes.len(), 62);
            // Against the camera: the sensor's size is named.
            let e =
                decode_image_for(&bytes, "huge.png", ImageLimits::of(&camera_1300())).unwrap_err();
            assert_eq!(
                e.to_string(),
                "huge.png: image is 100000×100000, camera file says 1300×1030"
            );
            // Without a camera: the hard maximum.
            let e = decode_image(&bytes, "huge.png").unwrap_err().to_string();
            assert!(
                e.starts_with("huge.png: corrupt image header: 100000×100000 is larger"),
                "{e}"
            );
        }
        // Within the side limit but too many pixels.
        let e = decode_image(&tiny_png(65_535, 65_535, 8), "big.png")
            .unwrap_err()
            .to_string();
        assert!(e.contains("65535×65535 is larger"), "{e}");
        // A supported size in the header reaches the decoder (which finds
        // the data bad), showing the header check is what refused the rest.
        let e = decode_image(&tiny_png(4, 4, 8), "small.png").unwrap_err();
        assert!(matches!(e, FormatError::ImageData { .. }), "{e}");
    }

    #[test]
    fn a_pgm_declaring_a_huge_image_is_refused_by_its_header() {
        let bytes = b"P5\n100000 100000\n65535\n\0\0\0\0";
        let e = decode_image_for(bytes, "huge.pgm", ImageLimits::of(&camera_1300()))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "huge.pgm: image is 100000×100000, camera file says 1300×1030"
        );
        let e = decode_image(bytes, "huge.pgm").unwrap_err().to_string();
        assert!(e.contains("100000×100000 is larger"), "{e}");
        // The camera's size passes the header and is then found truncated.
        let e = decode_image_for(
            b"P5\n1300 1030\n255\n\0",
            "short.pgm",
            ImageLimits::of(&camera_1300()),
        )
        .unwrap_err();
        assert!(matches!(e, FormatError::Truncated { .. }), "{e}");
    }

    #[test]
    fn the_file_limit_follows_the_sensor() {
        let limits = ImageLimits::of(&camera_1300());
        assert_eq!(limits.file_limit(), 4 * 1300 * 1030 + (1 << 20));
        assert_eq!(ImageLimits::Any.file_limit(), FileKind::Image.limit());
    }
}
