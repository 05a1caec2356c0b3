//! The summary table the starter prints after a move (the figures QMARC users tune by,
//! thesis 3.4 and 5.2). Columns are as wide as their widest cell, so figures never run
//! together; times are in µs, ms or s as fits.

use crate::summary::{MotorSummary, Pct, Summary};
use std::fmt::Write;

/// The open-loop check: per motor what it did and what it means.
fn check_lines(t: &mut String, check: &[crate::check::MotorCheck]) {
    if let Some(first) = check.first() {
        let _ = writeln!(
            t,
            "\n  open-loop check: {:.2} V for {} on each motor in turn, the loop open",
            first.volts,
            human_s(first.seconds)
        );
    }
    let mut rows =
        vec![["motor", "moved cnt", "cnt/s per V", "expected", ""].map(String::from).to_vec()];
    for m in check {
        rows.push(vec![
            m.motor.to_string(),
            format!("{:.1}", m.moved_counts),
            format!("{:.0}", m.counts_per_volt_second),
            format!("{:.0}", m.expected_counts_per_volt_second),
            if m.ok { "ok".into() } else { "CHANGE".into() },
        ]);
    }
    aligned(t, &rows);
    for m in check {
        let _ = writeln!(t, "  {}", m.advice);
    }
}

/// Renders `s` as a table for the terminal, ending with the data files it wrote that exist.
pub fn render(s: &Summary) -> String {
    let mut t = String::new();
    headline(&mut t, s);
    if let Some(check) = &s.check {
        check_lines(&mut t, check);
    }
    if let Some(homing) = &s.homing {
        homing_lines(&mut t, homing);
    }
    error_lines(&mut t, s);
    approach_and_settle_lines(&mut t, s);
    conveyor_line(&mut t, s);
    timing_lines(&mut t, &s.timing);
    warnings_and_files(&mut t, s);
    t
}

/// What the move was and how it ended, on two lines.
fn headline(t: &mut String, s: &Summary) {
    let check_failed = s.check.as_ref().is_some_and(|c| c.iter().any(|m| !m.ok));
    let verdict = match &s.fault {
        None if check_failed => "CHECK FAILED: see below what to change".to_string(),
        None if s.ok && s.check.is_some() => "ok".to_string(),
        None if s.ok && s.motors.iter().all(|m| m.followed) => "ok".to_string(),
        None if s.ok => "done, but a motor did not follow its command (see the warnings)".into(),
        None => "FAILED".to_string(),
        Some(f) => format!("FAULT {}: {}", f.kind, f.message),
    };
    let n_motors = if s.n_motors > 0 { s.n_motors } else { s.motors.len() };
    let _ = writeln!(
        t,
        "QMARC {}: {verdict}\n  {} motors, {} cycles of {} µs{}{}{}",
        s.what(),
        n_motors,
        s.cycles,
        s.period_us,
        if s.timing.policy.is_empty() { String::new() } else { format!(", {}", s.timing.policy) },
        if s.degraded { " — DEGRADED: not real time" } else { "" },
        if s.deterministic { ", deterministic (simulated time)" } else { "" },
    );
}

/// Where homing found each switch and put home.
fn homing_lines(t: &mut String, homing: &crate::summary::HomingReport) {
    let _ = writeln!(t, "\n  homing (counts in the frame before homing)");
    // Home reads 0 only where the hwserver read the frame homed after the preset (a
    // homing that failed, or a frame that could not be kept, leaves it unhomed).
    let homed_after =
        |i: usize| homing.after.as_ref().and_then(|a| a.homed.get(i)).copied().unwrap_or(false);
    // A count homing did not get to is said so, not read as 0.
    let at = |v: Option<f64>| v.map_or("not reached".to_string(), |c| format!("at {c:.0}"));
    for (i, r) in homing.motors.iter().enumerate() {
        let _ = writeln!(
            t,
            "  motor {}: top switch found {}{}, cleared {}; home {}{}",
            r.motor,
            at(r.switch_found_counts),
            if r.started_on_switch { " (started on it)" } else { "" },
            at(r.switch_cleared_counts),
            at(r.home_counts),
            match (r.home, homed_after(i)) {
                (true, true) => ", reads 0 from now on",
                (true, false) => ", reached, but its frame is not homed (see the fault)",
                (false, _) if r.home_counts.is_some() => " — not reached",
                (false, _) => "",
            },
        );
    }
}

