//! photopose-frame: the grey-value image that sources produce, the renderer
//! draws into and the vision crate reads. A leaf crate, so that neither the
//! sources nor vision depend on each other.
//!
//! Pixels are stored row-major without padding; `max_value` is the
//! saturation level (255 for 8-bit, 4095 for a 12-bit camera in a 16-bit
//! container, 65535 for full 16-bit).

mod meta;

pub use meta::FrameMeta;
use thiserror::Error;

/// Pixel storage.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Pixels {
    /// 8-bit grey values.
    Mono8(Vec<u8>),
    /// 16-bit grey values.
    Mono16(Vec<u16>),
}

/// An owned grey-value image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    width: u32,
    height: u32,
    max_value: u16,
    pixels: Pixels,
}

/// A borrowed view of an image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageView<'a> {
    /// 8-bit pixels.
    Mono8 {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Row-major pixels, `width * height` of them.
        data: &'a [u8],
    },
    /// 16-bit pixels.
    Mono16 {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Saturation level.
        max_value: u16,
        /// Row-major pixels, `width * height` of them.
        data: &'a [u16],
    },
}

/// An image whose buffer does not fit its size.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum FrameError {
    /// Buffer length differs from `width * height`.
    #[error("image buffer holds {got} pixels, {width}×{height} needs {need}")]
    BufferSize {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
        /// Pixels needed.
        need: usize,
        /// Pixels present.
        got: usize,
    },
    /// Zero width or height.
    #[error("image size {width}×{height} is empty")]
    Empty {
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },
    /// `max_value` of zero.
    #[error("saturation level must be positive")]
    MaxValue,
}

impl Image {
    /// A black 8-bit image.
    pub fn new_mono8(width: u32, height: u32) -> Self {
        Image {
            width,
            height,
            max_value: 255,
            pixels: Pixels::Mono8(vec![0; width as usize * height as usize]),
        }
    }

    /// A black 16-bit image with saturation level `max_value`.
    pub fn new_mono16(width: u32, height: u32, max_value: u16) -> Self {
        Image {
            width,
            height,
            max_value: max_value.max(1),
            pixels: Pixels::Mono16(vec![0; width as usize * height as usize]),
        }
    }

    /// An image from a buffer, checked against its size.
    pub fn from_pixels(
        width: u32,
        height: u32,
        max_value: u16,
        pixels: Pixels,
    ) -> Result<Self, FrameError> {
        if width == 0 || height == 0 {
            return Err(FrameError::Empty { width, height });
        }
        if max_value == 0 {
            return Err(FrameError::MaxValue);
        }
        let need = width as usize * height as usize;
        let got = match &pixels {
            Pixels::Mono8(v) => v.len(),
            Pixels::Mono16(v) => v.len(),
        };
        if got != need {
            return Err(FrameError::BufferSize {
                width,
                height,
                need,
                got,
            });
        }
        let max_value = match pixels {
            Pixels::Mono8(_) => max_value.min(255),
            Pixels::Mono16(_) => max_value,
        };
        Ok(Image {
            width,
            height,
            max_value,
            pixels,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Saturation level.
    pub fn max_value(&self) -> u16 {
        self.max_value
    }

    /// The pixel storage.
    pub fn pixels(&self) -> &Pixels {
        &self.pixels
    }

    /// The pixel storage, mutable (its length must not change).
    pub fn pixels_mut(&mut self) -> &mut Pixels {
        &mut self.pixels
    }

    /// Grey value at `(col, row)` as `u16`.
    #[inline]
    pub fn get(&self, col: u32, row: u32) -> u16 {
        let i = row as usize * self.width as usize + col as usize;
        match &self.pixels {
            Pixels::Mono8(v) => v[i] as u16,
            Pixels::Mono16(v) => v[i],
        }
    }

    /// A borrowed view.
    pub fn view(&self) -> ImageView<'_> {
        match &self.pixels {
            Pixels::Mono8(data) => ImageView::Mono8 {
                width: self.width,
                height: self.height,
                data,
            },
            Pixels::Mono16(data) => ImageView::Mono16 {
                width: self.width,
                height: self.height,
                max_value: self.max_value,
                data,
            },
        }
    }
}

impl ImageView<'_> {
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        match self {
            ImageView::Mono8 { width, .. } | ImageView::Mono16 { width, .. } => *width,
        }
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        match self {
            ImageView::Mono8 { height, .. } | ImageView::Mono16 { height, .. } => *height,
        }
    }

    /// Saturation level.
    pub fn max_value(&self) -> u16 {
        match self {
            ImageView::Mono8 { .. } => 255,
            ImageView::Mono16 { max_value, .. } => *max_value,
        }
    }

    /// Grey value at `(col, row)`.
    #[inline]
    pub fn get(&self, col: u32, row: u32) -> u16 {
        match self {
            ImageView::Mono8 { width, data, .. } => {
                data[row as usize * *width as usize + col as usize] as u16
            }
            ImageView::Mono16 { width, data, .. } => {
                data[row as usize * *width as usize + col as usize]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffer_size_is_checked() {
        assert!(Image::from_pixels(4, 3, 255, Pixels::Mono8(vec![0; 11])).is_err());
        let img = Image::from_pixels(4, 3, 4095, Pixels::Mono16((0..12).collect())).unwrap();
        assert_eq!(img.get(1, 2), 9);
        assert_eq!(img.view().get(3, 0), 3);
        assert_eq!(img.view().max_value(), 4095);
    }
}
