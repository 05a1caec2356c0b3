//! `qmarc-bench ipc`: the controller ⇄ hwserver exchange (the controller's `IoxLink` against
//! the real `qmarc-hwserver` binary: blocking, blocking with both on one CPU, spinning, and
//! blocking once per servo period, as the loop makes it, with both ends asleep between) beside
//! the baselines of [`crate::baselines`] measured in the same run — and what the benchmarks
//! need of the machine: where the binaries are, what the machine is, and cyclictest as an
//! outside reference.

use crate::baselines::{futex_ping_pong_processes, in_scratch_location, iox_ports, ping_pong};
use crate::stats::percentiles_us;
use qmarc_controller::link::{HwLink, IoxLink, LinkTimeouts};
use qmarc_proto::HwMsg;
use qmarc_proto::service::IpcLocation;
use qmarc_report::summary::Pct;
use qmarc_timer::TickerKind;
use qmarc_timer::clock::monotonic_now_ns;
use qmarc_timer::rt::{DmaLatencyGuard, RtRequest};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Duration;

/// Options of `ipc`.
#[derive(Debug, clap::Args)]
pub struct IpcArgs {
    /// Round trips per row.
    #[arg(long, default_value_t = 20_000)]
    pub samples: usize,
    /// Directory holding qmarc-hwserver (default: next to this program).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
    /// Write the figures as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// What the figures were measured on.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    /// `uname -r`.
    pub kernel: String,
    /// Online CPUs.
    pub cpus: usize,
    /// The CPU model, from /proc/cpuinfo.
    pub cpu: String,
    /// Running as root (SCHED_FIFO and mlockall granted).
    pub root: bool,
    /// RT throttling, µs of real-time run time per period (`null`: off): a spinning
    /// SCHED_FIFO hwserver is stopped for the rest of each period.
    pub rt_runtime_us: Option<i64>,
}

impl Machine {
    /// This machine.
    pub fn here() -> Machine {
        let uts = kernel_release();
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|c| c.lines().find(|l| l.starts_with("model name")).map(str::to_string))
            .and_then(|l| l.split_once(':').map(|(_, m)| m.trim().to_string()))
            .unwrap_or_default();
        Machine {
            kernel: uts,
            cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
            cpu,
            // SAFETY: geteuid has no preconditions.
            root: unsafe { libc::geteuid() } == 0,
            rt_runtime_us: qmarc_timer::rt::rt_throttling().map(|(runtime, _)| runtime),
        }
    }
}

fn kernel_release() -> String {
    std::fs::read_to_string("/proc/sys/kernel/osrelease")
        .map(|s| s.trim().to_string())
        .unwrap_or_default()
}

/// cyclictest's figures, run before and after the rounds.
#[derive(Debug, Clone, Serialize)]
pub struct Cyclictest {
    /// p99 wake latency before the rounds, µs.
    pub before_p99_us: f64,
    /// And after.
    pub after_p99_us: f64,
    /// Max before and after, µs.
    pub max_us: f64,
}

/// Runs cyclictest for `seconds` at `period_us` (one SCHED_FIFO thread, memory locked, a
/// histogram up to two periods) when it is installed and we are root; its p99 and max.
pub fn cyclictest(period_us: u32, seconds: f64, priority: Option<i32>) -> Option<(f64, f64)> {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return None;
    }
    let out = std::process::Command::new("cyclictest")
        .args(["-m", "-q", "-t1", "--policy=fifo"])
        .arg(format!("-p{}", priority.unwrap_or(80)))
        .arg(format!("-i{period_us}"))
        .arg(format!("-h{}", 2 * period_us))
        .arg(format!("-D{}", seconds.ceil() as u64))
        .output()
        .ok()?;
    parse_cyclictest(&String::from_utf8_lossy(&out.stdout))
}

/// The p99 (nearest rank over its histogram) and max of cyclictest's `-h` output.
pub fn parse_cyclictest(text: &str) -> Option<(f64, f64)> {
    let mut bins: Vec<(u64, u64)> = Vec::new();
    let mut max = None;
    for line in text.lines() {
        if let Some(rest) = line.strip_prefix("# Max Latencies:") {
            max = rest.split_whitespace().next().and_then(|v| v.parse::<f64>().ok());
        } else if !line.starts_with('#') {
            let mut f = line.split_whitespace();
            if let (Some(us), Some(n)) = (f.next(), f.next())
                && let (Ok(us), Ok(n)) = (us.parse::<u64>(), n.parse::<u64>())
            {
                bins.push((us, n));
            }
        }
    }
    let total: u64 = bins.iter().map(|b| b.1).sum();
    if total == 0 {
        return None;
    }
    let rank = (0.99 * total as f64).ceil() as u64;
    let mut seen = 0;
    let p99 = bins.iter().find(|b| {
        seen += b.1;
        seen >= rank
    })?;
    Some((p99.0 as f64, max.unwrap_or(p99.0 as f64)))
}

