//! The raw baselines `ipc` measures beside the controller ⇄ hwserver exchange, in the same
//! run: a futex ping-pong and a spin ping-pong between two threads sharing one word of memory
//! (the floors of a blocking and of a spinning exchange), and iceoryx2's request/response
//! ports alone, busy-polled by two threads (what the library costs before our hwserver, its
//! event notifications and its handling are added).

use crate::stats::percentiles_us;
use anyhow::anyhow;
use qmarc_proto::HwMsg;
use qmarc_proto::service::{IpcLocation, create_node, open_hw_services};
use qmarc_report::summary::Pct;
use qmarc_timer::clock::monotonic_now_ns;
use qmarc_timer::rt::RtRequest;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Barrier};

/// The futex(2) call on `word`.
fn futex(word: &AtomicU32, op: i32, val: u32) {
    // SAFETY: `word` is a live, aligned u32 for the call's duration; FUTEX_WAIT and
    // FUTEX_WAKE read it and queue/wake on its address only; no timeout pointer.
    unsafe {
        libc::syscall(libc::SYS_futex, word.as_ptr(), op, val, std::ptr::null::<libc::timespec>());
    }
}

const PING: u32 = 1;
const PONG: u32 = 2;
const STOP: u32 = 3;

/// Waits while `w` holds `not`: in futex(2) when `block`, else spinning; gives up after 2 s
/// (a partner that died). Returns the value that ended the wait.
fn wait_while(w: &AtomicU32, not: u32, block: bool) -> u32 {
    let deadline = monotonic_now_ns() + 2_000_000_000;
    loop {
        let v = w.load(Ordering::Acquire);
        if v != not || monotonic_now_ns() > deadline {
            return v;
        }
        if block {
            futex(w, libc::FUTEX_WAIT, v);
        } else {
            std::hint::spin_loop();
        }
    }
}

/// The answering side: turns every ping into a pong until told to stop. Only atomics, the
/// vDSO clock and futex(2): safe in a child forked from a threaded process.
fn pong(word: &AtomicU32, block: bool) {
    loop {
        // Wait for a ping (the word leaves PONG or 0), answer it.
        let mut v = word.load(Ordering::Acquire);
        while v != PING && v != STOP {
            v = wait_while(word, v, block);
        }
        if v == STOP {
            return;
        }
        word.store(PONG, Ordering::Release);
        if block {
            futex(word, libc::FUTEX_WAKE, 1);
        }
    }
}

/// The asking side: `samples` round trips, then tells the other side to stop.
fn ping(word: &AtomicU32, block: bool, samples: usize) -> Vec<u64> {
    let mut rtt = Vec::with_capacity(samples);
    for _ in 0..samples {
        let t0 = monotonic_now_ns();
        word.store(PING, Ordering::Release);
        if block {
            futex(word, libc::FUTEX_WAKE, 1);
        }
        while wait_while(word, PING, block) != PONG {}
        rtt.push(monotonic_now_ns() - t0);
    }
    word.store(STOP, Ordering::Release);
    futex(word, libc::FUTEX_WAKE, 1);
    rtt
}

/// The request for one side of a ping-pong: the priority the controller (80) or the hwserver
/// (85) runs at when `fifo`; on `cpu` when given.
fn side(priority: i32, fifo: bool, cpu: Option<usize>) -> RtRequest {
    RtRequest {
        priority: fifo.then_some(priority),
        lock_memory: false,
        prefault_stack_bytes: 64 * 1024,
        cpu,
    }
}

