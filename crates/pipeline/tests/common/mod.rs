//! Set-up shared by the pipeline's allocation tests: the daemon's config
//! for the synthetic source sending poses to a loopback UDP socket, the
//! source it names, and a receiver counting the pose datagrams.

// Each test binary uses its own part of this module.
#![allow(dead_code)]

use photopose_field::design::default_plate;
use photopose_field::Field;
use photopose_geometry::Camera;
use photopose_pipeline::config::Source;
use photopose_pipeline::source::SyntheticSource;
use photopose_pipeline::Config;
use std::net::UdpSocket;
use std::time::{Duration, Instant};

/// Poses arrive at a loopback UDP socket; frames never stall.
pub struct Poses {
    rx: UdpSocket,
    buf: [u8; 8192],
}

impl Poses {
    /// A socket on 127.0.0.1 with a 20 s read timeout.
    pub fn bind() -> Poses {
        let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
        rx.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
        Poses { rx, buf: [0; 8192] }
    }

    /// The daemon's config: the synthetic source at `rate_hz` (a 40 mm
    /// circle in 2 s, never ending), two workers over six slots that block
    /// when full, poses by UDP to this socket, then the sections `extra`.
    pub fn config(&self, rate_hz: f64, extra: &str) -> Config {
        Config::parse(
            &format!(
                r#"
[source]
kind = "synthetic"
[source.synthetic]
rate_hz = {rate_hz:?}
frames = 0
radius_mm = 40.0
period_s = 2.0
[pipeline]
workers = 2
slots = 6
overflow = "block"
max_age_ms = 5000.0
[output]
udp = ["{}"]
{extra}"#,
                self.rx.local_addr().unwrap()
            ),
            "test",
        )
        .unwrap()
    }

    /// Waits for `n` pose datagrams (at most a minute); allocates nothing.
    pub fn receive(&mut self, n: usize) {
        let mut got = 0;
        let t0 = Instant::now();
        while got < n {
            assert!(t0.elapsed() < Duration::from_secs(60), "poses stopped");
            if self.rx.recv(&mut self.buf).is_ok() {
                got += 1;
            }
        }
    }
}

/// The shipped default camera, the default plate and the synthetic source
/// of `cfg`.
pub fn synthetic_source(cfg: &Config) -> (Camera, Field, SyntheticSource) {
    let Source::Synthetic(syn) = cfg.source.clone() else {
        panic!("synthetic source expected")
    };
    let camera = photopose_formats::default_camera();
    let field = default_plate();
    let source = SyntheticSource::new(camera, &field, syn).unwrap();
    (camera, field, source)
}
