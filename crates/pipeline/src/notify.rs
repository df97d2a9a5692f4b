//! systemd notification (`sd_notify`) without a library: datagrams to the
//! socket named by `$NOTIFY_SOCKET` (`READY=1`, `WATCHDOG=1`, `STATUS=…`,
//! `STOPPING=1`, `RELOADING=1`). Without the variable every call does
//! nothing.

use std::os::unix::net::UnixDatagram;
use std::time::Duration;

/// The watchdog interval systemd asks for (`WATCHDOG_USEC`, for this
/// process when `WATCHDOG_PID` is set), if any.
pub fn watchdog_interval() -> Option<Duration> {
    if let Ok(pid) = std::env::var("WATCHDOG_PID") {
        if pid.trim().parse::<u32>().ok() != Some(std::process::id()) {
            return None;
        }
    }
    let usec: u64 = std::env::var("WATCHDOG_USEC").ok()?.trim().parse().ok()?;
    (usec > 0).then(|| Duration::from_micros(usec))
}

/// A handle on the service manager's notification socket.
#[derive(Debug)]
pub struct Notifier {
    socket: Option<(UnixDatagram, String)>,
}

impl Notifier {
    /// From `$NOTIFY_SOCKET`, if set.
    pub fn from_env() -> Self {
        let socket = std::env::var("NOTIFY_SOCKET").ok().and_then(|path| {
            let s = UnixDatagram::unbound().ok()?;
            Some((s, path))
        });
        Notifier { socket }
    }

    /// To the socket at `path` (`@name`: an abstract socket), whatever the
    /// environment says (tests).
    pub fn to_path(path: impl AsRef<std::path::Path>) -> Self {
        let path = path.as_ref().to_string_lossy().into_owned();
        Notifier {
            socket: UnixDatagram::unbound().ok().map(|s| (s, path)),
        }
    }

    /// Notifications that go nowhere.
    pub fn disabled() -> Self {
        Notifier { socket: None }
    }

    /// Whether notifications go anywhere.
    pub fn enabled(&self) -> bool {
        self.socket.is_some()
    }

    /// Sends one notification (e.g. `"READY=1"`); errors are ignored, as
    /// systemd's own library does.
    pub fn notify(&self, state: &str) {
        let Some((s, path)) = &self.socket else {
            return;
        };
        if let Some(name) = path.strip_prefix('@') {
            use std::os::linux::net::SocketAddrExt;
            if let Ok(addr) = std::os::unix::net::SocketAddr::from_abstract_name(name.as_bytes()) {
                let _ = s.send_to_addr(state.as_bytes(), &addr);
            }
        } else {
            let _ = s.send_to(state.as_bytes(), path);
        }
    }
}
