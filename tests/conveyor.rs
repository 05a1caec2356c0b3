//! `qmarc-starter conveyor` (issue 44): a serving session at the belt. The belt's encoder is
//! read in the same exchange as the motors' and gathered as `conv`; the session ends by
//! itself after `--seconds`, at rest, its data written.

use qmarc_tests::{TestRun, read_gather, read_summary};

/// The belt as the loop read it, at two servo periods: the same physical belt gives the
/// same counts against time (to a count's rounding), and the session ends after the seconds it was given, the periods it takes each way.
#[test]
fn the_belt_is_read_with_the_motors_and_the_session_ends_by_itself() {
    let run = TestRun::new("conveyor-belt");
    // Lock-step: the belt runs on the simulated robot's clock, every read one period on.
    let (speed, mm_per_count, seconds) = (400.0, 0.05, 1.0);
    for period_us in [400.0, 1600.0] {
        let config = run.config_with(&[]);
        let out = run.out(&format!("out-{period_us}"));
        let args = [
            format!("--config={}", config.display()),
            format!("--out={}", out.display()),
            format!("--period-us={period_us}"),
            "--deterministic".into(),
            "conveyor".into(),
            format!("--seconds={seconds}"),
            format!("--belt-mm-s={speed}"),
        ];
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        run.starter_ok(&args);
        let summary = read_summary(&out);
        assert!(summary.fault.is_none(), "{period_us} µs: {:?}", summary.fault);
        let (header, rows) = read_gather(&out);
        let col = |name: &str| header.iter().position(|h| h == name).unwrap();
        let (time, conv) = (col("time_s"), col("conv"));
        assert_eq!(header.last().map(String::as_str), Some("conv"), "{header:?}");
        // The belt ran before the loop began (the reads before it): the counts since its first
        // sample follow the time since it, to a count's rounding, while the session serves.
        // (Lock-step time is the simulated robot's reads: the end's own reads move it on.)
        let (t0, c0) = (rows[0][time], rows[0][conv]);
        for r in rows.iter().filter(|r| r[time] < seconds) {
            let expected = speed * (r[time] - t0) / mm_per_count;
            assert!(
                (r[conv] - c0 - expected).abs() <= 1.0 + 1e-9,
                "{period_us} µs at {} s: {} counts since the first sample, the belt's {expected}",
                r[time],
                r[conv] - c0
            );
        }
        // It quit after `seconds` of cycles, then settled: not before, and not long after.
        let last = rows.last().unwrap()[time];
        assert!(last >= seconds && last < seconds + 1.0, "{period_us} µs: ended at {last} s");
    }
    run.assert_clean();
}
