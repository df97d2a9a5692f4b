//! photopose-frame: the grey-value image that sources produce, the renderer
//! draws into and the vision crate reads. A leaf crate, so that neither the
//! sources nor vision depend on each other.
//!
//! An [`Image`] stores its pixels row-major without padding; `max_value` is
//! the saturation level (255 for 8-bit, 4095 for a 12-bit camera in a 16-bit
//! container, 65535 for full 16-bit). An [`ImageView`] borrows a window of a
//! frame without copying: its origin in the full frame's pixel coordinates,
//! its size and the row stride of the buffer it reads.

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

/// The pixels a view borrows: the view's first pixel is element 0 and its
/// row `r` starts at element `r * stride`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ViewPixels<'a> {
    /// 8-bit grey values.
    Mono8(&'a [u8]),
    /// 16-bit grey values.
    Mono16(&'a [u16]),
}

/// A borrowed window of a frame, without copying: `width × height` pixels
/// whose top-left pixel is `origin()` in the full frame's pixel
/// coordinates, rows `stride` elements apart in the underlying buffer.
/// [`Image::view`] gives the whole frame (origin `(0, 0)`, stride = width);
/// [`ImageView::window`] a part of a view. Positions passed to and
/// returned by a view are full-frame pixel coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageView<'a> {
    pixels: ViewPixels<'a>,
    col0: u32,
    row0: u32,
    width: u32,
    height: u32,
    stride: usize,
    max_value: u16,
}

/// An image whose buffer does not fit its size.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
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
    /// A row stride shorter than the row.
    #[error("row stride {stride} is shorter than the width {width}")]
    Stride {
        /// Width.
        width: u32,
        /// Stride, pixels.
        stride: usize,
    },
    /// A window that is empty or not inside its view (or that would leave
    /// the range of pixel coordinates).
    #[error(
        "window {width}×{height} at ({col}, {row}) is not inside the view \
         {view_width}×{view_height} at ({view_col}, {view_row})"
    )]
    Window {
        /// Window's first column (full-frame coordinates).
        col: u32,
        /// Window's first row.
        row: u32,
        /// Window width.
        width: u32,
        /// Window height.
        height: u32,
        /// The view's first column.
        view_col: u32,
        /// The view's first row.
        view_row: u32,
        /// The view's width.
        view_width: u32,
        /// The view's height.
        view_height: u32,
    },
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

    /// The pixel storage, giving up the image (to reuse its buffer for
    /// the next one without allocating).
    pub fn into_pixels(self) -> Pixels {
        self.pixels
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

    /// The whole frame as a view (origin `(0, 0)`, stride = width).
    pub fn view(&self) -> ImageView<'_> {
        let pixels = match &self.pixels {
            Pixels::Mono8(data) => ViewPixels::Mono8(data),
            Pixels::Mono16(data) => ViewPixels::Mono16(data),
        };
        ImageView {
            pixels,
            col0: 0,
            row0: 0,
            width: self.width,
            height: self.height,
            stride: self.width as usize,
            // (8-bit views saturate at 255, as they always did.)
            max_value: match self.pixels {
                Pixels::Mono8(_) => 255,
                Pixels::Mono16(_) => self.max_value,
            },
        }
    }
}

/// Elements a `width × height` layout with rows `stride` apart spans.
fn span(width: u32, height: u32, stride: usize) -> usize {
    (height as usize - 1) * stride + width as usize
}

impl<'a> ImageView<'a> {
    fn from_parts(
        pixels: ViewPixels<'a>,
        width: u32,
        height: u32,
        stride: usize,
        max_value: u16,
    ) -> Result<Self, FrameError> {
        if width == 0 || height == 0 {
            return Err(FrameError::Empty { width, height });
        }
        if stride < width as usize {
            return Err(FrameError::Stride { width, stride });
        }
        if max_value == 0 {
            return Err(FrameError::MaxValue);
        }
        let need = span(width, height, stride);
        let got = match pixels {
            ViewPixels::Mono8(d) => d.len(),
            ViewPixels::Mono16(d) => d.len(),
        };
        if got < need {
            return Err(FrameError::BufferSize {
                width,
                height,
                need,
                got,
            });
        }
        // Trimmed to the span, so that every row of the view is in range.
        let pixels = match pixels {
            ViewPixels::Mono8(d) => ViewPixels::Mono8(&d[..need]),
            ViewPixels::Mono16(d) => ViewPixels::Mono16(&d[..need]),
        };
        Ok(ImageView {
            pixels,
            col0: 0,
            row0: 0,
            width,
            height,
            stride,
            max_value,
        })
    }

