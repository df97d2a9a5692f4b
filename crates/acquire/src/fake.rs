//! Test support: an in-process GigE Vision fake camera (aravis'
//! `GvFakeCamera`, bound to 127.0.0.1) that serves a given Mono8 image in
//! every frame over the real GigE Vision protocol, so that tests can put
//! rendered plates through the real [`GigeSource`](crate::GigeSource).
//!
//! ```no_run
//! use photopose_acquire::fake::FakeGigeCamera;
//! use photopose_frame::Image;
//! let image = Image::new_mono8(320, 240);
//! let camera = FakeGigeCamera::start("RENDER01", &image).unwrap();
//! // open it with GigeConfig { camera: Some(camera.serial().into()), .. }
//! // and swap the served image at any time:
//! camera.set_image(&image).unwrap();
//! ```
//!
//! Only one GigE Vision camera can answer on 127.0.0.1 at a time: it
//! conflicts with an external `arv-fake-gv-camera-0.8 -i 127.0.0.1`, and
//! tests using either must not run concurrently. The camera's sensor size
//! is set to the image's; a client that sets another region gets the
//! image's first `width * height` bytes.

use crate::ffi;
use photopose_frame::{Image, Pixels};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};
use thiserror::Error;

/// Why the fake camera cannot serve.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum FakeError {
    /// Only 8-bit images can be served.
    #[error("the fake camera serves Mono8 images only")]
    NotMono8,
    /// The image differs in size from the one the camera was started with.
    #[error("image is {}×{} px, the camera serves {}×{} px", got.0, got.1, want.0, want.1)]
    Size {
        /// Camera's (width, height).
        want: (u32, u32),
        /// Image's (width, height).
        got: (u32, u32),
    },
    /// The camera did not start listening (address in use?).
    #[error("fake camera {serial} is not listening on 127.0.0.1 (is another one running?)")]
    NotRunning {
        /// Its serial number.
        serial: String,
    },
}

/// A running in-process GigE Vision fake camera serving a given image.
pub struct FakeGigeCamera {
    // Field order matters: the camera (and its thread, which calls the fill
    // callback) is dropped before the callback's data.
    camera: Option<aravis::GvFakeCamera>,
    fill: Option<ffi::FillGuard>,
    bytes: Arc<Mutex<Vec<u8>>>,
    serial: String,
    size: (u32, u32),
}

impl std::fmt::Debug for FakeGigeCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FakeGigeCamera")
            .field("serial", &self.serial)
            .field("size", &self.size)
            .finish()
    }
}

fn mono8(image: &Image) -> Result<&[u8], FakeError> {
    match image.pixels() {
        Pixels::Mono8(v) => Ok(v),
        Pixels::Mono16(_) => Err(FakeError::NotMono8),
    }
}

impl FakeGigeCamera {
    /// Starts a fake camera with serial number `serial` on 127.0.0.1,
    /// sensor sized to `image`, serving `image` in every frame.
    pub fn start(serial: &str, image: &Image) -> Result<Self, FakeError> {
        let bytes = Arc::new(Mutex::new(mono8(image)?.to_vec()));
        let camera = aravis::GvFakeCamera::new(Some("127.0.0.1"), Some(serial));
        let fake = camera.fake_camera().ok_or_else(|| FakeError::NotRunning {
            serial: serial.into(),
        })?;
        fake.write_register(
            aravis_sys::ARV_FAKE_CAMERA_REGISTER_WIDTH as u32,
            image.width(),
        );
        fake.write_register(
            aravis_sys::ARV_FAKE_CAMERA_REGISTER_HEIGHT as u32,
            image.height(),
        );
        let fill = ffi::set_fill(&fake, Arc::clone(&bytes));
        let mut me = FakeGigeCamera {
            camera: Some(camera),
            fill: Some(fill),
            bytes,
            serial: serial.into(),
            size: (image.width(), image.height()),
        };
        let t0 = Instant::now();
        while !me.is_running() {
            if t0.elapsed() > Duration::from_secs(2) {
                me.shutdown();
                return Err(FakeError::NotRunning {
                    serial: serial.into(),
                });
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        Ok(me)
    }

    /// Serves `image` from the next frame on.
    pub fn set_image(&self, image: &Image) -> Result<(), FakeError> {
        let got = (image.width(), image.height());
        if got != self.size {
            return Err(FakeError::Size {
                want: self.size,
                got,
            });
        }
        let src = mono8(image)?;
        let mut dst = self.bytes.lock().unwrap_or_else(PoisonError::into_inner);
        dst.copy_from_slice(src);
        Ok(())
    }

    /// The exposure time the camera holds now (its `ExposureTimeAbs`, as
    /// a client last set it), µs, read from its register: what an
    /// exposure control loop wrote.
    pub fn exposure_us(&self) -> Option<u32> {
        self.camera
            .as_ref()?
            .fake_camera()?
            .read_register(aravis_sys::ARV_FAKE_CAMERA_REGISTER_EXPOSURE_TIME_US as u32)
    }

    /// The camera's serial number (open it by this).
    pub fn serial(&self) -> &str {
        &self.serial
    }

    /// Whether it listens on 127.0.0.1.
    pub fn is_running(&self) -> bool {
        self.camera.as_ref().is_some_and(|c| c.is_running())
    }

    fn shutdown(&mut self) {
        // Camera first: its thread calls the fill callback.
        self.camera = None;
        self.fill = None;
    }
}

impl Drop for FakeGigeCamera {
    fn drop(&mut self) {
        self.shutdown();
    }
}
