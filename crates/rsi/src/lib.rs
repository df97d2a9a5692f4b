//! photopose-rsi: the sensor side of KUKA's Robot Sensor Interface (RSI,
//! Ethernet object): the `<Rob>`/`<Sen>` codec, the controller's
//! `RSI_EthernetConfig.xml`, the correction law from camera pose to TCP
//! correction, the lock-free latest-measurement slot the vision side
//! publishes into, the UDP server thread that answers every cycle, and a
//! simulated controller for tests and demos.
//!
//! Pure modules (no IO, no clocks, no threads): [`xml`], [`codec`],
//! [`ethernet_config`], [`config`], [`warning`], [`law`], [`session`],
//! [`kit`] (the controller-side files for a configuration).
//! Concurrency: [`slot`], [`tap`]. IO: [`server`], [`monitor`] (its counters),
//! [`controller`].

pub mod codec;
pub mod config;
pub mod controller;
pub mod ethernet_config;
pub mod kit;
pub mod law;
pub mod monitor;
pub mod server;
pub mod session;
pub mod slot;
pub mod tap;
pub mod warning;
pub mod xml;

pub use codec::{parse_rob, CodecError, Ipoc, Pose6, RobFrame, SenFormat};
pub use config::{ConfigError, RsiConfig, RsiSettings};
pub use law::{
    CorrFrame, CorrectionLaw, CorrectionMode, HandEye, LawConfig, LawStatus, Measurement,
};
pub use slot::{latest_slot, SlotPublisher, SlotReader};
pub use warning::RsiWarning;