/// The following errors of the path, per cycle and over the gathered rows, and the end-effector's (none for the check, whose command is where the motors are).
fn error_lines(t: &mut String, s: &Summary) {
    // The check's command is where the motors are: it has no following error to show.
    let closed_loop = s.check.is_none();
    if !s.motors.is_empty() && closed_loop {
        let _ = writeln!(t, "\n  following error (command − actual), every cycle of the path");
        error_table(t, &s.motors, true);
    }
    match &s.gathered {
        Some(g) if g.every > 1 => {
            let _ = writeln!(
                t,
                "\n  the same over the {} gathered rows of the path (every {} cycles, as the thesis summed them)",
                g.rows, g.every
            );
            error_table(t, &g.motors, false);
        }
        _ => {}
    }
    if let Some(e) = s.effector.as_ref().filter(|_| closed_loop) {
        let _ = writeln!(
            t,
            "\n  end-effector error (command − actual through the forward kinematics), {} rows{}",
            e.rows,
            if e.no_pose_rows > 0 {
                format!(", {} without a pose left out", e.no_pose_rows)
            } else {
                String::new()
            }
        );
        let mut rows =
            vec![["", "min mm", "max mm", "RMS mm", "max |e| mm"].map(String::from).to_vec()];
        for (name, a) in [("x", &e.x), ("y", &e.y), ("z", &e.z), ("distance", &e.distance)] {
            rows.push(vec![
                name.to_string(),
                format!("{:.3}", a.min_mm),
                format!("{:.3}", a.max_mm),
                format!("{:.3}", a.rms_mm),
                format!("{:.3}", a.max_abs_mm),
            ]);
        }
        aligned(t, &rows);
    }
}

/// The approach before the path and the settle after it.
fn approach_and_settle_lines(t: &mut String, s: &Summary) {
    if let Some(a) = &s.approach {
        let list = |v: &[f64]| v.iter().map(|e| format!("{e:.1}")).collect::<Vec<_>>().join(" ");
        let _ = writeln!(
            t,
            "\n  approach to the path's start from {} cnt, before the figures above: {} ({} \
             cycles), largest |e| {} cnt",
            list(&a.from_counts),
            human_s(a.seconds),
            a.cycles,
            list(&a.max_abs_error_counts),
        );
    }
    if let Some(st) = &s.settle {
        let list = |v: &[f64]| v.iter().map(|e| format!("{e:.1}")).collect::<Vec<_>>().join(" ");
        let _ = writeln!(
            t,
            "\n  settle, last command held {} ({} cycles): error at its end {} cnt, largest |e| {} cnt",
            human_s(st.seconds),
            st.cycles,
            list(&st.final_error_counts),
            list(&st.max_abs_error_counts),
        );
    }
}

/// A conveyor session's parts.
fn conveyor_line(t: &mut String, s: &Summary) {
    if let Some(c) = &s.conveyor {
        let _ = writeln!(
            t,
            "\n  parts: {} picked, {} missed, {} pending ({:.1} picks/min); grip error max {:.2} \
             mm, RMS {:.2} mm; while closing max {:.2} mm",
            c.picked,
            c.missed,
            c.pending,
            c.picks_per_min,
            c.grip_error_mm.max,
            c.grip_error_mm.rms,
            c.closing_error_max_mm,
        );
    }
    if let Some(c) = &s.cell {
        let _ = writeln!(
            t,
            "  cell {}, robot {}: {} picked, {} passed to the others, {} missed",
            c.name, c.robot, c.picked, c.passed, c.missed
        );
    }
}

