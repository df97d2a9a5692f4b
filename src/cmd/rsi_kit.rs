//! `photopose rsi kit [--config FILE] --out DIR`: writes the KUKA
//! integration kit (`photopose_rsi::kit`) for the daemon's `[rsi]` section —
//! `RSI_EthernetConfig.xml`, the RSI context `photopose.rsix` and the KRL
//! program `photopose.src`/`.dat` — into DIR, and prints what the
//! integrator must still adapt.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use photopose_rsi::kit::{self, KitOptions};
use photopose_rsi::RsiConfig;
use std::net::IpAddr;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `photopose rsi`.
#[derive(Parser, Debug)]
pub struct Args {
    #[command(subcommand)]
    command: RsiCommand,
}

#[derive(Subcommand, Debug)]
enum RsiCommand {
    /// The controller-side files (KRL program, RSI context,
    /// RSI_EthernetConfig.xml) that match the daemon's configuration.
    Kit(KitArgs),
}

/// Arguments of `photopose rsi kit`.
#[derive(Parser, Debug)]
pub struct KitArgs {
    /// The daemon's configuration file (default: the built-in one).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Folder to write the files into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// The sensor PC's address as the controller reaches it (IP_NUMBER);
    /// needed when `[rsi] bind` is 0.0.0.0 or ::.
    #[arg(long)]
    pub sensor_ip: Option<IpAddr>,
    /// Late replies the controller tolerates before RSI stops (the
    /// ETHERNET object's Timeout).
    #[arg(long, default_value_t = 100)]
    pub timeout: u32,
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    match args.command {
        RsiCommand::Kit(a) => kit(a),
    }
}

fn kit(args: KitArgs) -> Result<ExitCode> {
    let (text, origin) = match &args.config {
        Some(p) => (
            std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?,
            p.display().to_string(),
        ),
        None => (
            crate::cmd::run::DEFAULT_CONFIG.to_string(),
            "the built-in configuration".to_string(),
        ),
    };
    let config = RsiConfig::from_toml(&text).with_context(|| origin.clone())?;
    let xml = match &config.ethernet_config {
        // Read as the daemon reads it (same size limit, same errors).
        Some(p) => Some(
            photopose_formats::read_text(p, photopose_formats::FileKind::ControllerFile)
                .with_context(|| format!("{origin}: [rsi] ethernet_config"))?,
        ),
        None => None,
    };
    let options = KitOptions {
        sensor_ip: args.sensor_ip,
        timeout: args.timeout,
        origin: origin.clone(),
    };
    let kit = kit::generate(&config, xml.as_deref(), &options).with_context(|| origin.clone())?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    for f in &kit.files {
        let path = args.out.join(f.name);
        std::fs::write(&path, &f.text)
            .with_context(|| format!("cannot write {}", path.display()))?;
        outln!("wrote {}", path.display())?;
    }
    let l = kit.limits;
    outln!(
        "POSCORR ±{} mm, MaxRotAngle {}°; POSCORRMON MaxTrans {} mm, MaxRotAngle {}°",
        l.poscorr_mm,
        l.poscorr_deg,
        l.monitor_mm,
        l.monitor_deg
    )?;
    for n in &kit.notes {
        eprintln!("photopose: note: {n}");
    }
    outln!("next: copy the files to the controller (docs/rsi.md, \"The integration kit\")")?;
    Ok(ExitCode::SUCCESS)
}
