//! From an aravis buffer into a ring slot: one `memcpy` (Mono8) or one
//! widening pass (Mono16, little-endian on the wire), and the count of
//! frames missed between camera frame ids.

use crate::ffi;
use crate::ring::Slot;
use aravis::{Buffer, PixelFormat};
use photopose_frame::{Image, Pixels};

/// Frames missed between camera frame ids `last` and `id`. GigE Vision 1.x
/// block ids are 16-bit and skip 0 on wrap; a smaller id that is not a wrap
/// (a camera that restarted counting) counts as no gap.
pub fn id_gap(last: u64, id: u64) -> u64 {
    if id > last {
        id - last - 1
    } else if last > 0xFF00 && last <= 0xFFFF && id < 0x100 {
        // 16-bit wrap: ids run ..., 0xFFFF, 1, 2, ...
        (0xFFFF - last) + id.saturating_sub(1)
    } else {
        0
    }
}

pub(super) enum Copy {
    Incomplete,
    Format(u32),
}

/// Copies a complete buffer's pixels into `slot` (reallocating its image
/// only if the size or depth differ); returns whether it reallocated.
pub(super) fn copy_frame(buffer: &Buffer, slot: &mut Slot) -> Result<bool, Copy> {
    let width = buffer.image_width().max(0) as u32;
    let height = buffer.image_height().max(0) as u32;
    let format = buffer.image_pixel_format();
    let wide = if format == PixelFormat::MONO_8 {
        false
    } else if format == PixelFormat::MONO_16 {
        true
    } else {
        return Err(Copy::Format(format.raw()));
    };
    let pixels = width as usize * height as usize;
    let bytes = ffi::payload(buffer);
    let need = pixels * if wide { 2 } else { 1 };
    if pixels == 0 || bytes.len() < need {
        return Err(Copy::Incomplete);
    }
    let image = slot.image_mut();
    let fits = image.width() == width
        && image.height() == height
        && matches!(
            (image.pixels(), wide),
            (Pixels::Mono8(_), false) | (Pixels::Mono16(_), true)
        );
    if !fits {
        *image = if wide {
            Image::new_mono16(width, height, u16::MAX)
        } else {
            Image::new_mono8(width, height)
        };
    }
    match image.pixels_mut() {
        Pixels::Mono8(dst) => dst.copy_from_slice(&bytes[..need]),
        Pixels::Mono16(dst) => {
            for (d, s) in dst.iter_mut().zip(bytes[..need].chunks_exact(2)) {
                *d = u16::from_le_bytes([s[0], s[1]]);
            }
        }
    }
    Ok(!fits)
}
