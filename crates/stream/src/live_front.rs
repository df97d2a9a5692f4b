//! The live view's front door: the public listener of `[live]`. It bounds
//! the number of clients, and it accepts the Foxglove WebSocket protocol
//! under both of its names before handing each connection to the `foxglove`
//! crate's server, which listens on the loopback only.
//!
//! The protocol was published as `foxglove.websocket.v1`; the Foxglove SDK
//! (and so the `foxglove` crate) speaks the same protocol under the name
//! `foxglove.sdk.v1` and refuses the old name at the handshake. Clients in
//! the field still offer only the old name (Lichtblick, older Foxglove
//! Studio releases, ws-protocol based tools). For such a client the front
//! door offers the server the current name and answers the client with the
//! name it asked for; every byte after the handshake is passed through
//! unchanged. A client that offers the current name is passed through
//! as it is.
//!
//! Resources are bounded by configuration, not by clients: at most
//! `max_clients` connections are served (one more is answered `503` and
//! closed), a handshake head larger than [`HEAD_LIMIT`] or slower than
//! [`HEAD_TIMEOUT`] is refused, and every connection ends when the edge
//! stops.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio_util::sync::CancellationToken;

/// The protocol's name as published first.
pub const LEGACY_SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// The same protocol's name in the Foxglove SDK.
pub const SDK_SUBPROTOCOL: &str = "foxglove.sdk.v1";
/// Largest handshake head (request or response), bytes.
pub const HEAD_LIMIT: usize = 16 * 1024;
/// Longest time a handshake head may take to arrive.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(5);

/// What the front door did to a request head.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Request {
    /// Forward unchanged.
    Pass,
    /// The client offered only the legacy name: forward this head (the
    /// current name offered instead) and rename the answer.
    Renamed(Vec<u8>),
}

/// The end of an HTTP head (`\r\n\r\n`) in `buf`, as the length of the head.
fn head_end(buf: &[u8]) -> Option<usize> {
    buf.windows(4).position(|w| w == b"\r\n\r\n").map(|p| p + 4)
}

/// The value of the `Sec-WebSocket-Protocol` line, and the line's byte
/// range in `head`.
fn protocol_line(head: &[u8]) -> Option<(std::ops::Range<usize>, &str)> {
    let mut at = 0;
    for line in head.split_inclusive(|&b| b == b'\n') {
        let start = at;
        at += line.len();
        let text = std::str::from_utf8(line)
            .ok()?
            .trim_end_matches(['\r', '\n']);
        if let Some((name, value)) = text.split_once(':') {
            if name.trim().eq_ignore_ascii_case("sec-websocket-protocol") {
                return Some((start..at, value.trim()));
            }
        }
    }
    None
}

/// `head` with its `Sec-WebSocket-Protocol` line (at `line`) naming
/// `protocol` instead.
fn with_protocol(head: &[u8], line: std::ops::Range<usize>, protocol: &str) -> Vec<u8> {
    let mut out = Vec::with_capacity(head.len() + 8);
    out.extend_from_slice(&head[..line.start]);
    out.extend_from_slice(format!("Sec-WebSocket-Protocol: {protocol}\r\n").as_bytes());
    out.extend_from_slice(&head[line.end..]);
    out
}

/// Looks at a client's request head: a client offering the legacy name and
/// not the current one gets its offer renamed.
pub(crate) fn rewrite_request(head: &[u8]) -> Request {
    let Some((range, value)) = protocol_line(head) else {
        return Request::Pass;
    };
    let offers: Vec<&str> = value.split(',').map(str::trim).collect();
    let current = offers.iter().any(|p| p.starts_with("foxglove.sdk."));
    if current || !offers.contains(&LEGACY_SUBPROTOCOL) {
        return Request::Pass;
    }
    Request::Renamed(with_protocol(head, range, SDK_SUBPROTOCOL))
}

/// The server's answer to a renamed request, answered with the name the
/// client offered.
pub(crate) fn rewrite_response(head: &[u8]) -> Vec<u8> {
    match protocol_line(head) {
        Some((range, value)) if value == SDK_SUBPROTOCOL => {
            with_protocol(head, range, LEGACY_SUBPROTOCOL)
        }
        _ => head.to_vec(),
    }
}

/// Reads up to the end of an HTTP head into `buf`; what came after the
/// head stays in `buf` behind it. `None`: closed, too large or too slow.
async fn read_head(stream: &mut TcpStream, buf: &mut Vec<u8>) -> Option<usize> {
    let read = async {
        let mut chunk = [0u8; 2048];
        loop {
            if let Some(end) = head_end(buf) {
                return Some(end);
            }
            if buf.len() >= HEAD_LIMIT {
                return None;
            }
            let n = stream.read(&mut chunk).await.ok()?;
            if n == 0 {
                return None;
            }
            buf.extend_from_slice(&chunk[..n]);
        }
    };
    tokio::time::timeout(HEAD_TIMEOUT, read)
        .await
        .ok()
        .flatten()
}

/// Counters of the front door.
#[derive(Debug, Default)]
pub struct FrontStats {
    /// Connections being served now.
    pub active: AtomicUsize,
    /// Connections refused because `max_clients` were served.
    pub refused: AtomicUsize,
    /// Handshakes renamed from the legacy subprotocol name.
    pub renamed: AtomicUsize,
}