    /// An 8-bit view of a caller's buffer (a frame with padded rows, or a
    /// camera's region of interest): `width × height` pixels, rows `stride`
    /// pixels apart, origin `(0, 0)` (see [`ImageView::placed_at`]).
    pub fn mono8(
        data: &'a [u8],
        width: u32,
        height: u32,
        stride: usize,
    ) -> Result<Self, FrameError> {
        Self::from_parts(ViewPixels::Mono8(data), width, height, stride, 255)
    }

    /// A 16-bit view of a caller's buffer with saturation level
    /// `max_value`; see [`ImageView::mono8`].
    pub fn mono16(
        data: &'a [u16],
        width: u32,
        height: u32,
        stride: usize,
        max_value: u16,
    ) -> Result<Self, FrameError> {
        Self::from_parts(ViewPixels::Mono16(data), width, height, stride, max_value)
    }

    /// The same pixels placed with their top-left pixel at `(col, row)` of
    /// the full frame (a camera's region of interest, say).
    pub fn placed_at(self, col: u32, row: u32) -> Result<Self, FrameError> {
        let fits = col.checked_add(self.width).is_some() && row.checked_add(self.height).is_some();
        if !fits {
            return Err(FrameError::Window {
                col,
                row,
                width: self.width,
                height: self.height,
                view_col: 0,
                view_row: 0,
                view_width: u32::MAX,
                view_height: u32::MAX,
            });
        }
        Ok(ImageView {
            col0: col,
            row0: row,
            ..self
        })
    }