/// A ping-pong between two threads over one shared word: `block` waits in futex(2) (the
/// shared, not private, form, as between processes over shared memory), else spins. Each
/// side at the priority the hwserver and controller run at when `fifo`; both on `cpu` when
/// given.
pub fn ping_pong(
    samples: usize,
    block: bool,
    fifo: bool,
    cpu: Option<usize>,
) -> anyhow::Result<Pct> {
    let word = Arc::new(AtomicU32::new(0));
    let server_word = Arc::clone(&word);
    let server = qmarc_timer::rt::spawn("bench-pong", side(85, fifo, cpu), move |_| {
        pong(&server_word, block)
    })?;
    let client = qmarc_timer::rt::spawn("bench-ping", side(80, fifo, cpu), move |_| {
        ping(&word, block, samples)
    })?;
    let mut rtt = client.join().map_err(|_| anyhow::anyhow!("ping thread panicked"))?;
    server.join().map_err(|_| anyhow::anyhow!("pong thread panicked"))?;
    Ok(percentiles_us(&mut rtt))
}

/// The futex ping-pong between two processes, as controller and hwserver are: the word in a
/// shared anonymous mapping, the pong side a child forked from this (then single-threaded)
/// process, both SCHED_FIFO; both on `cpu` when given. Beside [`ping_pong`] it shows what a
/// hand-over costs more when each side has its own address space.
pub fn futex_ping_pong_processes(samples: usize, cpu: Option<usize>) -> anyhow::Result<Pct> {
    use nix::sys::mman::{MapFlags, ProtFlags, mmap_anonymous, munmap};
    use nix::unistd::{ForkResult, fork};
    let len = std::num::NonZeroUsize::new(4096).expect("non-zero");
    let prot = ProtFlags::PROT_READ | ProtFlags::PROT_WRITE;
    // SAFETY: a fresh anonymous mapping, unmapped below after both sides are done with it.
    let page = unsafe { mmap_anonymous(None, len, prot, MapFlags::MAP_SHARED)? };
    // SAFETY: the page is zeroed, page-aligned and mapped until the munmap below.
    let word: &'static AtomicU32 = unsafe { page.cast::<AtomicU32>().as_ref() };
    let result = (|| -> anyhow::Result<Pct> {
        // SAFETY: the child only makes raw system calls and touches atomics before _exit.
        match unsafe { fork()? } {
            ForkResult::Child => {
                // Gone with the parent, whatever ends it.
                let _ = nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGKILL);
                let _ = qmarc_timer::rt::set_current_thread_fifo(85);
                if let Some(c) = cpu {
                    let _ = qmarc_timer::rt::pin_current_thread(c);
                }
                pong(word, true);
                // SAFETY: ends the child without running the parent's exit handlers.
                unsafe { libc::_exit(0) }
            }
            ForkResult::Parent { child } => {
                let client = qmarc_timer::rt::spawn("bench-ping", side(80, true, cpu), move |_| {
                    ping(word, true, samples)
                });
                let rtt = client.map(|c| c.join());
                // Whatever became of the ping side, the child stops and is reaped.
                word.store(STOP, Ordering::Release);
                futex(word, libc::FUTEX_WAKE, 1);
                let _ = nix::sys::wait::waitpid(child, None);
                let mut rtt = rtt?.map_err(|_| anyhow::anyhow!("ping thread panicked"))?;
                Ok(percentiles_us(&mut rtt))
            }
        }
    })();
    // SAFETY: the child is reaped and the ping thread joined: nobody uses the page now.
    let _ = unsafe { munmap(page, len.get()) };
    result
}

/// Round trips through iceoryx2's request/response ports (the hwserver's service, its QoS
/// and its 72-byte message) between two threads of this process that both busy-poll: no
/// event, no hwserver, the request echoed back.
pub fn iox_ports(samples: usize) -> anyhow::Result<Pct> {
    in_scratch_location("ports", |_, location| iox_ports_at(samples, location))
}

/// Runs `f` with a scratch directory and an iceoryx2 location of its own (prefix
/// `qb<tag><pid>_`, root in that directory), then removes both, whatever `f` returned. Only
/// for `f` that leaves no process of that prefix running.
pub fn in_scratch_location<T>(
    tag: &str,
    f: impl FnOnce(&Path, &IpcLocation) -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let pid = std::process::id();
    let dir = std::env::temp_dir().join(format!("qmarc-bench-{tag}-{pid}"));
    std::fs::create_dir_all(&dir)?;
    let location = IpcLocation::new(&format!("qb{tag}{pid}_"), &format!("{}/", dir.display()));
    let result = f(&dir, &location);
    location.remove_files();
    let _ = std::fs::remove_dir_all(&dir);
    result
}

