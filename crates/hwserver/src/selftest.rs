//! `qmarc-hwserver --backend s626 --device PATH --selftest`: what a user runs first on the real
//! PC. It opens the card and checks it is a 626 as its driver presents it, shows what each
//! motor's counter and switches read now (a wiring check), times the read and the write
//! instruction lists of a servo cycle N times, and enables nothing: the write list carries
//! 0 V on every DAC, every enable off and a still charge pump.

use crate::backend::{Backend, BackendOpenError, Inputs};
use crate::backends::s626::S626;
use qmarc_config::Settings;
use qmarc_proto::Status;
use qmarc_timer::clock::monotonic_now_ns;
use std::fmt::Write;

/// Nearest-rank percentiles of durations, µs: p50, p99, p99.9, max.
fn percentiles(mut ns: Vec<u64>) -> [f64; 4] {
    ns.sort_unstable();
    let at = |p: f64| {
        let rank = ((p * ns.len() as f64).ceil() as usize).clamp(1, ns.len().max(1));
        ns.get(rank - 1).map_or(0.0, |&v| v as f64 / 1e3)
    };
    [at(0.5), at(0.99), at(0.999), ns.last().map_or(0.0, |&v| v as f64 / 1e3)]
}

/// Times `f` `count` times, ns each; stops at the first error.
fn time(
    count: u32,
    mut f: impl FnMut() -> Result<(), crate::HwFault>,
) -> Result<Vec<u64>, crate::HwFault> {
    let mut ns = Vec::with_capacity(count as usize);
    for _ in 0..count {
        let t0 = monotonic_now_ns();
        f()?;
        ns.push(monotonic_now_ns() - t0);
    }
    Ok(ns)
}

/// Runs the selftest on the 626 of `s`, `count` lists of each kind; the report, or why the
/// card cannot be used.
pub fn run(s: &Settings, count: u32) -> Result<String, BackendOpenError> {
    if s.hwserver.backend != qmarc_config::BackendKind::S626 {
        return Err(BackendOpenError::Invalid(format!(
            "--selftest checks the Sensoray 626: give --backend s626 (the settings say `{}`)",
            s.hwserver.backend
        )));
    }
    let mut card = S626::open(s, false)?;
    card.stop_charge_pump(); // the relay stays open: nothing can be enabled
    let fault = |what: &str, e: crate::HwFault| {
        BackendOpenError::Invalid(format!("{}: the {what} list failed: {e}", card_name(s)))
    };
    let mut now = Inputs::default();
    card.read_inputs(&mut now).map_err(|e| fault("read", e))?;
    let reads = time(count, || card.run_read_list()).map_err(|e| fault("read", e))?;
    let writes = time(count, || card.run_write_list()).map_err(|e| fault("write", e))?;
    card.safe_state();
    Ok(report(s, &now, count, percentiles(reads), percentiles(writes)))
}

fn card_name(s: &Settings) -> String {
    s.s626.device.display().to_string()
}

fn report(s: &Settings, now: &Inputs, count: u32, read: [f64; 4], write: [f64; 4]) -> String {
    let w = &s.s626;
    let n = s.n_motors;
    let mut out = format!(
        "QMARC selftest: {} is a Sensoray 626 (driver s626; AO, DIO bank 0 and the counters \
         locked)\n\n",
        card_name(s)
    );
    let side = |active: bool| if active { "TRIPPED (or its wire is broken)" } else { "closed" };
    for m in 0..n {
        let _ = writeln!(
            out,
            "  motor {}: counter {} reads {:>8}, top switch DIO{} {}, bottom switch DIO{} {}",
            m + 1,
            ["0A", "1A", "2A", "0B", "1B", "2B"][w.counter_channels[m] as usize % 6],
            now.counters[m],
            w.limit_top_dio[m],
            side(now.limits.contains(Status::limit_top(m))),
            w.limit_bottom_dio[m],
            side(now.limits.contains(Status::limit_bottom(m))),
        );
    }
    let _ = writeln!(
        out,
        "\n  {:<34}{:>9}{:>9}{:>10}{:>9}",
        format!("instruction lists, {count} of each"),
        "p50 µs",
        "p99 µs",
        "p99.9 µs",
        "max µs"
    );
    for (name, p) in [
        (format!("read  ({n} counters + DIO bank 0)"), read),
        (format!("write ({n} DACs + DIO bank 0)"), write),
    ] {
        let _ = writeln!(out, "  {name:<34}{:>9.2}{:>9.2}{:>10.2}{:>9.2}", p[0], p[1], p[2], p[3]);
    }
    let _ = writeln!(
        out,
        "\n  a servo cycle runs both: {:.1} µs at p99 of its {} µs period ({:.0} %)\n  \
         nothing was enabled; every DAC at 0 V",
        read[1] + write[1],
        s.period_us,
        100.0 * (read[1] + write[1]) / f64::from(s.period_us)
    );
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn percentiles_are_nearest_rank() {
        let ns: Vec<u64> = (1..=1000).map(|v| v * 1000).collect();
        assert_eq!(super::percentiles(ns), [500.0, 990.0, 999.0, 1000.0]);
        assert_eq!(super::percentiles(vec![]), [0.0; 4]);
    }
}