/// Serves `listener` until `stop`: each connection (at most `max_clients`
/// at once) is forwarded to the server at `inner`.
pub(crate) async fn serve(
    listener: TcpListener,
    inner: SocketAddr,
    max_clients: usize,
    stats: Arc<FrontStats>,
    stop: CancellationToken,
) {
    loop {
        let accepted = tokio::select! {
            _ = stop.cancelled() => return,
            a = listener.accept() => a,
        };
        let Ok((mut client, _)) = accepted else {
            // Out of descriptors or a connection reset before accept: go on
            // after a breath rather than spin.
            tokio::time::sleep(Duration::from_millis(50)).await;
            continue;
        };
        if stats.active.load(Ordering::Relaxed) >= max_clients {
            stats.refused.fetch_add(1, Ordering::Relaxed);
            tokio::spawn(async move {
                let _ = client
                    .write_all(
                        b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
                    )
                    .await;
                let _ = client.shutdown().await;
            });
            continue;
        }
        stats.active.fetch_add(1, Ordering::Relaxed);
        let stats = stats.clone();
        let stop = stop.clone();
        tokio::spawn(async move {
            tokio::select! {
                _ = stop.cancelled() => {}
                _ = forward(client, inner, &stats) => {}
            }
            stats.active.fetch_sub(1, Ordering::Relaxed);
        });
    }
}

/// One connection: the handshake (renamed if needed), then both directions
/// passed through until either side closes.
async fn forward(mut client: TcpStream, inner: SocketAddr, stats: &FrontStats) {
    let mut head = Vec::with_capacity(1024);
    let Some(end) = read_head(&mut client, &mut head).await else {
        return;
    };
    let mut server = match TcpStream::connect(inner).await {
        Ok(s) => s,
        Err(_) => {
            let _ = client
                .write_all(
                    b"HTTP/1.1 502 Bad Gateway\r\nContent-Length: 0\r\nConnection: close\r\n\r\n",
                )
                .await;
            return;
        }
    };
    let renamed = match rewrite_request(&head[..end]) {
        Request::Pass => false,
        Request::Renamed(request) => {
            stats.renamed.fetch_add(1, Ordering::Relaxed);
            let mut whole = request;
            whole.extend_from_slice(&head[end..]);
            head = whole;
            true
        }
    };
    if server.write_all(&head).await.is_err() {
        return;
    }
    if renamed {
        let mut answer = Vec::with_capacity(512);
        let Some(end) = read_head(&mut server, &mut answer).await else {
            return;
        };
        let mut out = rewrite_response(&answer[..end]);
        out.extend_from_slice(&answer[end..]);
        if client.write_all(&out).await.is_err() {
            return;
        }
    }
    let _ = tokio::io::copy_bidirectional(&mut client, &mut server).await;
}

#[cfg(test)]
mod tests {
    use super::*;

    const REQUEST: &str = "GET / HTTP/1.1\r\nHost: 127.0.0.1:8765\r\nUpgrade: websocket\r\n\
        Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\
        Sec-WebSocket-Version: 13\r\nsec-websocket-protocol: foxglove.websocket.v1\r\n\r\n";

    #[test]
    fn a_legacy_offer_is_renamed_and_nothing_else_changes() {
        let Request::Renamed(out) = rewrite_request(REQUEST.as_bytes()) else {
            panic!("not renamed");
        };
        let out = String::from_utf8(out).unwrap();
        assert_eq!(
            out,
            REQUEST.replace(
                "sec-websocket-protocol: foxglove.websocket.v1",
                "Sec-WebSocket-Protocol: foxglove.sdk.v1"
            )
        );
    }

    #[test]
    fn current_names_other_protocols_and_no_offer_pass() {
        for offer in [
            "foxglove.websocket.v1, foxglove.sdk.v1",
            "foxglove.sdk.v1.1",
            "something.else",
        ] {
            let head = REQUEST.replace("foxglove.websocket.v1", offer);
            assert_eq!(rewrite_request(head.as_bytes()), Request::Pass, "{offer}");
        }
        let none = "GET / HTTP/1.1\r\nHost: x\r\n\r\n";
        assert_eq!(rewrite_request(none.as_bytes()), Request::Pass);
    }

    #[test]
    fn the_answer_names_the_protocol_the_client_offered() {
        let answer = "HTTP/1.1 101 Switching Protocols\r\nupgrade: websocket\r\n\
            sec-websocket-protocol: foxglove.sdk.v1\r\nconnection: Upgrade\r\n\r\n";
        let out = String::from_utf8(rewrite_response(answer.as_bytes())).unwrap();
        assert!(out.contains("Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n"));
        assert!(out.starts_with("HTTP/1.1 101 Switching Protocols\r\n"));
        assert!(out.ends_with("connection: Upgrade\r\n\r\n"));
        // A refusal has no protocol line and passes unchanged.
        let refusal = "HTTP/1.1 400 Bad Request\r\n\r\n";
        assert_eq!(rewrite_response(refusal.as_bytes()), refusal.as_bytes());
    }

    #[test]
    fn the_head_ends_at_the_blank_line() {
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n\r\nrest"), Some(18));
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n"), None);
    }
}
