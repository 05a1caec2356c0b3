//! Loopback ports for a program's own servers (a benchmark's Zenoh router, a test's bridge).

use std::net::TcpListener;
use std::sync::atomic::{AtomicU16, Ordering};

/// The lowest port of Linux's default ephemeral range (`net.ipv4.ip_local_port_range`):
/// every outgoing connection takes its local port from there.
const EPHEMERAL_FROM: u16 = 32_768;
/// Where this module's ports start: above the well-known and common service ports.
const FROM: u16 = 20_000;

/// A TCP port free on loopback now, below the ephemeral range. A port the kernel hands out
/// (`bind(0)`) is an ephemeral one, which any outgoing connection of another process — a
/// Zenoh client of a test running beside — may take before the server that was to listen
/// there binds it; below the range only another explicit choice can. Each process starts
/// at its own place (its pid) and each call moves on, so programs and tests running side by
/// side rarely even try the same port.
pub fn free_loopback_port() -> u16 {
    static NEXT: AtomicU16 = AtomicU16::new(0);
    let span = EPHEMERAL_FROM - FROM;
    let start = (std::process::id() % u32::from(span / 16)) as u16 * 16;
    loop {
        let k = NEXT.fetch_add(1, Ordering::Relaxed);
        let port = FROM + (start.wrapping_add(k)) % span;
        if TcpListener::bind(("127.0.0.1", port)).is_ok() {
            return port;
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn ports_are_free_distinct_and_below_the_ephemeral_range() {
        let ports: Vec<u16> = (0..20).map(|_| super::free_loopback_port()).collect();
        assert!(ports.iter().all(|p| (super::FROM..super::EPHEMERAL_FROM).contains(p)));
        let mut distinct = ports.clone();
        distinct.sort();
        distinct.dedup();
        assert_eq!(distinct.len(), ports.len(), "{ports:?}");
    }
}
