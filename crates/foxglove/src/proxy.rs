//! The live view's front door: a TCP relay at the user's address in front of the foxglove
//! SDK's WebSocket server, which takes one name of the protocol only.
//!
//! The Foxglove WebSocket protocol (`ws-protocol`) is spoken under the subprotocol name
//! `foxglove.websocket.v1` by Foxglove's app, PlotJuggler's Foxglove bridge plugin and the
//! protocol's own clients; the foxglove SDK (0.30) speaks the same messages under
//! `foxglove.sdk.v1` and refuses any other name (HTTP 400). The relay reads the client's
//! opening handshake, offers `foxglove.sdk.v1` for `foxglove.websocket.v1`, gives the answer
//! back under the name the client asked for, and from then on copies bytes both ways
//! untouched: the frames do not depend on the name. A client that asks `foxglove.sdk.v1`
//! (or anything else) is relayed as it asked.
//!
//! Each connection has two copying threads; a viewer that stops reading stalls only its own
//! (the SDK drops what its queue cannot hold), one that vanishes ends them.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// The protocol's name as its clients ask for it.
pub const WEBSOCKET_V1: &str = "foxglove.websocket.v1";
/// The same protocol's name in the foxglove SDK.
pub const SDK_V1: &str = "foxglove.sdk.v1";
/// The most an opening handshake may have, bytes.
const MAX_HEAD: usize = 16 << 10;
/// How long a client may take to send its handshake.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);

/// The relay, accepting until dropped.
pub struct Relay {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Relay {
    /// Listens at `addr` (`host:port`) and relays each connection to the server at
    /// `127.0.0.1:upstream`. An address that cannot be taken is an error here, before
    /// anything is served.
    pub fn start(addr: &str, upstream: u16) -> io::Result<Relay> {
        let listener = TcpListener::bind(addr)?;
        let addr = listener.local_addr()?;
        listener.set_nonblocking(true)?;
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = stop.clone();
        let thread = std::thread::Builder::new().name("qmarc-relay".into()).spawn(move || {
            while !stopping.load(Ordering::Relaxed) {
                match listener.accept() {
                    Ok((client, _)) => {
                        let _ = std::thread::Builder::new().name("qmarc-relay-conn".into()).spawn(
                            move || {
                                let _ = relay(client, upstream);
                            },
                        );
                    }
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                        std::thread::sleep(Duration::from_millis(20));
                    }
                    Err(_) => std::thread::sleep(Duration::from_millis(20)),
                }
            }
        })?;
        Ok(Relay { addr, stop, thread: Some(thread) })
    }

    /// Where it listens.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Reads from `s` until the end of an HTTP head (`\r\n\r\n`): the head, and what came after
/// it in the same reads.
fn read_head(s: &mut TcpStream) -> io::Result<(Vec<u8>, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            return Ok((buf, rest));
        }
        if buf.len() > MAX_HEAD {
            return Err(io::Error::new(io::ErrorKind::InvalidData, "handshake too long"));
        }
        let n = s.read(&mut chunk)?;
        if n == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// `head` with the values of its `Sec-WebSocket-Protocol` header passed through `rename`;
/// whether any was renamed.
fn rename_protocols(head: &[u8], rename: impl Fn(&str) -> Option<&'static str>) -> (Vec<u8>, bool) {
    let text = String::from_utf8_lossy(head);
    let mut renamed = false;
    let lines: Vec<String> = text
        .split("\r\n")
        .map(|line| match line.split_once(':') {
            Some((name, values)) if name.trim().eq_ignore_ascii_case("sec-websocket-protocol") => {
                let values: Vec<String> = values
                    .split(',')
                    .map(|v| match rename(v.trim()) {
                        Some(to) => {
                            renamed = true;
                            to.to_string()
                        }
                        None => v.trim().to_string(),
                    })
                    .collect();
                format!("{name}: {}", values.join(", "))
            }
            _ => line.to_string(),
        })
        .collect();
    (lines.join("\r\n").into_bytes(), renamed)
}

/// The client's handshake as the SDK takes it: `foxglove.websocket.v1` offered as
/// `foxglove.sdk.v1`, unless the client offers that too.
pub fn request_for_sdk(head: &[u8]) -> (Vec<u8>, bool) {
    let offers_sdk = String::from_utf8_lossy(head).contains(SDK_V1);
    rename_protocols(head, |v| (v == WEBSOCKET_V1 && !offers_sdk).then_some(SDK_V1))
}

/// The SDK's answer under the name the client asked for.
pub fn response_for_client(head: &[u8]) -> Vec<u8> {
    rename_protocols(head, |v| (v == SDK_V1).then_some(WEBSOCKET_V1)).0
}

/// One connection: the handshake, renamed where needed, then bytes both ways until either
/// side ends.
fn relay(mut client: TcpStream, upstream: u16) -> io::Result<()> {
    client.set_nonblocking(false)?;
    client.set_read_timeout(Some(HANDSHAKE_TIMEOUT))?;
    let (head, rest) = read_head(&mut client)?;
    let (head, renamed) = request_for_sdk(&head);
    let mut server = TcpStream::connect(("127.0.0.1", upstream))?;
    server.write_all(&head)?;
    server.write_all(&rest)?;
    server.set_read_timeout(Some(HANDSHAKE_TIMEOUT))?;
    let (answer, rest) = read_head(&mut server)?;
    let answer = if renamed { response_for_client(&answer) } else { answer };
    client.write_all(&answer)?;
    client.write_all(&rest)?;
    client.set_read_timeout(None)?;
    server.set_read_timeout(None)?;
    let _ = client.set_nodelay(true);
    let _ = server.set_nodelay(true);
    let (c2, s2) = (client.try_clone()?, server.try_clone()?);
    let up = std::thread::Builder::new()
        .name("qmarc-relay-up".into())
        .spawn(move || copy_then_close(c2, s2))?;
    copy_then_close(server, client);
    let _ = up.join();
    Ok(())
}

/// Copies `from` into `to` until either ends, then shuts both down (so that the other
/// direction's copy ends too).
fn copy_then_close(mut from: TcpStream, mut to: TcpStream) {
    let _ = io::copy(&mut from, &mut to);
    let _ = from.shutdown(Shutdown::Both);
    let _ = to.shutdown(Shutdown::Both);
}

#[cfg(test)]
mod tests {
    use super::*;

    const REQUEST: &str = "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n\
        Sec-WebSocket-Protocol: foxglove.websocket.v1\r\nSec-WebSocket-Key: k\r\n\r\n";

    #[test]
    fn the_protocols_name_is_swapped_both_ways_and_only_there() {
        let (req, renamed) = request_for_sdk(REQUEST.as_bytes());
        assert!(renamed);
        let req = String::from_utf8(req).unwrap();
        assert_eq!(req, REQUEST.replace(WEBSOCKET_V1, SDK_V1));
        let answer =
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1\r\n\r\n";
        let back = String::from_utf8(response_for_client(answer.as_bytes())).unwrap();
        assert_eq!(back, answer.replace(SDK_V1, WEBSOCKET_V1));
        // A client that offers the SDK's name, or another protocol, is relayed as it asked.
        let both = REQUEST.replace(WEBSOCKET_V1, "foxglove.websocket.v1, foxglove.sdk.v1");
        let (req, renamed) = request_for_sdk(both.as_bytes());
        assert!(!renamed);
        assert_eq!(String::from_utf8(req).unwrap(), both);
        let other = REQUEST.replace(WEBSOCKET_V1, "chat");
        assert_eq!(request_for_sdk(other.as_bytes()), (other.clone().into_bytes(), false));
    }
}
