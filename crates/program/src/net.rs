//! Loopback ports for a program's own servers (a benchmark's Zenoh router, a test's bridge),
//! and a second host on this machine for the programs that try a network of them
//! ([`Netns`]: the bridge's and the cell's two-host tests and benchmark).

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

/// A network namespace joined to this one by a veth pair — a second host on this machine
/// (10.231.S.1 on this side, 10.231.S.2 there); deleted, with its link, on drop. Making one
/// takes root (`ip netns`, iproute2).
#[derive(Debug)]
pub struct Netns {
    /// Its name (`ip netns exec NAME …` runs a program there).
    pub name: String,
    /// This side's address.
    pub here: String,
    /// Its side's address.
    pub there: String,
    /// This side's end of the link.
    link: String,
}

impl Netns {
    /// A new namespace and its link, up; an error saying which `ip` command failed and why.
    pub fn new() -> Result<Netns, String> {
        static MADE: AtomicU16 = AtomicU16::new(0);
        if !nix::unistd::geteuid().is_root() {
            return Err("a second host (ip netns) needs root".into());
        }
        let (pid, k) = (std::process::id(), MADE.fetch_add(1, Ordering::Relaxed));
        // A subnet no other namespace of this machine's has taken (another process's, made
        // beside: two links on one /24 would misroute silently).
        let taken = |subnet: &str| {
            std::process::Command::new("ip")
                .args(["-4", "-o", "addr", "show", "to", &format!("{subnet}.0/24")])
                .output()
                .map_or(true, |o| !o.stdout.is_empty())
        };
        let start = (pid + u32::from(k) * 7) % 200;
        let subnet = (0..200)
            .map(|i| format!("10.231.{}", (start + i) % 200 + 20))
            .find(|s| !taken(s))
            .ok_or("no free subnet in 10.231.20‥219.0/24")?;
        let tag = format!("{pid}{k}");
        let (name, a, b) = (format!("qmarc{tag}"), format!("qv{tag}a"), format!("qv{tag}b"));
        let ns = Netns {
            name: name.clone(),
            here: format!("{subnet}.1"),
            there: format!("{subnet}.2"),
            link: a.clone(),
        };
        let ip = |args: &[&str]| -> Result<(), String> {
            let out = std::process::Command::new("ip")
                .args(args)
                .output()
                .map_err(|e| format!("ip (iproute2): {e}"))?;
            if out.status.success() {
                Ok(())
            } else {
                Err(format!("ip {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr)))
            }
        };
        ip(&["netns", "add", &name])?;
        // From here the namespace is deleted on every way out (ns's drop).
        ip(&["link", "add", &a, "type", "veth", "peer", "name", &b])?;
        ip(&["link", "set", &b, "netns", &name])?;
        ip(&["addr", "add", &format!("{}/24", ns.here), "dev", &a])?;
        ip(&["link", "set", &a, "up"])?;
        ip(&["-n", &name, "addr", "add", &format!("{}/24", ns.there), "dev", &b])?;
        ip(&["-n", &name, "link", "set", &b, "up"])?;
        ip(&["-n", &name, "link", "set", "lo", "up"])?;
        Ok(ns)
    }

    /// Cuts the link to the namespace (`up` false: its cable pulled) or restores it.
    pub fn set_link(&self, up: bool) -> Result<(), String> {
        let state = if up { "up" } else { "down" };
        let out = std::process::Command::new("ip")
            .args(["link", "set", &self.link, state])
            .output()
            .map_err(|e| format!("ip (iproute2): {e}"))?;
        match out.status.success() {
            true => Ok(()),
            false => Err(format!(
                "ip link set {} {state}: {}",
                self.link,
                String::from_utf8_lossy(&out.stderr)
            )),
        }
    }

    /// `program` to be run in the namespace (`ip netns exec NAME program`).
    pub fn command(&self, program: &std::path::Path) -> std::process::Command {
        let mut c = std::process::Command::new("ip");
        c.args(["netns", "exec", &self.name]).arg(program);
        c
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        // The veth pair goes with the namespace, once its end is there; before (a step of
        // `new` that failed) it is deleted here.
        for args in [["netns", "del", &self.name], ["link", "del", &self.link]] {
            let _ = std::process::Command::new("ip")
                .args(args)
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .status();
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

    #[test]
    fn a_second_host_is_made_reachable_and_gone_on_drop() {
        if !nix::unistd::geteuid().is_root() {
            return; // CI runs as root; a user's `cargo test` may not.
        }
        let ns = super::Netns::new().unwrap();
        // A connection from there reaches a listener on this side's address.
        let listener = std::net::TcpListener::bind((ns.here.as_str(), 0)).unwrap();
        let port = listener.local_addr().unwrap().port();
        let reached = ns
            .command(std::path::Path::new("bash"))
            .args(["-c", &format!("exec 3<>/dev/tcp/{}/{port}", ns.here)])
            .status()
            .unwrap();
        assert!(reached.success(), "this side reachable from there");
        assert!(listener.accept().is_ok());
        // Its cable pulled, nothing gets through; put back, it does again.
        let connect = || {
            ns.command(std::path::Path::new("timeout"))
                .args(["2", "bash", "-c", &format!("exec 3<>/dev/tcp/{}/{port}", ns.here)])
                .status()
                .unwrap()
                .success()
        };
        ns.set_link(false).unwrap();
        assert!(!connect(), "cut off");
        ns.set_link(true).unwrap();
        assert!(connect(), "back");
        let list = || {
            let out = std::process::Command::new("ip").args(["netns", "list"]).output().unwrap();
            String::from_utf8_lossy(&out.stdout).into_owned()
        };
        let name = ns.name.clone();
        assert!(list().contains(&name));
        drop(ns);
        assert!(!list().contains(&name), "deleted on drop");
    }
}
