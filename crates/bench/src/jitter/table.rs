//! The table `qmarc-bench jitter` prints: per timer, each round's loops, the p99 ratio, the
//! missed periods and the noisy-host verdict, then cyclictest's figures.

use super::{JitterArgs, Missed, Pin, TimerResult};

/// The table `jitter` prints.
pub fn render(
    a: &JitterArgs,
    results: &[TimerResult],
    cyclic: Option<&crate::ipc::Cyclictest>,
) -> String {
    use std::fmt::Write;
    let mut t = String::new();
    let _ = writeln!(
        t,
        "qmarc-bench jitter: {} µs, {} interleaved rounds of {} s per loop{}{}{}",
        a.period_us,
        a.rounds,
        a.segment_s,
        if results.len() > 1 { ", the timers taking turns within each round" } else { "" },
        if a.spin { ", hwserver spinning" } else { "" },
        a.pin.map_or("", Pin::describe)
    );
    for r in results {
        let _ = writeln!(
            t,
            "\n  timer {}: wake latency µs (against the intended expiry)\n  round first  loop    p50    p99  p99.9      max  missed (in stalls)  >±40µs  out p99",
            r.timer
        );
        for round in &r.rounds {
            let rows = [Some(("bare", &round.bare)), round.worked.as_ref().map(|w| ("busy", w))];
            for (name, f) in rows.into_iter().flatten().chain([("servo", &round.servo)]) {
                let out = f.output_us.map_or("—".to_string(), |o| format!("{:.0}", o.p99));
                let _ = writeln!(
                    t,
                    "  {:>5} {:<6} {name:<5} {:>6.0} {:>6.0} {:>6.0} {:>8.0} {:>7} {:>10} {:>7} {:>8}{}",
                    if name == "bare" { round.round.to_string() } else { String::new() },
                    if name == "bare" { round.first } else { "" },
                    f.wake_us.p50,
                    f.wake_us.p99,
                    f.wake_us.p999,
                    f.wake_us.max,
                    f.missed,
                    format!("({})", f.missed_in_stalls),
                    f.outside_40us,
                    out,
                    f.fault.as_ref().map_or(String::new(), |x| format!("  FAULT {x}")),
                );
            }
        }
        let _ = writeln!(
            t,
            "  p99 ratio servo/bare: median {:.2} (min {:.2}, max {:.2}); p99 difference median {:+.0} µs",
            r.p99_ratio_median, r.p99_ratio_min, r.p99_ratio_max, r.p99_diff_us_median,
        );
        let _ = writeln!(t, "  {}", missed_line(&r.missed()));
        if let (Some(work), Some(n), Some(out), Some((all, out_rate))) =
            (a.bare_work_us, r.missed_worked, r.missed_worked_outside_stalls, r.worked_rates())
        {
            let _ = writeln!(
                t,
                "  the bare loop busy {work} µs after each wake (\"busy\"): missed {n} ({all:.0} per \
                 100 000), outside host stalls {out} ({out_rate:.0}) — the machine's own figure \
                 for a loop that works as long as ours"
            );
        }
        let _ = writeln!(
            t,
            "  {}",
            if r.noisy_host {
                format!("host too noisy — ratio not meaningful: {}", r.noisy_reasons.join("; "))
            } else if r.p99_ratio_median <= 1.3 {
                "quiet host: median ratio ≤ 1.3 (the goal)".to_string()
            } else {
                "quiet host: median ratio above the 1.3 goal".to_string()
            }
        );
    }
    if let Some(m) = Missed::of_all(results) {
        let _ = writeln!(t, "\n  all timers together: {}", missed_line(&m));
    }
    let _ = writeln!(t, "\n  {}", crate::ipc::describe_cyclictest(cyclic));
    t
}

/// "missed periods servo … / bare … (per 100 000 …); outside host stalls …".
fn missed_line(m: &Missed) -> String {
    let ((all_s, all_b), (out_s, out_b)) = (m.rates(false), m.rates(true));
    format!(
        "missed periods servo {} / bare {} (per 100 000 periods {all_s:.0} / {all_b:.0}); \
         outside host stalls (a wake ≥ 1 ms late) servo {} / bare {} ({out_s:.0} / {out_b:.0})",
        m.servo, m.bare, m.servo_outside_stalls, m.bare_outside_stalls
    )
}
