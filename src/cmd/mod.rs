//! The subcommands of the `photopose` binary, one module each.

pub mod batch;
pub mod bench;
pub mod calibrate;
pub mod calibrate_camera;
pub mod calibrate_hand_eye;
pub mod calibrate_stations;
pub mod camera;
pub mod circle_test;
pub mod defaults;
pub mod demo;
pub mod detect;
pub mod export;
pub mod field;
pub mod generate;
pub mod input;
pub mod pose_arg;
pub mod progress;
pub mod record;
pub mod render;
pub mod resect;
pub mod rsi_kit;
pub mod rsi_sim;
pub mod run;
pub mod simulate;