/// The loop's timing figures.
fn timing_lines(t: &mut String, tm: &crate::summary::TimingSummary) {
    if tm.method == crate::summary::UNPACED {
        let _ = writeln!(
            t,
            "\n  timing: none to show — unpaced (--unpaced), each cycle followed the last at once"
        );
    } else if !tm.method.is_empty() {
        let _ = writeln!(t, "\n  timing ({})", tm.method);
        let mut rows = vec![["", "p50", "p99", "p99.9", "max"].map(String::from).to_vec()];
        for (name, p) in [
            ("wake latency", &tm.wake_latency_us),
            ("period error", &tm.period_error_us),
            ("read round trip", &tm.read_us),
            ("trajectory + law", &tm.compute_us),
            ("tick → DAC written", &tm.output_latency_us),
        ] {
            rows.push(pct_row(name, p));
        }
        aligned(t, &rows);
        let _ = write!(
            t,
            "  periods off by > 40 µs: {}   missed periods: {}",
            tm.outside_40us, tm.missed_periods
        );
        let _ = match tm.missed_in_stalls {
            0 => writeln!(t),
            n => writeln!(t, " ({n} of them in host stalls of ≥ 1 ms)"),
        };
    }
}

/// The warnings, then the data files the move wrote that exist.
fn warnings_and_files(t: &mut String, s: &Summary) {
    for w in &s.warnings {
        let _ = writeln!(t, "  warning: {w}");
    }
    let files: Vec<String> =
        s.files.iter().filter(|f| f.exists()).map(|f| f.display().to_string()).collect();
    if files.is_empty() {
        let _ = writeln!(t, "\n  no data files: the move wrote none");
    } else {
        let _ = writeln!(
            t,
            "\n  data ({} rows, every {} cycles): {}",
            s.gathered_rows,
            s.gather_every,
            files.join(", ")
        );
    }
}

/// The thesis' Table 5-2 columns per motor, in counts and rad; `followed` marks a motor that
/// did not follow its command.
fn error_table(t: &mut String, motors: &[MotorSummary], followed: bool) {
    let mut rows = vec![
        [
            "motor",
            "min cnt",
            "max cnt",
            "Σ|e| cnt",
            "Σe² cnt²",
            "min rad",
            "max rad",
            "Σ|e| rad",
            "Σe² rad²",
        ]
        .map(String::from)
        .to_vec(),
    ];
    for (i, m) in motors.iter().enumerate() {
        rows.push(vec![
            format!("{}{}", i + 1, if m.followed || !followed { "" } else { " DID NOT FOLLOW" }),
            format!("{:.1}", m.min_error_counts),
            format!("{:.1}", m.max_error_counts),
            format!("{:.1}", m.accumulated_abs_error_counts),
            format!("{:.1}", m.sum_squares_error_counts2),
            format!("{:.3e}", m.min_error_rad),
            format!("{:.3e}", m.max_error_rad),
            format!("{:.4}", m.accumulated_abs_error_rad),
            format!("{:.4e}", m.sum_squares_error_rad2),
        ]);
    }
    aligned(t, &rows);
}

/// A timing row: the name, then p50/p99/p99.9/max in human units.
fn pct_row(name: &str, p: &Pct) -> Vec<String> {
    let mut row = vec![name.to_string()];
    row.extend([p.p50, p.p99, p.p999, p.max].map(human_us));
    row
}

/// A duration given in µs as a person reads it: `37 µs`, `1.24 ms`, `2.5 s`.
pub fn human_us(us: f64) -> String {
    if us < 1_000.0 {
        format!("{us:.0} µs")
    } else if us < 1_000_000.0 {
        format!("{:.2} ms", us / 1e3)
    } else {
        format!("{:.2} s", us / 1e6)
    }
}

/// A duration given in s, as [`human_us`].
pub fn human_s(s: f64) -> String {
    human_us(s * 1e6)
}

