//! The summary table the starter prints after a move (the figures QMARC users tune by,
//! thesis 3.4 and 5.2).

use qmarc_controller::summary::{Pct, Summary};
use std::fmt::Write;
use std::path::Path;

/// Renders `s` as a table for the terminal; `out_dir` is where the data files are.
pub fn render(s: &Summary, out_dir: &Path) -> String {
    let mut t = String::new();
    let verdict = match &s.fault {
        None if s.ok => "ok".to_string(),
        None => "FAILED".to_string(),
        Some(f) => format!("FAULT {}: {}", f.kind, f.message),
    };
    let _ = writeln!(
        t,
        "QMARC {}{}: {verdict}\n  {} motors, {} cycles of {} µs, {}{}{}",
        s.mode,
        if s.trajectory == s.mode { String::new() } else { format!(" ({})", s.trajectory) },
        s.motors.len(),
        s.cycles,
        s.period_us,
        s.timing.policy,
        if s.degraded { " — DEGRADED: not real time" } else { "" },
        if s.deterministic { ", deterministic (simulated time)" } else { "" },
    );
    if let Some(motors) = s.homing.as_ref().and_then(|h| h["motors"].as_array()) {
        let _ = writeln!(t, "\n  homing (counts in the frame before homing)");
        for r in motors {
            let f = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
            let _ = writeln!(
                t,
                "  motor {}: top switch found at {:.0}{}, cleared at {:.0}; home at {:.0}{}",
                r["motor"],
                f("switch_found_counts"),
                if r["started_on_switch"].as_bool() == Some(true) {
                    " (started on it)"
                } else {
                    ""
                },
                f("switch_cleared_counts"),
                f("home_counts"),
                if r["home"].as_bool() == Some(true) {
                    ", reads 0 from now on"
                } else {
                    " — not reached"
                },
            );
        }
    }
    let _ = writeln!(t, "\n  following error (command − actual)");
    let _ = writeln!(
        t,
        "  {:>5} {:>10} {:>10} {:>14} {:>16} {:>11} {:>11} {:>11} {:>12}",
        "motor",
        "min cnt",
        "max cnt",
        "Σ|e| cnt",
        "Σe² cnt²",
        "min rad",
        "max rad",
        "Σ|e| rad",
        "Σe² rad²"
    );
    for (i, m) in s.motors.iter().enumerate() {
        let _ = writeln!(
            t,
            "  {:>5} {:>10.1} {:>10.1} {:>14.1} {:>16.1} {:>11.3e} {:>11.3e} {:>11.4} {:>12.4e}",
            i + 1,
            m.min_error_counts,
            m.max_error_counts,
            m.accumulated_abs_error_counts,
            m.sum_squares_error_counts2,
            m.min_error_rad,
            m.max_error_rad,
            m.accumulated_abs_error_rad,
            m.sum_squares_error_rad2,
        );
    }
    if let Some(st) = &s.settle {
        let list = |v: &[f64]| v.iter().map(|e| format!("{e:.1}")).collect::<Vec<_>>().join(" ");
        let _ = writeln!(
            t,
            "\n  settle, last command held {:.3} s ({} cycles): error at its end {} cnt, largest |e| {} cnt",
            st.seconds,
            st.cycles,
            list(&st.final_error_counts),
            list(&st.max_abs_error_counts),
        );
    }
    let tm = &s.timing;
    let _ = writeln!(t, "\n  timing, µs ({})      p50      p99    p99.9      max", tm.method);
    let row = |t: &mut String, name: &str, p: &Pct| {
        let _ = writeln!(
            t,
            "  {name:<20} {:>8.0} {:>8.0} {:>8.0} {:>8.1}",
            p.p50, p.p99, p.p999, p.max
        );
    };
    row(&mut t, "wake latency", &tm.wake_latency_us);
    row(&mut t, "period error", &tm.period_error_us);
    row(&mut t, "read round trip", &tm.read_us);
    row(&mut t, "trajectory + law", &tm.compute_us);
    row(&mut t, "tick → DAC written", &tm.output_latency_us);
    let _ = writeln!(
        t,
        "  periods off by > 40 µs: {}   missed periods: {}",
        tm.outside_40us, tm.missed_periods
    );
    for w in &s.warnings {
        let _ = writeln!(t, "  warning: {w}");
    }
    let _ = writeln!(
        t,
        "\n  data ({} rows, every {} cycles): {}",
        s.gathered_rows,
        s.gather_every,
        ["gather.csv", "gather.m", "summary.json"]
            .map(|f| out_dir.join(f).display().to_string())
            .join(", ")
    );
    t
}
