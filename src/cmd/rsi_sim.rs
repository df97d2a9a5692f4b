//! `photopose rsi-sim --server ADDR`: a simulated KUKA controller
//! (`photopose_rsi::controller`) against a running daemon's RSI server —
//! `<Rob>` every cycle on its own clock, late and mismatched replies counted
//! into `Delay`, stop after `Timeout` faults — for commissioning without a
//! robot and for measuring the daemon's reply timing. Shows its progress on
//! stderr when that is a terminal (a bar; nothing otherwise), then the
//! run's summary. Exit status 1 if nothing ever
//! answered ("nothing answers at ADDR"), if no reply ever matched, or if the
//! simulated controller stopped on `Timeout`. A run whose replies were all
//! zero (the daemon's `measure_only`, or no fresh measurement) says that no
//! correction was applied and reports the robot's path error as measured,
//! not as a fault.

use anyhow::{Context, Result};
use clap::Parser;
use photopose_rsi::controller::{SimConfig, SimController, SimReport};
use photopose_rsi::ethernet_config::EthernetConfig;
use photopose_rsi::server::RsiClock;
use photopose_rsi::CorrectionMode;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

/// Arguments of `photopose rsi-sim`.
#[derive(Parser, Debug)]
pub struct Args {
    /// The daemon's RSI address (`[rsi] bind` and `port`): an IP address
    /// or a host name, and the port (`localhost:49152`).
    #[arg(long)]
    pub server: String,
    /// Cycles to send.
    #[arg(long, default_value_t = 10_000)]
    pub cycles: u64,
    /// Cycle time, ms (4 for `#IPO_FAST`, 12 for `#IPO`).
    #[arg(long, default_value_t = 4.0)]
    pub cycle_ms: f64,
    /// Late or mismatched replies after which the controller stops (its
    /// Ethernet object's `Timeout`).
    #[arg(long, default_value_t = 100)]
    pub timeout: u64,
    /// Correction mode the controller applies: `relative` or `absolute`.
    #[arg(long, default_value = "relative")]
    pub mode: String,
    /// SCHED_FIFO priority of the controller's thread (failure: a warning).
    #[arg(long)]
    pub realtime_priority: Option<u8>,
    /// The controller's `RSI_EthernetConfig.xml` (e.g. the one `photopose
    /// rsi kit` wrote): replies must carry its SENTYPE and correction
    /// element (default: `ImFree`, `RKorr`).
    #[arg(long)]
    pub ethernet_config: Option<PathBuf>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<ExitCode> {
    if !(args.cycle_ms.is_finite() && (1.0..=100.0).contains(&args.cycle_ms)) {
        anyhow::bail!("--cycle-ms {}: must be in [1, 100]", args.cycle_ms);
    }
    let mode = match args.mode.as_str() {
        "relative" => CorrectionMode::Relative,
        "absolute" => CorrectionMode::Absolute,
        other => anyhow::bail!("--mode '{other}': must be relative or absolute"),
    };
    let sen = match &args.ethernet_config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("--ethernet-config: cannot read {}", p.display()))?;
            EthernetConfig::parse(&text)
                .and_then(|e| e.sen_format(4))
                .with_context(|| format!("--ethernet-config {}", p.display()))?
        }
        None => photopose_rsi::SenFormat::default(),
    };
    let server = resolve_server(&args.server)?;
    let defaults = SimConfig::new(server);
    // Loopback servers are reached from loopback; any other from every
    // interface of the family.
    let bind = match server.ip() {
        ip if ip.is_loopback() => defaults.bind,
        IpAddr::V4(_) => SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0)),
        IpAddr::V6(_) => SocketAddr::from((Ipv6Addr::UNSPECIFIED, 0)),
    };
    let config = SimConfig {
        cycles: args.cycles,
        cycle: Duration::from_secs_f64(args.cycle_ms / 1000.0),
        timeout: args.timeout,
        mode,
        realtime_priority: args.realtime_priority,
        bind,
        sen,
        ..defaults
    };
    let controller = SimController::spawn(config, RsiClock::new())
        .with_context(|| format!("cannot start the simulated controller for {server}"))?;
    // Live progress on stderr (a terminal only): cycles done and the
    // correction the controller is applying.
    // Only when shown: reading the state clones the controller's record
    // under its lock, which the controller's own cycle then waits for.
    let bar = crate::cmd::progress::bar(Some(args.cycles), "cycles");
    let probe = controller.probe();
    while crate::cmd::progress::shown() && !probe.is_finished() {
        let s = probe.state();
        let t = &s.total;
        bar.set_position(s.cycle);
        bar.set_message(format!(
            "correction {:.4} {:.4} {:.4} mm {:.5} {:.5} {:.5}°",
            t[0], t[1], t[2], t[3], t[4], t[5]
        ));
        std::thread::sleep(Duration::from_millis(100));
    }
    bar.finish_and_clear();
    let r = controller
        .join()
        .context("the simulated controller failed")?;
    let (line, code) = outcome(&r, server);
    match code {
        0 => outln!("{line}")?,
        _ => eprintln!("photopose: error: {line}"),
    }
    Ok(ExitCode::from(code))
}