/// cyclictest after the rounds, paired with the run before.
pub fn cyclictest_pair(
    before: Option<(f64, f64)>,
    period_us: u32,
    seconds: f64,
    priority: Option<i32>,
) -> Option<Cyclictest> {
    let (b99, bmax) = before?;
    let (a99, amax) = cyclictest(period_us, seconds, priority)?;
    Some(Cyclictest { before_p99_us: b99, after_p99_us: a99, max_us: bmax.max(amax) })
}

/// One line on the outside reference.
pub fn describe_cyclictest(c: Option<&Cyclictest>) -> String {
    match c {
        Some(c) => format!(
            "cyclictest (outside reference): p99 {:.0} µs before, {:.0} µs after; max {:.0} µs",
            c.before_p99_us, c.after_p99_us, c.max_us
        ),
        None => "cyclictest: not run (needs root and `cyclictest` on PATH: apt-get install \
                 rt-tests) — the bare loop is the reference"
            .to_string(),
    }
}

/// How an exchange row runs.
#[derive(Debug, Clone, Copy, Default)]
struct Mode {
    /// The hwserver busy-polls (`--spin`) and the client polls for each response before it
    /// would block.
    spin: bool,
    /// Both pinned to this CPU.
    cpu: Option<usize>,
    /// One exchange per tick of the controller's timerfd at this period, as the servo loop
    /// makes them (both ends asleep in between); `None`: back to back.
    paced_ns: Option<u64>,
}

/// Read exchanges with a real `qmarc-hwserver` (lock-step simulated robot), the client at the
/// servo thread's priority, as `mode` says.
fn exchange(samples: usize, bin_dir: &std::path::Path, mode: Mode) -> anyhow::Result<Pct> {
    in_scratch_location("ipc", |dir, location| exchange_at(samples, bin_dir, mode, dir, location))
}

fn exchange_at(
    samples: usize,
    bin_dir: &std::path::Path,
    Mode { spin, cpu, paced_ns }: Mode,
    dir: &std::path::Path,
    location: &IpcLocation,
) -> anyhow::Result<Pct> {
    let wait = if spin { "spin" } else { "block" };
    let pin = cpu.map_or(-1, |c| c as i64);
    let spec = qmarc_hwserver::backends::standalone_run(
        &format!(
            "[timer]\nhwserver_cpu = {pin}\n[hwserver]\nwatchdog_periods = 2500\nwait = \"{wait}\"\n\
             [sim]\nstate_file = \"\"\n"
        ),
        location,
        true,
    )
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let run_file = dir.join("run.json");
    spec.write(&run_file)?;
    let mut server = std::process::Command::new(bin_dir.join("qmarc-hwserver"))
        .arg(format!("--settings={}", run_file.display()))
        .spawn()?;
    let loc = location.clone();
    let req =
        RtRequest { priority: Some(80), lock_memory: false, prefault_stack_bytes: 64 * 1024, cpu };
    let client =
        qmarc_timer::rt::spawn("bench-exchange", req, move |_| -> anyhow::Result<Vec<u64>> {
            let spin_ns = if spin { 1_000_000 } else { 0 };
            let timeouts =
                LinkTimeouts { deadline_ns: 2_000_000, give_up_ns: 2_000_000_000, spin_ns };
            let link = IoxLink::connect(&loc, timeouts, Duration::from_secs(10), None)?;
            let mut link = if spin { link.to_spinning_server() } else { link };
            let read = HwMsg::read_all_encoders();
            let mut rtt = Vec::with_capacity(samples);
            for _ in 0..samples / 10 {
                link.exchange(&read)?;
            }
            let mut ticker = paced_ns.map(|p| TickerKind::TimerFd.build(p));
            if let Some(t) = &mut ticker {
                t.start()?;
            }
            for _ in 0..samples {
                if let Some(t) = &mut ticker {
                    t.wait()?;
                }
                let t0 = monotonic_now_ns();
                link.exchange(&read)?;
                rtt.push(monotonic_now_ns() - t0);
            }
            let _ = link.exchange(&HwMsg::request(qmarc_proto::MsgType::Exit));
            Ok(rtt)
        })?;
    let result = client.join().map_err(|_| anyhow::anyhow!("exchange thread panicked"));
    if !matches!(result, Ok(Ok(_))) {
        let _ = server.kill(); // no Exit was sent: it would wait for one for ever
    }
    let _ = server.wait();
    let result = result?;
    Ok(percentiles_us(&mut result?))
}

/// One row of `ipc`.
#[derive(Debug, Serialize)]
struct Row {
    name: &'static str,
    #[serde(flatten)]
    us: Pct,
}

/// The JSON `--json` writes.
#[derive(Debug, Serialize)]
struct Report<'a> {
    samples: usize,
    machine: Machine,
    rows: &'a [Row],
    blocking_over_futex: f64,
    one_cpu_over_futex: f64,
    blocking_over_process_futex: f64,
    one_cpu_over_process_futex: f64,
    spinning_over_spin: f64,
    ports_over_spin: f64,
    paced_over_back_to_back: f64,
}

