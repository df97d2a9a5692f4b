//! Consistency warnings about an RSI set-up that loads but is probably not
//! what the integrator meant (HOLDON against the correction mode, no `RSol`
//! in the SEND list, a RECEIVE element with part of a correction, an
//! `IP_NUMBER` that is not the bind address, a dual-stack bind): plain data with a `Display`, so
//! `check-config` and `run` report the same list.

use crate::law::CorrectionMode;
use std::fmt;
use std::net::IpAddr;

/// One warning about the `[rsi]` section or the controller's file.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum RsiWarning {
    /// A correction tag of the RECEIVE list whose `HOLDON` does not fit the
    /// mode (absolute needs `HOLDON="1"`, relative `HOLDON="0"`).
    Holdon {
        /// 1-based line in `RSI_EthernetConfig.xml`.
        line: usize,
        /// The tag (`RKorr.X`).
        tag: String,
        /// Its `HOLDON` (`None`: not given).
        holdon: Option<bool>,
        /// The configured mode.
        mode: CorrectionMode,
    },
    /// The SEND list has no `DEF_RSol`: the commanded pose never arrives and
    /// the correction stays frozen (`stale_no_command`).
    NoRsol,
    /// `bind` is the IPv6 wildcard and some controllers are IPv4: their
    /// datagrams arrive as IPv4-mapped addresses only while the system keeps
    /// dual-stack sockets (`net.ipv6.bindv6only = 0`, Linux's default).
    DualStackBind {
        /// The bind address.
        bind: IpAddr,
    },
    /// A RECEIVE element other than the correction that carries some of
    /// `X Y Z A B C` but not all: probably a correction meant to be
    /// complete (the daemon answers it with zeros).
    PartialCorrection {
        /// 1-based line of its first tag.
        line: usize,
        /// The element (`RKorr`).
        element: String,
        /// The attributes it lacks.
        missing: Vec<String>,
    },
    /// The controller file's `IP_NUMBER` (where the controller sends) is
    /// not the address the daemon binds.
    IpNumber {
        /// `IP_NUMBER` as written.
        ip_number: String,
        /// The bind address.
        bind: IpAddr,
    },
}

impl fmt::Display for RsiWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let holdon = |h: Option<bool>| match h {
            Some(true) => "1",
            Some(false) => "0",
            None => "unset",
        };
        match self {
            RsiWarning::Holdon {
                line,
                tag,
                holdon: h,
                mode: CorrectionMode::Absolute,
            } => write!(
                f,
                "RSI_EthernetConfig.xml line {line}: {tag} has HOLDON={}; absolute mode needs HOLDON=\"1\" (one late packet would snap the robot back)",
                holdon(*h)
            ),
            RsiWarning::Holdon {
                line,
                tag,
                holdon: h,
                mode: CorrectionMode::Relative,
            } => write!(
                f,
                "RSI_EthernetConfig.xml line {line}: {tag} has HOLDON={}; relative mode needs HOLDON=\"0\" (a held increment keeps moving the robot)",
                holdon(*h)
            ),
            RsiWarning::NoRsol => f.write_str(
                "RSI_EthernetConfig.xml: SEND list has no DEF_RSol: the commanded pose is unknown, corrections stay frozen",
            ),
            RsiWarning::DualStackBind { bind } => write!(
                f,
                "[rsi] bind = \"{bind}\" with IPv4 controllers: their datagrams arrive only on a dual-stack socket (net.ipv6.bindv6only = 0); bind an IPv4 address to be independent of it"
            ),
            RsiWarning::PartialCorrection {
                line,
                element,
                missing,
            } => write!(
                f,
                "RSI_EthernetConfig.xml line {line}: RECEIVE element {element} lacks {} of the six correction attributes X Y Z A B C: it is answered with zeros, not used as the correction",
                missing.join(" ")
            ),
            RsiWarning::IpNumber { ip_number, bind } => write!(
                f,
                "RSI_EthernetConfig.xml: IP_NUMBER {ip_number} (where the controller sends) is not [rsi] bind = \"{bind}\": the daemon never sees the controller's datagrams"
            ),
        }
    }
}