    /// The window `width × height` whose top-left pixel is `(col, row)` in
    /// full-frame coordinates; it must be non-empty and lie inside this view.
    pub fn window(&self, col: u32, row: u32, width: u32, height: u32) -> Result<Self, FrameError> {
        let inside = width > 0
            && height > 0
            && col >= self.col0
            && row >= self.row0
            && col as u64 + width as u64 <= self.col0 as u64 + self.width as u64
            && row as u64 + height as u64 <= self.row0 as u64 + self.height as u64;
        if !inside {
            return Err(FrameError::Window {
                col,
                row,
                width,
                height,
                view_col: self.col0,
                view_row: self.row0,
                view_width: self.width,
                view_height: self.height,
            });
        }
        let first = (row - self.row0) as usize * self.stride + (col - self.col0) as usize;
        let end = first + span(width, height, self.stride);
        let pixels = match self.pixels {
            ViewPixels::Mono8(d) => ViewPixels::Mono8(&d[first..end]),
            ViewPixels::Mono16(d) => ViewPixels::Mono16(&d[first..end]),
        };
        Ok(ImageView {
            pixels,
            col0: col,
            row0: row,
            width,
            height,
            stride: self.stride,
            max_value: self.max_value,
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

    /// Full-frame coordinates `(col, row)` of the view's top-left pixel.
    pub fn origin(&self) -> (u32, u32) {
        (self.col0, self.row0)
    }

    /// Distance between the starts of two rows in the buffer, pixels.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// Saturation level (255 for every 8-bit view).
    pub fn max_value(&self) -> u16 {
        self.max_value
    }

    /// The borrowed pixels: the view's first pixel is element 0, row `r`
    /// of the view starts at element `r * stride()`, and the slice ends
    /// with the last pixel of the last row.
    pub fn pixels(&self) -> ViewPixels<'a> {
        self.pixels
    }

    /// Whether the full-frame position `(col, row)` lies in the view.
    pub fn contains(&self, col: u32, row: u32) -> bool {
        col >= self.col0
            && row >= self.row0
            && ((col - self.col0) as u64) < self.width as u64
            && ((row - self.row0) as u64) < self.height as u64
    }

    /// Grey value at the full-frame position `(col, row)`; `None` outside
    /// the view.
    #[inline]
    pub fn get(&self, col: u32, row: u32) -> Option<u16> {
        if !self.contains(col, row) {
            return None;
        }
        let i = (row - self.row0) as usize * self.stride + (col - self.col0) as usize;
        Some(match self.pixels {
            ViewPixels::Mono8(d) => d[i] as u16,
            ViewPixels::Mono16(d) => d[i],
        })
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
        assert_eq!(img.view().get(3, 0), Some(3));
        assert_eq!(img.view().get(4, 0), None);
        assert_eq!(img.view().max_value(), 4095);
    }

    #[test]
    fn windows_keep_full_frame_coordinates() {
        // 6 × 5, value = 10·row + col.
        let px = (0..5u8)
            .flat_map(|r| (0..6u8).map(move |c| 10 * r + c))
            .collect();
        let img = Image::from_pixels(6, 5, 255, Pixels::Mono8(px)).unwrap();
        let v = img.view();
        assert_eq!(
            (v.origin(), v.stride(), v.width(), v.height()),
            ((0, 0), 6, 6, 5)
        );
        let w = v.window(2, 1, 3, 3).unwrap();
        assert_eq!(
            (w.origin(), w.stride(), w.width(), w.height()),
            ((2, 1), 6, 3, 3)
        );
        assert_eq!(w.get(2, 1), Some(12));
        assert_eq!(w.get(4, 3), Some(34));
        assert_eq!(w.get(1, 1), None);
        assert_eq!(w.get(5, 3), None);
        let ViewPixels::Mono8(d) = w.pixels() else {
            panic!("8-bit")
        };
        assert_eq!(d.len(), 2 * 6 + 3);
        assert_eq!((d[0], d[6], d[14]), (12, 22, 34));
        // A window of a window, in the same coordinates.
        let ww = w.window(3, 2, 2, 2).unwrap();
        assert_eq!((ww.origin(), ww.get(4, 3)), ((3, 2), Some(34)));
        // Not inside, or empty: an error naming the window and the view.
        for (c, r, ww_, hh) in [(1, 1, 2, 2), (3, 2, 3, 1), (2, 1, 0, 1), (4, 3, 1, 2)] {
            let e = w.window(c, r, ww_, hh).unwrap_err();
            assert!(
                matches!(
                    e,
                    FrameError::Window {
                        view_col: 2,
                        view_row: 1,
                        ..
                    }
                ),
                "{e}"
            );
        }
        assert!(v.window(u32::MAX, 0, 2, 1).is_err());
    }

    #[test]
    fn views_of_padded_buffers_are_checked() {
        // 3 × 2 pixels in rows of 5, the last row unpadded.
        let buf = [1u16, 2, 3, 0, 0, 4, 5, 6];
        let v = ImageView::mono16(&buf, 3, 2, 5, 4095).unwrap();
        assert_eq!(
            (v.get(0, 1), v.get(2, 1), v.get(3, 0)),
            (Some(4), Some(6), None)
        );
        let p = v.placed_at(100, 40).unwrap();
        assert_eq!(
            (p.origin(), p.get(102, 41), p.get(2, 1)),
            ((100, 40), Some(6), None)
        );
        assert!(matches!(
            ImageView::mono16(&buf[..7], 3, 2, 5, 4095),
            Err(FrameError::BufferSize {
                need: 8,
                got: 7,
                ..
            })
        ));
        assert!(matches!(
            ImageView::mono8(&[0; 8], 3, 2, 2),
            Err(FrameError::Stride {
                width: 3,
                stride: 2
            })
        ));
        assert!(ImageView::mono8(&[], 0, 2, 2).is_err());
        assert!(v.placed_at(u32::MAX - 1, 0).is_err());
    }
}
