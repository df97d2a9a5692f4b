//! `photopose camera list` and `photopose camera grab`: the real cell's
//! camera tools. `list` names the cameras the transports find (aravis:
//! GigE Vision and USB3 Vision; the devices of a GenTL producer, the one of
//! `--config`'s `[source.gentl]` or of `GENICAM_GENTL64_PATH`); `grab` takes stills for calibration and hand-eye work
//! through the daemon's own GigE source (same settings, same
//! `[source.gige.features]`) and says per still how well it is exposed:
//! the peak grey value of the detected targets against full scale, and the
//! saturated pixels and targets.

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `photopose camera`.
#[derive(Parser, Debug)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(Subcommand, Debug)]
enum What {
    /// The cameras found: transport, id, vendor, model, serial, address.
    List(ListArgs),
    /// Stills from the camera as PGM files, with the exposure aid per still.
    Grab(GrabArgs),
}

/// Arguments of `photopose camera list`.
#[derive(Parser, Debug)]
pub struct ListArgs {
    /// The daemon's configuration: with `source.kind = "gentl"` the devices
    /// of its producer are listed; without it (or another kind), those of
    /// the producer in `GENICAM_GENTL64_PATH`, if one is there.
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// Arguments of `photopose camera grab`.
#[derive(Parser, Debug)]
pub struct GrabArgs {
    /// Stills to take.
    #[arg(long, default_value_t = 1)]
    pub count: u32,
    /// Folder for the stills (`still-001.pgm`, …; created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// The daemon's configuration: its `[source.gige]` (camera, settings,
    /// features), camera file and field are used.
    #[arg(long, conflicts_with = "device")]
    pub config: Option<PathBuf>,
    /// The camera by device id, address or serial (as `camera list` shows
    /// it), with the default settings; neither this nor `--config`: the
    /// first camera found.
    #[arg(long)]
    pub device: Option<String>,
    /// Seconds to wait for each still.
    #[arg(long, default_value_t = 10.0)]
    pub timeout_s: f64,
}

/// One camera a transport found.
#[derive(Debug, Clone)]
pub struct Found {
    /// The transport (`GigEVision`, `USB3Vision`, …).
    pub transport: String,
    /// The id `[source.gige] camera` and `--device` take.
    pub id: String,
    /// Vendor.
    pub vendor: String,
    /// Model.
    pub model: String,
    /// Serial number.
    pub serial: String,
    /// Address on its transport.
    pub address: String,
}

/// How a transport lists the cameras it finds.
type Lister = fn() -> Vec<Found>;

/// The transports this build can list cameras of, each a function giving
/// what it finds (a GenTL producer goes here once the crate has one).
fn transports() -> Vec<(&'static str, Lister)> {
    #[cfg(feature = "gige")]
    {
        vec![("aravis", aravis_cameras as Lister)]
    }
    #[cfg(not(feature = "gige"))]
    {
        Vec::new()
    }
}

#[cfg(feature = "gige")]
fn aravis_cameras() -> Vec<Found> {
    photopose_acquire::list_cameras()
        .into_iter()
        .map(|c| Found {
            transport: c.protocol,
            id: c.id,
            vendor: c.vendor,
            model: c.model,
            serial: c.serial,
            address: c.address,
        })
        .collect()
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    match args.what {
        What::List(l) => list(l),
        What::Grab(g) => grab(g),
    }
}

/// The devices of the GenTL producer of `config` (`[source.gentl]`, when
/// its source is GenTL) or of `GENICAM_GENTL64_PATH`; `None` when no
/// producer is named or found.
#[cfg(feature = "gentl")]
fn gentl_devices(config: Option<&std::path::Path>) -> Result<Option<(String, Vec<Found>)>> {
    use anyhow::Context;
    use photopose_pipeline::config::Source;
    let named = match config {
        Some(path) => match crate::cmd::run::load(Some(path))?.source {
            Source::Gentl(g) => Some(g.producer),
            _ => None,
        },
        None => None,
    };
    let var = photopose_gentl::PRODUCER_PATH_VAR;
    let producer = match named {
        Some(p) => p,
        None => match std::env::var_os(var) {
            None => return Ok(None),
            Some(search) => photopose_gentl::find_producer(None, Some(&search), var)?,
        },
    };
    let file = producer.file_name().map_or_else(
        || producer.display().to_string(),
        |f| f.to_string_lossy().into_owned(),
    );
    let devices = photopose_gentl::list_devices(&producer)
        .with_context(|| format!("GenTL producer {}", producer.display()))?;
    let found = devices
        .into_iter()
        .map(|d| Found {
            transport: d.transport.unwrap_or_else(|| "GenTL".into()),
            id: d.id,
            vendor: d.vendor.unwrap_or_default(),
            model: d.model.unwrap_or_default(),
            serial: d.serial.unwrap_or_default(),
            address: format!("{file}:{}", d.interface),
        })
        .collect();
    Ok(Some((format!("GenTL {file}"), found)))
}

#[cfg(not(feature = "gentl"))]
fn gentl_devices(_: Option<&std::path::Path>) -> Result<Option<(String, Vec<Found>)>> {
    Ok(None)
}

fn list(args: ListArgs) -> Result<ExitCode> {
    let transports = transports();
    let gentl = gentl_devices(args.config.as_deref())?;
    if transports.is_empty() && gentl.is_none() {
        anyhow::bail!(
            "this build has no camera transport (cargo feature `gige`) and no GenTL producer \
             is named (`--config` with a gentl source, or GENICAM_GENTL64_PATH; feature `gentl`)"
        );
    }
    let mut found: Vec<Found> = transports.iter().flat_map(|(_, list)| list()).collect();
    let mut names: Vec<String> = transports.iter().map(|(n, _)| n.to_string()).collect();
    if let Some((name, devices)) = gentl {
        names.push(name);
        found.extend(devices);
    }
    if found.is_empty() {
        eprintln!("photopose: no camera found ({})", names.join(", "));
        return Ok(ExitCode::from(1));
    }
    let dash = |s: &str| {
        if s.is_empty() {
            "-".to_string()
        } else {
            s.to_string()
        }
    };
    outln!("transport\tid\tvendor\tmodel\tserial\taddress")?;
    for c in &found {
        outln!(
            "{}\t{}\t{}\t{}\t{}\t{}",
            dash(&c.transport),
            dash(&c.id),
            dash(&c.vendor),
            dash(&c.model),
            dash(&c.serial),
            dash(&c.address)
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(not(feature = "gige"))]
fn grab(_: GrabArgs) -> Result<ExitCode> {
    anyhow::bail!("this build has no GigE Vision support (cargo feature `gige`)")
}

#[cfg(feature = "gige")]
fn grab(args: GrabArgs) -> Result<ExitCode> {
    use crate::cmd::{defaults, run};
    use anyhow::Context;
    use photopose_pipeline::config::Source;
    use photopose_pipeline::{FrameSource, Slot, SourceError};
    use std::time::{Duration, Instant};

    if args.count == 0 {
        anyhow::bail!("--count 0: take at least one still");
    }
    if !(args.timeout_s.is_finite() && args.timeout_s > 0.0) {
        anyhow::bail!("--timeout-s {}: must be a positive number", args.timeout_s);
    }
    let (gige, camera_file, field_file) = match &args.config {
        Some(path) => {
            let config = run::load(Some(path))?;
            let Source::Gige(g) = config.source else {
                anyhow::bail!(
                    "{}: `source.kind` is not \"gige\"; camera grab takes stills from a GigE Vision camera",
                    path.display()
                );
            };
            (g, config.camera_file, config.field_file)
        }
        None => (
            photopose_acquire::GigeConfig {
                camera: args.device.clone(),
                ..Default::default()
            },
            None,
            None,
        ),
    };
    let camera = defaults::camera(camera_file.as_deref()).context(run::CAMERA_KEY)?;
    let field = defaults::field(field_file.as_deref()).context(run::FIELD_KEY)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("--out: cannot create {}", args.out.display()))?;
    let mut source =
        photopose_acquire::GigeSource::new("grab", gige).context("GigE source ([source.gige])")?;
    let described = source.describe();
    // Without a camera file the slot takes the size of the first frame.
    let (width, height) = match camera_file {
        Some(_) => (camera.sensor.width, camera.sensor.height),
        None => (0, 0),
    };
    let mut slot = Slot::new(photopose_frame::Image::new_mono8(
        width.max(1),
        height.max(1),
    ));
    let mut detector: Option<photopose_vision::Detector> = None;
    let options = photopose_vision::DetectorOptions::for_field(&field);
    source.start().context("cannot start the camera")?;
    let bar = crate::cmd::progress::bar(Some(u64::from(args.count)), "stills");
    let timeout = Duration::from_secs_f64(args.timeout_s);
    let mut taken = 0u32;
    let result = (|| -> Result<()> {
        while taken < args.count {
            let t0 = Instant::now();
            loop {
                match source.next_frame(&mut slot, Duration::from_millis(200)) {
                    Ok(()) => break,
                    Err(e) if e.is_fatal() => {
                        return Err(e).with_context(|| format!("{described} failed"))
                    }
                    Err(SourceError::Ended) => anyhow::bail!("{described} ended"),
                    Err(e) if t0.elapsed() >= timeout => {
                        return Err(e).with_context(|| {
                            format!(
                                "no frame from {described} in {} s (is it connected? `photopose camera list`)",
                                args.timeout_s
                            )
                        })
                    }
                    Err(_) => {}
                }
            }
            taken += 1;
            let image = slot.image();
            let path = args.out.join(format!("still-{taken:03}.pgm"));
            photopose_formats::image::save_image(&path, image)?;
            let (w, h) = (image.width(), image.height());
            let fits = detector
                .as_ref()
                .is_some_and(|d| d.capacity().0 >= w && d.capacity().1 >= h);
            if !fits {
                detector = Some(
                    photopose_vision::Detector::new(w, h, options)
                        .context("the detector refuses the frame size")?,
                );
            }
            let aid = match detector.as_mut() {
                Some(d) => exposure_aid(image, d.detect(image.view()).ok()),
                None => exposure_aid(image, None),
            };
            let size_note =
                if camera_file.is_some() && (w, h) != (camera.sensor.width, camera.sensor.height) {
                    format!(
                        " (the camera file says {}×{})",
                        camera.sensor.width, camera.sensor.height
                    )
                } else {
                    String::new()
                };
            bar.suspend(|| outln!("{}: {w}×{h}{size_note}, {aid}", path.display()))?;
            bar.inc(1);
        }
        Ok(())
    })();
    bar.finish_and_clear();
    source.stop();
    result?;
    outln!("{}: {taken} stills from {described}", args.out.display())?;
    Ok(ExitCode::SUCCESS)
}

/// The exposure aid of one still: the brightest target's peak against full
/// scale, and how many pixels (inside the targets' boxes) and targets are
/// saturated. Without targets: the frame's own maximum and saturated count.
#[cfg(feature = "gige")]
fn exposure_aid(
    image: &photopose_frame::Image,
    detections: Option<&photopose_vision::Detections>,
) -> String {
    let full = u32::from(image.max_value()).max(1);
    let (w, h) = (image.width(), image.height());
    let percent = |v: u32| 100.0 * f64::from(v) / f64::from(full);
    let targets = detections.map_or(&[][..], |d| &d.targets[..]);
    if targets.is_empty() {
        let mut max = 0u32;
        let mut saturated = 0u64;
        for row in 0..h {
            for col in 0..w {
                let v = u32::from(image.get(col, row));
                max = max.max(v);
                saturated += u64::from(v >= full);
            }
        }
        return format!(
            "no targets detected; frame maximum {max}/{full} ({:.0} %), {saturated} saturated pixels",
            percent(max)
        );
    }
    let peak = targets.iter().map(|t| t.peak).max().unwrap_or(0);
    let mut saturated_pixels = 0u64;
    let mut saturated_targets = 0usize;
    for t in targets {
        if t.peak < full {
            continue;
        }
        saturated_targets += 1;
        let r = t.semi_major.max(1.0) + 2.0;
        let clip = |v: f64, max: u32| v.clamp(0.0, f64::from(max.saturating_sub(1))) as u32;
        for row in clip(t.row - r, h)..=clip(t.row + r, h) {
            for col in clip(t.col - r, w)..=clip(t.col + r, w) {
                saturated_pixels += u64::from(u32::from(image.get(col, row)) >= full);
            }
        }
    }
    format!(
        "{} targets, peak {peak}/{full} ({:.0} %), {saturated_pixels} saturated pixels in {saturated_targets} saturated targets",
        targets.len(),
        percent(peak)
    )
}