/// The paced rows' period: the servo loop's default 2.5 kHz.
const PACED_NS: u64 = 400_000;
/// The paced rows' round trips at most (2 s each).
const PACED_SAMPLES: usize = 5_000;

/// Runs `ipc`.
pub fn run(a: &IpcArgs) -> anyhow::Result<()> {
    let bin_dir = qmarc_program::process::bin_dir(a.bin_dir.as_deref())?;
    // As the servo thread holds it during a move: no CPU of ours sleeps deeply between
    // exchanges (a deep idle state's exit would be in the paced rows).
    let _dma = DmaLatencyGuard::request_zero();
    let n = a.samples.max(100);
    let row = |name, us| Row { name, us };
    let x = |mode| exchange(n, &bin_dir, mode);
    let paced = Mode { paced_ns: Some(PACED_NS), ..Mode::default() };
    let n_paced = n.min(PACED_SAMPLES);
    // Measured in this order, one after the other; the ratios below name what they divide.
    let blocking = x(Mode::default())?;
    let blocking_one_cpu = x(Mode { cpu: Some(0), ..Mode::default() })?;
    let spinning = x(Mode { spin: true, ..Mode::default() })?;
    let ports = iox_ports(n)?;
    let futex = ping_pong(n, true, true, None)?;
    let futex_one_cpu = ping_pong(n, true, true, Some(0))?;
    let process_futex = futex_ping_pong_processes(n, None)?;
    let process_futex_one_cpu = futex_ping_pong_processes(n, Some(0))?;
    let futex_other = ping_pong(n, true, false, None)?;
    let spin = ping_pong(n, false, false, None)?;
    let paced_blocking = exchange(n_paced, &bin_dir, paced)?;
    let paced_one_cpu = exchange(n_paced, &bin_dir, Mode { cpu: Some(0), ..paced })?;
    let rows = [
        row("controller ⇄ hwserver exchange (iceoryx2, blocking)", blocking),
        row("the same, both pinned to CPU 0", blocking_one_cpu),
        row("the same, hwserver spinning, controller polling", spinning),
        row("iceoryx2 request/response ports alone, both polling", ports),
        row("raw futex ping-pong, 2 threads, SCHED_FIFO", futex),
        row("the same, both pinned to CPU 0", futex_one_cpu),
        row("raw futex ping-pong, 2 processes, SCHED_FIFO", process_futex),
        row("the same, both pinned to CPU 0", process_futex_one_cpu),
        row("raw futex ping-pong, 2 threads, SCHED_OTHER", futex_other),
        row("raw spin ping-pong, 2 threads, SCHED_OTHER", spin),
        row("blocking, one exchange per 400 µs tick (asleep between)", paced_blocking),
        row("the same, both pinned to CPU 0", paced_one_cpu),
    ];
    println!("qmarc-bench ipc: {n} round trips per row, µs");
    println!("  {:<55} {:>8} {:>8} {:>8} {:>9}", "", "p50", "p99", "p99.9", "max");
    for Row { name, us: p } in &rows {
        println!("  {name:<55} {:>8.2} {:>8.2} {:>8.2} {:>9.1}", p.p50, p.p99, p.p999, p.max);
    }
    let over = |a: Pct, b: Pct| a.p50.max(1e-3) / b.p50.max(1e-3);
    let report = Report {
        samples: n,
        machine: Machine::here(),
        rows: &rows,
        blocking_over_futex: over(blocking, futex),
        one_cpu_over_futex: over(blocking_one_cpu, futex_one_cpu),
        blocking_over_process_futex: over(blocking, process_futex),
        one_cpu_over_process_futex: over(blocking_one_cpu, process_futex_one_cpu),
        spinning_over_spin: over(spinning, spin),
        ports_over_spin: over(ports, spin),
        paced_over_back_to_back: over(paced_blocking, blocking),
    };
    println!(
        "  blocking exchange p50 = {:.2}× the futex ping-pong's at the same policy ({:.2}× with \
         both on one CPU), {:.2}× the ping-pong between processes ({:.2}× on one CPU); \
         spinning exchange p50 = {:.1}× the spin ping-pong's, of which iceoryx2's ports alone \
         are {:.1}×; paced once per 400 µs the blocking exchange p50 is \
         {:.1}× its back-to-back one (both ends asleep between, as in the servo loop)",
        report.blocking_over_futex,
        report.one_cpu_over_futex,
        report.blocking_over_process_futex,
        report.one_cpu_over_process_futex,
        report.spinning_over_spin,
        report.ports_over_spin,
        report.paced_over_back_to_back
    );
    if let Some(path) = &a.json {
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text + "\n")
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
        println!("  JSON: {}", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cyclictest_histograms_give_p99_and_max() {
        let text = "# /dev/cpu_dma_latency set to 0us\n000010 000050\n000011 000049\n000012 000001\n# Total: 000000100\n# Max Latencies: 00012\n";
        assert_eq!(parse_cyclictest(text), Some((11.0, 12.0)));
        assert_eq!(parse_cyclictest("# nothing\n"), None);
    }
}
