//! The controller session: which datagrams advance the RSI cycle. Pure
//! (time passed in as seconds), allocation-free.
//!
//! The rule:
//! - the first valid `<Rob>` from a listed address opens the session and
//!   fixes its address *and* port;
//! - a cycle is a datagram from the session's address and port whose IPOC is
//!   larger than the last one: only such a datagram moves the correction,
//!   at most one step per cycle;
//! - the IPOC just answered, again from the session's port, is a repeat: it
//!   may be answered with the same reply (never a new step);
//! - a smaller IPOC from the session's port is old and dropped;
//! - a datagram from another port (or another listed address) is dropped
//!   while the session is live;
//! - once the session has not advanced for the idle time (`session_idle_ms`,
//!   the controller stopped or restarted RSI), a valid datagram from another
//!   port or with a smaller IPOC restarts the session: it becomes the new
//!   session, and the correction starts again from zero (a restarted RSI
//!   object starts with zero correction).
//!
//! Addresses are compared in canonical form (an IPv4-mapped IPv6 address is
//! its IPv4 address).

use std::net::SocketAddr;

/// What a datagram from a listed address means for the session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// The first valid datagram: opens the session (a cycle).
    Open,
    /// A larger IPOC from the session's address and port: a new cycle.
    Advance,
    /// The last IPOC again from the session's port: answer unchanged.
    Repeat,
    /// A smaller IPOC from the session's port while it is live: dropped.
    Older,
    /// Another port or address while the session is live: dropped.
    Foreign,
    /// After the idle time, another port or a smaller IPOC: a new session
    /// (a cycle; the correction restarts from zero).
    Restart,
}

impl Verdict {
    /// The datagram is a cycle: the law runs and the reply is new.
    pub fn advances(self) -> bool {
        matches!(self, Verdict::Open | Verdict::Advance | Verdict::Restart)
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Peer {
    addr: SocketAddr,
    last_ipoc: u64,
    last_advance_s: f64,
}

/// The session state.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    idle_s: f64,
    peer: Option<Peer>,
}

fn canonical(a: SocketAddr) -> SocketAddr {
    SocketAddr::new(a.ip().to_canonical(), a.port())
}

impl Session {
    /// No session yet; `idle_s` is the silence after which it may restart.
    pub fn new(idle_s: f64) -> Session {
        Session { idle_s, peer: None }
    }

    /// The session's address (canonical), once open.
    pub fn peer(&self) -> Option<SocketAddr> {
        self.peer.map(|p| p.addr)
    }

    /// The last IPOC that advanced the cycle.
    pub fn last_ipoc(&self) -> Option<u64> {
        self.peer.map(|p| p.last_ipoc)
    }

    fn idle(&self, p: &Peer, now_s: f64) -> bool {
        // A clock that went backwards (or NaN) never counts as idle.
        now_s - p.last_advance_s >= self.idle_s
    }

    /// A datagram from `from` is dropped whatever it holds (another port
    /// while the session is live): it need not be parsed.
    pub fn is_foreign(&self, from: SocketAddr, now_s: f64) -> bool {
        match &self.peer {
            Some(p) => p.addr != canonical(from) && !self.idle(p, now_s),
            None => false,
        }
    }

    /// What a valid datagram with `ipoc` from `from` at `now_s` means
    /// (nothing changes until [`Session::commit`]).
    pub fn classify(&self, from: SocketAddr, ipoc: u64, now_s: f64) -> Verdict {
        let Some(p) = &self.peer else {
            return Verdict::Open;
        };
        let idle = self.idle(p, now_s);
        if p.addr != canonical(from) {
            return if idle {
                Verdict::Restart
            } else {
                Verdict::Foreign
            };
        }
        match ipoc.cmp(&p.last_ipoc) {
            std::cmp::Ordering::Greater => Verdict::Advance,
            std::cmp::Ordering::Equal => Verdict::Repeat,
            std::cmp::Ordering::Less if idle => Verdict::Restart,
            std::cmp::Ordering::Less => Verdict::Older,
        }
    }

    /// Records a datagram whose verdict [advances](Verdict::advances).
    pub fn commit(&mut self, from: SocketAddr, ipoc: u64, now_s: f64) {
        self.peer = Some(Peer {
            addr: canonical(from),
            last_ipoc: ipoc,
            last_advance_s: now_s,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn a(s: &str) -> SocketAddr {
        s.parse().unwrap()
    }

    #[test]
    fn the_rule() {
        let mut s = Session::new(0.1);
        let ctl = a("10.0.0.2:6000");
        assert_eq!(s.classify(ctl, 100, 0.0), Verdict::Open);
        s.commit(ctl, 100, 0.0);
        assert_eq!(s.classify(ctl, 104, 0.004), Verdict::Advance);
        assert_eq!(s.classify(ctl, 100, 0.004), Verdict::Repeat);
        assert_eq!(s.classify(ctl, 96, 0.004), Verdict::Older);
        // Another port, the same address: dropped while live, unparsed.
        let other = a("10.0.0.2:6001");
        assert!(s.is_foreign(other, 0.05));
        assert_eq!(s.classify(other, 1_000_000, 0.05), Verdict::Foreign);
        // IPv4-mapped is the same address.
        assert!(!s.is_foreign(a("[::ffff:10.0.0.2]:6000"), 0.05));
        assert_eq!(
            s.classify(a("[::ffff:10.0.0.2]:6000"), 104, 0.05),
            Verdict::Advance
        );
        // After the idle time: another port or a smaller IPOC restarts.
        assert!(!s.is_foreign(other, 0.1));
        assert_eq!(s.classify(other, 5, 0.1), Verdict::Restart);
        assert_eq!(s.classify(ctl, 5, 0.1), Verdict::Restart);
        assert_eq!(s.classify(ctl, 104, 0.1), Verdict::Advance);
        s.commit(other, 5, 0.1);
        assert_eq!(s.peer(), Some(other));
        assert_eq!(s.last_ipoc(), Some(5));
        assert!(s.is_foreign(ctl, 0.15));
        // A clock that is not a number never makes a session idle.
        assert!(s.is_foreign(ctl, f64::NAN));
    }
}
