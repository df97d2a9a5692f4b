//! The KUKA integration kit and the simulated controller end to end:
//! `photopose rsi kit` writes XML files that parse (quick-xml) and agree
//! with the daemon's `[rsi]` section in either mode; the daemon runs from
//! the kit's `RSI_EthernetConfig.xml` and `photopose rsi-sim` gets every
//! cycle answered; `rsi-sim` against a port where nothing listens says so,
//! naming the address, and fails.

mod common;

use common::{bin, root, scratch};

use quick_xml::events::Event;
use quick_xml::Reader;
use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// One element of a parsed XML file.
#[derive(Debug)]
struct El {
    name: String,
    attrs: HashMap<String, String>,
    text: String,
}

/// Every element of `xml` in document order (fails the test on bad XML).
fn elements(xml: &str) -> Vec<El> {
    let mut r = Reader::from_str(xml);
    let mut out: Vec<El> = Vec::new();
    let mut open: Vec<usize> = Vec::new();
    loop {
        match r.read_event().expect("well-formed XML") {
            Event::Start(e) => {
                out.push(element(&e));
                open.push(out.len() - 1);
            }
            Event::Empty(e) => out.push(element(&e)),
            Event::End(_) => {
                open.pop();
            }
            Event::Text(t) => {
                if let Some(&i) = open.last() {
                    out[i].text.push_str(t.unescape().unwrap().trim());
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    assert!(open.is_empty(), "unclosed elements");
    out
}

fn element(e: &quick_xml::events::BytesStart<'_>) -> El {
    El {
        name: String::from_utf8(e.name().as_ref().to_vec()).unwrap(),
        attrs: e
            .attributes()
            .map(|a| {
                let a = a.expect("a well-formed attribute");
                (
                    String::from_utf8(a.key.as_ref().to_vec()).unwrap(),
                    a.unescape_value().unwrap().into_owned(),
                )
            })
            .collect(),
        text: String::new(),
    }
}

fn text_of<'e>(els: &'e [El], name: &str) -> &'e str {
    &els.iter()
        .find(|e| e.name == name)
        .unwrap_or_else(|| panic!("no <{name}>"))
        .text
}

fn param(els: &[El], object: &str, name: &str) -> f64 {
    // Parameters follow their RsiObject in document order.
    let start = els
        .iter()
        .position(|e| e.name == "RsiObject" && e.attrs["ObjType"] == object)
        .unwrap_or_else(|| panic!("no {object} object"));
    els[start + 1..]
        .iter()
        .take_while(|e| e.name != "RsiObject")
        .find(|e| e.name == "Parameter" && e.attrs["Name"] == name)
        .unwrap_or_else(|| panic!("no {object} {name}"))
        .attrs["ParamValue"]
        .parse()
        .unwrap()
}

/// A free UDP port on loopback (bound, read, released).
fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The shipped configuration with its outputs on free ports and `rsi`
/// as the `[rsi]` section.
fn daemon_config(rsi: &str) -> String {
    let base = std::fs::read_to_string(root().join("config/photopose.toml")).unwrap();
    let head = &base[..base.find("[rsi]").expect("[rsi] is the last section")];
    let head = head
        .replace(
            "udp = [\"127.0.0.1:5005\"]",
            &format!("udp = [\"127.0.0.1:{}\"]", free_port()),
        )
        .replace(
            "tcp_listen = \"127.0.0.1:5006\"",
            "tcp_listen = \"127.0.0.1:0\"",
        )
        .replace("listen = \"127.0.0.1:9464\"", "listen = \"127.0.0.1:0\"");
    format!(
        "{head}[rsi]\nenabled = true\nbind = \"127.0.0.1\"\ncontrollers = [\"127.0.0.1\"]\nhand_eye = \"{}\"\n{rsi}",
        root().join("config/bench/hand-eye.toml").display()
    )
}

fn kit(config: &Path, out: &Path) {
    let o = bin()
        .args(["rsi", "kit", "--config"])
        .arg(config)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn kit_agrees_with_the_daemon(mode: &str, holdon: &str, ipo: &str) {
    let dir = scratch(&format!("kit-{mode}"));
    let config = dir.join("photopose.toml");
    let port = free_port();
    std::fs::write(
        &config,
        daemon_config(&format!(
            "port = {port}\nsentype = \"PhotoPose\"\nmode = \"{mode}\"\nframe = \"tool\"\n\
             clamp_mm = 3.0\nclamp_deg = 1.5\nposcorr_limit_mm = 4.0\nposcorr_limit_deg = 3.0\n"
        )),
    )
    .unwrap();
    let out = dir.join("kit");
    kit(&config, &out);
    let read = |name: &str| std::fs::read_to_string(out.join(name)).unwrap();

    let eth = elements(&read("RSI_EthernetConfig.xml"));
    assert_eq!(text_of(&eth, "IP_NUMBER"), "127.0.0.1");
    assert_eq!(text_of(&eth, "PORT"), port.to_string());
    assert_eq!(text_of(&eth, "SENTYPE"), "PhotoPose");
    assert_eq!(text_of(&eth, "ONLYSEND"), "FALSE");
    let tags: Vec<(&str, Option<&str>)> = eth
        .iter()
        .filter(|e| e.name == "ELEMENT")
        .map(|e| {
            (
                e.attrs["TAG"].as_str(),
                e.attrs.get("HOLDON").map(String::as_str),
            )
        })
        .collect();
    let mut want: Vec<(&str, Option<&str>)> =
        vec![("DEF_RIst", None), ("DEF_RSol", None), ("DEF_Delay", None)];
    let corr: Vec<String> = ["X", "Y", "Z", "A", "B", "C"]
        .iter()
        .map(|a| format!("RKorr.{a}"))
        .collect();
    want.extend(corr.iter().map(|t| (t.as_str(), Some(holdon))));
    assert_eq!(tags, want);

    let rsix = elements(&read("photopose.rsix"));
    for axis in ["X", "Y", "Z"] {
        assert_eq!(param(&rsix, "PosCorr", &format!("LowerLim{axis}")), -4.0);
        assert_eq!(param(&rsix, "PosCorr", &format!("UpperLim{axis}")), 4.0);
    }
    assert_eq!(param(&rsix, "PosCorr", "MaxRotAngle"), 3.0);
    assert_eq!(param(&rsix, "PosCorr", "RefCorrSys"), 3.0, "Tool");
    // The clamp inside POSCORR, the monitor at or above it.
    let max_trans = param(&rsix, "PosCorrMon", "MaxTrans");
    assert!(max_trans >= 4.0 * 3f64.sqrt() && max_trans < 4.0 * 3f64.sqrt() + 0.01);
    assert!(3.0 * 3f64.sqrt() <= max_trans);
    assert!(param(&rsix, "PosCorrMon", "MaxRotAngle") >= 1.5);
    assert!(1.5 * 3f64.sqrt() <= param(&rsix, "PosCorr", "MaxRotAngle"));
    assert_eq!(
        rsix.iter()
            .find(|e| e.name == "Parameter" && e.attrs["Name"] == "ConfigFile")
            .unwrap()
            .attrs["ParamValue"],
        "RSI_EthernetConfig.xml"
    );

    let src = read("photopose.src");
    assert!(
        src.contains(&format!("RSI_ON(#{}, {ipo})", mode.to_uppercase())),
        "{src}"
    );
    assert!(src.contains("RSI_CREATE(\"photopose.rsix\""), "{src}");
    assert!(read("photopose.dat").contains("DEFDAT photopose"));

    // The daemon takes the kit's file as its ethernet_config, warning-free.
    let from_kit = dir.join("from-kit.toml");
    std::fs::write(
        &from_kit,
        daemon_config(&format!(
            "ethernet_config = \"{}\"\nmode = \"{mode}\"\nframe = \"tool\"\n\
             clamp_mm = 3.0\nclamp_deg = 1.5\nposcorr_limit_mm = 4.0\nposcorr_limit_deg = 3.0\n",
            out.join("RSI_EthernetConfig.xml").display()
        )),
    )
    .unwrap();
    let o = bin()
        .args(["check-config", "--strict"])
        .arg(&from_kit)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn the_kit_agrees_with_a_relative_daemon() {
    kit_agrees_with_the_daemon("relative", "0", "#IPO_FAST");
}

#[test]
fn the_kit_agrees_with_an_absolute_daemon() {
    kit_agrees_with_the_daemon("absolute", "1", "#IPO_FAST");
}

/// The daemon, killed and reaped on drop.
struct Daemon(Child);

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn the_daemon_and_rsi_sim_run_from_the_kit() {
    let dir = scratch("kit-loop");
    let port = free_port();
    let keys = dir.join("keys.toml");
    // 12 ms (#IPO): a wide reply window on a loaded test machine.
    std::fs::write(
        &keys,
        daemon_config(&format!(
            "port = {port}\nsentype = \"PhotoPose\"\ncycle_ms = 12.0\n"
        )),
    )
    .unwrap();
    let out = dir.join("kit");
    kit(&keys, &out);
    let xml: PathBuf = out.join("RSI_EthernetConfig.xml");
    assert!(std::fs::read_to_string(out.join("photopose.src"))
        .unwrap()
        .contains("RSI_ON(#RELATIVE, #IPO)"));
    // Measure-only: the replies are zero, rsi-sim must not call the robot's
    // error a fault.
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        daemon_config(&format!(
            "ethernet_config = \"{}\"\ncycle_ms = 12.0\nmeasure_only = true\n",
            xml.display()
        )),
    )
    .unwrap();
    let mut daemon = Daemon(
        bin()
            .args(["run", "--config"])
            .arg(&config)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    // Wait for the RSI server (its log line), at most 30 s.
    let (tx, rx) = mpsc::channel();
    let stderr = daemon.0.stderr.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut log = String::new();
    loop {
        let line = rx
            .recv_timeout(Duration::from_secs(30))
            .unwrap_or_else(|_| panic!("no RSI server within 30 s:\n{log}"));
        log.push_str(&line);
        log.push('\n');
        if line.contains("RSI server listening on") {
            break;
        }
    }
    let sim = Command::new(env!("CARGO_BIN_EXE_photopose"))
        .args(["rsi-sim", "--server", &format!("127.0.0.1:{port}")])
        .args(["--cycles", "500", "--cycle-ms", "12", "--timeout", "1000"])
        .arg("--ethernet-config")
        .arg(&xml)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&sim.stdout).to_string();
    let err = String::from_utf8_lossy(&sim.stderr).to_string();
    // Stop the daemon: its summary counts the cycles it saw and answered.
    let kill = Command::new("kill")
        .args(["-TERM", &daemon.0.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let t0 = std::time::Instant::now();
    while daemon.0.try_wait().unwrap().is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "the daemon did not stop"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut summary = String::new();
    std::io::Read::read_to_string(&mut daemon.0.stdout.take().unwrap(), &mut summary).unwrap();
    assert!(sim.status.success(), "{said}{err}");
    assert!(said.contains("completed"), "{said}");
    assert!(
        said.contains("no correction applied") && !said.contains("final TCP error"),
        "{said}"
    );
    let sent: u64 = said.split_whitespace().next().unwrap().parse().unwrap();
    assert!(sent > 0, "{said}");
    // Every cycle answered, counted by the daemon (not timing: a reply
    // that arrives after the next cycle on a loaded machine is answered).
    let rsi = summary
        .lines()
        .find(|l| l.starts_with("RSI: "))
        .unwrap_or_else(|| panic!("no RSI summary:\n{summary}"));
    assert!(
        rsi.starts_with(&format!("RSI: {sent} cycles, {sent} replies")),
        "{sent} sent: {rsi}"
    );
    // Timing is not asserted strictly (a shared test machine): a gross
    // failure (over 5 % late) still shows.
    let late: u64 = said
        .split(", ")
        .find(|p| p.ends_with(" late"))
        .and_then(|p| p.split_whitespace().next()?.parse().ok())
        .unwrap();
    assert!(late * 20 <= sent, "{said}");
}

#[test]
fn rsi_sim_says_when_nothing_answers() {
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let o = bin()
        .args([
            "rsi-sim",
            "--server",
            &addr,
            "--cycles",
            "500",
            "--timeout",
            "20",
        ])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success(), "{said}{err}");
    assert!(
        err.contains(&format!("nothing answers at {addr}")),
        "{said}{err}"
    );
    assert!(!said.contains("late"), "{said}");
}

#[test]
fn check_config_strict_refuses_a_controller_file_that_disagrees() {
    let dir = scratch("kit-disagree");
    let keys = dir.join("keys.toml");
    std::fs::write(&keys, daemon_config(&format!("port = {}\n", free_port()))).unwrap();
    let out = dir.join("kit");
    kit(&keys, &out);
    // An integrator's edit: a second, partial correction element and no RSol.
    let xml = std::fs::read_to_string(out.join("RSI_EthernetConfig.xml"))
        .unwrap()
        .replace(
            "</ELEMENTS>\n  </RECEIVE>",
            "<ELEMENT TAG=\"Tech.X\" TYPE=\"DOUBLE\" INDX=\"7\" HOLDON=\"0\"/></ELEMENTS>\n  </RECEIVE>",
        )
        .replace("DEF_RSol", "DEF_Tech.T1");
    let edited = dir.join("edited.xml");
    std::fs::write(&edited, xml).unwrap();
    let config = dir.join("photopose.toml");
    std::fs::write(
        &config,
        daemon_config(&format!("ethernet_config = \"{}\"\n", edited.display())),
    )
    .unwrap();
    let o = bin().args(["check-config"]).arg(&config).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("Tech lacks Y Z A B C"), "{err}");
    assert!(err.contains("no DEF_RSol"), "{err}");
    let o = bin()
        .args(["check-config", "--strict"])
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("2 warning(s) and --strict"), "{err}");
}
