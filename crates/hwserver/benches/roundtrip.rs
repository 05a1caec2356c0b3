//! Round trip controller → hwserver → controller over iceoryx2 against the real
//! `qmarc-hwserver` binary. Prints latency percentiles for back-to-back exchanges and for
//! servo cycles paced at 2.5 kHz (read + write exchange, as the controller does), with the
//! scheduling policy both sides got.
//!
//! `cargo bench -p qmarc-hwserver --bench roundtrip` (`QMARC_BENCH_CYCLES` sets the number
//! of cycles, default 10 000 = 4 s per phase).

use qmarc_controller::link::{HwLink, IoxLink, LinkTimeouts};
use qmarc_proto::service::IpcLocation;
use qmarc_proto::{HwMsg, MsgType};
use qmarc_timer::clock::monotonic_now_ns;
use qmarc_timer::rt::{RtRequest, spawn};
use qmarc_timer::{Histogram, Percentiles, TickerKind};
use std::process::Command;
use std::time::Duration;

const PERIOD_NS: u64 = 400_000;

fn row(name: &str, h: &Histogram) {
    let Percentiles { p50_us, p99_us, p999_us, max_us } = h.percentiles();
    println!(
        "{name:<34} {:>8} {p50_us:>7.0} {p99_us:>7.0} {p999_us:>7.0} {max_us:>9.1} {:>9}",
        h.count(),
        h.count_above_us(400)
    );
}

fn main() {
    let cycles: u64 =
        std::env::var("QMARC_BENCH_CYCLES").ok().and_then(|v| v.parse().ok()).unwrap_or(10_000);
    let pid = std::process::id();
    let dir = std::env::temp_dir().join(format!("qmarc-bench-rt-{pid}"));
    let location = IpcLocation::new(&format!("qb{pid}_"), &format!("{}/", dir.display()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let spec = qmarc_hwserver::backends::standalone_run(
        "[hwserver]\nwatchdog_periods = 2500\n[sim]\nstate_file = \"\"\n",
        &location,
        false,
    )
    .expect("bench settings");
    let run_file = dir.join("run.json");
    spec.write(&run_file).expect("run file");
    let mut server = Command::new(env!("CARGO_BIN_EXE_qmarc-hwserver"))
        .arg(format!("--settings={}", run_file.display()))
        .spawn()
        .expect("spawn qmarc-hwserver");

    let loc = location.clone();
    let result = spawn(
        "bench-client",
        RtRequest { priority: Some(80), ..RtRequest::default() },
        move |rt| {
            let timeouts =
                LinkTimeouts { deadline_ns: 5 * PERIOD_NS, give_up_ns: 1_000_000_000, spin_ns: 0 };
            let mut link =
                IoxLink::connect(&loc, timeouts, Duration::from_secs(10), None).expect("connect");
            let read = HwMsg::read_all_encoders();
            let write = HwMsg::write_all_dacs(&[0; 4]);

            let mut back_to_back = Histogram::new(2_000);
            for _ in 0..cycles / 10 {
                link.exchange(&read).expect("warm-up");
            }
            for _ in 0..cycles {
                let t = monotonic_now_ns();
                link.exchange(&read).expect("exchange");
                back_to_back.record_ns(monotonic_now_ns() - t);
            }

            let (mut read_rtt, mut write_rtt, mut output, mut wake) = (
                Histogram::new(2_000),
                Histogram::new(2_000),
                Histogram::new(2_000),
                Histogram::new(2_000),
            );
            let mut ticker = TickerKind::TimerFd.build(PERIOD_NS);
            ticker.start().expect("timer");
            let mut missed = 0;
            for _ in 0..cycles {
                let tick = ticker.wait().expect("tick");
                missed += tick.missed;
                wake.record_ns(tick.latency_ns());
                let t0 = monotonic_now_ns();
                link.exchange(&read).expect("read");
                let t1 = monotonic_now_ns();
                link.exchange(&write).expect("write");
                let t2 = monotonic_now_ns();
                read_rtt.record_ns(t1 - t0);
                write_rtt.record_ns(t2 - t1);
                output.record_ns(t2 - tick.intended_ns);
            }
            link.exchange(&HwMsg::request(MsgType::Exit)).expect("exit");
            (rt.policy(), back_to_back, read_rtt, write_rtt, output, wake, missed)
        },
    )
    .expect("client thread")
    .join()
    .expect("client");
    let status = server.wait().expect("server");
    location.remove_files();
    let _ = std::fs::remove_dir_all(&dir);

    let (policy, b2b, read_rtt, write_rtt, output, wake, missed) = result;
    println!(
        "\nqmarc-hwserver round trip over iceoryx2 (µs), 72-byte message, both sides blocking on events"
    );
    println!("client: {policy}; server: SCHED_FIFO 85 if permitted; server exit: {status}");
    println!(
        "{:<34} {:>8} {:>7} {:>7} {:>7} {:>9} {:>9}",
        "", "n", "p50", "p99", "p99.9", "max", ">400µs"
    );
    row("back-to-back read", &b2b);
    row("2.5 kHz cycle: read round trip", &read_rtt);
    row("2.5 kHz cycle: write round trip", &write_rtt);
    row("2.5 kHz cycle: tick → DAC written", &output);
    row("2.5 kHz cycle: wake latency", &wake);
    println!("missed periods: {missed}");
}