/// `--server`: an IP address with its port, or a host name with its port
/// resolved now (its IPv4 address if it has one); the error names the flag.
fn resolve_server(text: &str) -> Result<SocketAddr> {
    use std::net::ToSocketAddrs;
    if let Ok(a) = text.parse::<SocketAddr>() {
        return Ok(a);
    }
    let found: Vec<SocketAddr> = text
        .to_socket_addrs()
        .with_context(|| {
            format!("--server \"{text}\": not host:port, or the host does not resolve")
        })?
        .collect();
    found
        .iter()
        .find(|a| a.is_ipv4())
        .or(found.first())
        .copied()
        .with_context(|| format!("--server \"{text}\": the name resolves to no address"))
}

/// The run's summary line and exit status.
fn outcome(r: &SimReport, server: SocketAddr) -> (String, u8) {
    let answered = r.cycles - r.late;
    if answered == 0 && r.mismatched == 0 {
        return (
            format!(
                "nothing answers at {server}: no reply in {} cycles (is `photopose run` up with [rsi] enabled on this address and port, and this host in [rsi] controllers?)",
                r.cycles
            ),
            1,
        );
    }
    if answered == 0 {
        return (
            format!(
                "{server} answers, but no reply matched ({} mismatched of {} cycles): its SENTYPE, correction element or IPOC is not what this controller expects (give --ethernet-config)",
                r.mismatched, r.cycles
            ),
            1,
        );
    }
    let last = r.errors.last().copied().unwrap_or((f64::NAN, f64::NAN));
    let counts = format!(
        "{} cycles ({} skipped by the simulator), {answered} answered, {} late, {} mismatched, Delay {}, {}",
        r.cycles,
        r.skipped,
        r.late,
        r.mismatched,
        r.delay,
        if r.stopped_by_timeout {
            "stopped on Timeout"
        } else {
            "completed"
        },
    );
    let applied = r.max_total.iter().any(|c| *c != 0.0);
    let result = if applied {
        format!(
            "final TCP error {:.4} mm / {:.5}° (robot against the programmed pose, corrected)",
            last.0, last.1
        )
    } else {
        format!(
            "no correction applied (every reply was zero: measure_only, or no fresh measurement); the robot's path error measured {:.4} mm / {:.5}°",
            last.0, last.1
        )
    };
    (
        format!("{counts}; {result}"),
        u8::from(r.stopped_by_timeout),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(cycles: u64, late: u64, mismatched: u64, total: f64) -> SimReport {
        SimReport {
            cycles,
            late,
            mismatched,
            delay: late + mismatched,
            errors: vec![(1.0, 0.05)],
            max_total: [total, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..SimReport::default()
        }
    }

    #[test]
    fn the_outcome_names_what_happened() {
        let at: SocketAddr = "127.0.0.1:4000".parse().unwrap();
        let (line, code) = outcome(&report(101, 101, 0, 0.0), at);
        assert_eq!(code, 1);
        assert!(
            line.starts_with("nothing answers at 127.0.0.1:4000"),
            "{line}"
        );
        let (line, code) = outcome(&report(101, 101, 101, 0.0), at);
        assert_eq!(code, 1);
        assert!(line.contains("no reply matched"), "{line}");
        let (line, code) = outcome(&report(500, 0, 0, 0.0), at);
        assert_eq!(code, 0);
        assert!(
            line.contains("no correction applied") && line.contains("path error measured"),
            "{line}"
        );
        assert!(!line.contains("final TCP error"), "{line}");
        let (line, code) = outcome(&report(500, 2, 0, 0.3), at);
        assert_eq!(code, 0);
        assert!(
            line.starts_with("500 cycles")
                && line.contains(", 2 late,")
                && line.contains("completed"),
            "{line}"
        );
        assert!(line.contains("final TCP error"), "{line}");
    }
}