fn iox_ports_at(samples: usize, location: &IpcLocation) -> anyhow::Result<Pct> {
    // The services exist before either port: each thread opens them.
    let node = create_node("qmarc-bench", location)?;
    let _services = open_hw_services(&node)?;
    let ready = Arc::new(Barrier::new(2));
    let done = Arc::new(AtomicBool::new(false));
    let req = RtRequest { priority: None, lock_memory: false, prefault_stack_bytes: 0, cpu: None };
    let (loc, go, stop) = (location.clone(), Arc::clone(&ready), Arc::clone(&done));
    // Each side meets the other at the barrier whether or not its port came up, so that
    // neither waits for ever on a failed partner.
    let server = qmarc_timer::rt::spawn("bench-iox-server", req, move |_| -> anyhow::Result<()> {
        let port = || -> anyhow::Result<_> {
            let node = create_node("qmarc-bench-server", &loc)?;
            let services = open_hw_services(&node)?;
            let server = services.hw.server_builder().create().map_err(|e| anyhow!("{e:?}"))?;
            Ok((node, server))
        };
        let port = port();
        go.wait();
        let (_node, server) = port?;
        while !stop.load(Ordering::Relaxed) {
            while let Some(active) = server.receive().map_err(|e| anyhow!("{e:?}"))? {
                let echo = *active.payload();
                active.send_copy(echo).map_err(|e| anyhow!("{e:?}"))?;
            }
            std::hint::spin_loop();
        }
        Ok(())
    })?;
    let loc = location.clone();
    let client = qmarc_timer::rt::spawn("bench-iox-client", req, move |_| {
        let run = || -> anyhow::Result<Vec<u64>> {
            let port = || -> anyhow::Result<_> {
                let node = create_node("qmarc-bench-client", &loc)?;
                let services = open_hw_services(&node)?;
                let client = services.hw.client_builder().create().map_err(|e| anyhow!("{e:?}"))?;
                Ok((node, client))
            };
            let port = port();
            ready.wait();
            let (_node, client) = port?;
            let mut rtt = Vec::with_capacity(samples);
            for i in 0..samples + samples / 10 {
                let t0 = monotonic_now_ns();
                let pending = client
                    .send_copy(HwMsg::read_all_encoders())
                    .map_err(|e| anyhow!("request send: {e:?}"))?;
                let deadline = t0 + 2_000_000_000;
                while pending.receive().map_err(|e| anyhow!("{e:?}"))?.is_none() {
                    if monotonic_now_ns() > deadline {
                        return Err(anyhow!("no response from the echo server in 2 s"));
                    }
                    std::hint::spin_loop();
                }
                if i >= samples / 10 {
                    rtt.push(monotonic_now_ns() - t0);
                }
            }
            Ok(rtt)
        };
        let r = run();
        done.store(true, Ordering::Relaxed);
        r
    })?;
    let rtt = client.join().map_err(|_| anyhow!("client thread panicked"))?;
    server.join().map_err(|_| anyhow!("server thread panicked"))??;
    Ok(percentiles_us(&mut rtt?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_ping_pongs_and_the_ports_complete() {
        for block in [true, false] {
            let p = ping_pong(200, block, false, None).unwrap();
            assert!(p.p50 > 0.0 && p.max >= p.p99, "{p:?}");
        }
        let p = futex_ping_pong_processes(200, None).unwrap();
        assert!(p.p50 > 0.0 && p.max >= p.p99, "{p:?}");
        let p = iox_ports(200).unwrap();
        assert!(p.p50 > 0.0 && p.max >= p.p99, "{p:?}");
    }
}