/// Appends `rows` with every column as wide as its widest cell: the first left-aligned, the
/// others right-aligned, two spaces between columns, two spaces of indent.
fn aligned(t: &mut String, rows: &[Vec<String>]) {
    let cols = rows.iter().map(Vec::len).max().unwrap_or(0);
    let width: Vec<usize> = (0..cols)
        .map(|c| rows.iter().filter_map(|r| r.get(c)).map(|s| s.chars().count()).max().unwrap_or(0))
        .collect();
    for r in rows {
        let mut line = String::from(" ");
        for (c, cell) in r.iter().enumerate() {
            let pad = width[c] - cell.chars().count();
            if c == 0 {
                let _ = write!(line, " {cell}{}", " ".repeat(pad));
            } else {
                let _ = write!(line, "  {}{cell}", " ".repeat(pad));
            }
        }
        let _ = writeln!(t, "{}", line.trim_end());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qmarc_config::Mode;

    /// Issue 42: a homing that ended before a motor's switch was found says so, not "found
    /// at 0".
    #[test]
    fn what_homing_did_not_reach_is_said_not_reached() {
        use crate::summary::{HomingReport, MotorHome};
        let done = MotorHome {
            motor: 1,
            switch_found_counts: Some(-4500.0),
            switch_cleared_counts: Some(-4498.0),
            home_counts: Some(-2498.0),
            ended_counts: Some(-2498.0),
            started_on_switch: false,
            home: true,
        };
        let begun = MotorHome { motor: 3, ..MotorHome::default() };
        let mut t = String::new();
        homing_lines(&mut t, &HomingReport { motors: vec![done, begun], after: None });
        assert!(t.contains("motor 1: top switch found at -4500, cleared at -4498; home at -2498"));
        assert!(
            t.contains(
                "motor 3: top switch found not reached, cleared not reached; home not reached\n"
            ),
            "{t}"
        );
        let json = serde_json::to_string(&begun).unwrap();
        assert!(json.contains("\"switch_found_counts\":null"), "{json}");
    }

    #[test]
    fn durations_are_in_human_units() {
        assert_eq!(human_us(37.4), "37 µs");
        assert_eq!(human_us(1_240.0), "1.24 ms");
        assert_eq!(human_us(142_030.3), "142.03 ms");
        assert_eq!(human_us(2_500_000.0), "2.50 s");
    }

    /// Issue 10, item 15: wide figures do not run together.
    #[test]
    fn columns_never_run_together() {
        let mut t = String::new();
        let rows = vec![
            vec!["wake latency".to_string(), "142030.25".into(), "1".into()],
            vec!["x".to_string(), "2".into(), "99999999.5".into()],
        ];
        aligned(&mut t, &rows);
        assert_eq!(
            t,
            "  wake latency  142030.25           1\n  x                     2  99999999.5\n"
        );
    }

    /// A robot of a cell says its share: picked, passed to the others, missed.
    #[test]
    fn a_cell_robot_says_its_share() {
        let mut s = Summary::controller_lost((Mode::Step, true), 3, 400, 10, "x".into());
        assert!(!render(&s).contains("cell "));
        s.cell = Some(crate::summary::CellSummary {
            name: "belt1".into(),
            robot: "west".into(),
            picked: 24,
            passed: 23,
            missed: 1,
        });
        let t = render(&s);
        assert!(
            t.contains("  cell belt1, robot west: 24 picked, 23 passed to the others, 1 missed\n"),
            "{t}"
        );
    }

    /// Issue 28, item 8: an unpaced move has no timing to show, and says so (before: "periods
    /// off by > 40 µs: 500499"); a paced one shows its table.
    #[test]
    fn an_unpaced_move_says_it_has_no_timing() {
        let mut s = Summary::controller_lost((Mode::Step, true), 3, 400, 10, "x".into());
        s.timing.method = crate::summary::UNPACED.to_string();
        s.timing.outside_40us = 500_499;
        let t = render(&s);
        assert!(t.contains("timing: none to show — unpaced (--unpaced)"), "{t}");
        assert!(!t.contains("periods off by"), "{t}");
        s.timing.method = "timerfd".to_string();
        assert!(render(&s).contains("periods off by > 40 µs: 500499"));
    }
}
