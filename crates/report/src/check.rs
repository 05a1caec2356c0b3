//! The open-loop check's report (`qmarc-starter check`, `summary.json`'s `check`): per motor,
//! which way it counted for a positive voltage and how fast against what the feed-forward
//! expects of the amplifier, whether another motor moved with it, and what to change.

use qmarc_config::Settings;
use qmarc_plugins::check::MotorCheckReport;
use serde::{Deserialize, Serialize};

/// A motor that moved less than this share of what the feed-forward expects did not move.
const STILL_SHARE: f64 = 0.05;

/// The amplifier's speed against the feed-forward's may be off by this factor either way
/// before the check says so.
const SCALE_TOLERANCE: f64 = 2.0;

/// One motor's check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MotorCheck {
    /// 1-based motor.
    pub motor: usize,
    /// The voltage it got, V.
    pub volts: f64,
    /// For how long, s.
    pub seconds: f64,
    /// How far it moved for it, counts: while driven and in the rest after (a velocity loop's
    /// lag moves it on for a moment).
    pub moved_counts: f64,
    /// What that makes of the amplifier: counts/s per volt.
    pub counts_per_volt_second: f64,
    /// What the feed-forward gains expect of it (eq. 3-1: the amplifier whose speed Kvff − Kd
    /// exactly supplies), counts/s per volt.
    pub expected_counts_per_volt_second: f64,
    /// The largest distance another motor moved while this one was driven, counts, and which.
    pub other_motor: usize,
    /// That distance.
    pub other_moved_counts: f64,
    /// Direction right, speed within a factor of two of the feed-forward's, nothing else
    /// moving, and its pulse ran to its end.
    pub ok: bool,
    /// What it means, and what to change.
    pub advice: String,
}

/// The gain (counts/s per volt) of the amplifier whose speed the feed-forward of eq. 3-1 exactly
/// supplies: for a motion at v counts/s, CV = AV = v·T counts per period, the output is
/// 2⁻²¹·Kp·(Kvff − Kd)·v·T/128 codes = that × 10/8191 V, which must ask v.
pub fn expected_counts_per_volt_second(s: &Settings, motor: usize) -> f64 {
    let g = s.effective_gains(motor);
    let volts_per_count_per_s = g.kp * (g.kvff - g.kd) * s.period_s() / 128.0 / 2_097_152.0
        * qmarc_proto::DAC_FULL_SCALE_V
        / f64::from(qmarc_proto::DAC_MAX);
    1.0 / volts_per_count_per_s
}

impl MotorCheck {
    /// The check of `r` on the robot of `s`.
    pub fn of(s: &Settings, r: &MotorCheckReport) -> MotorCheck {
        let m = r.motor - 1;
        let moved = r.moved_counts + r.coasted_counts;
        let rate = moved / (r.volts * r.seconds);
        let expected = expected_counts_per_volt_second(s, m);
        // Gains without a velocity feed-forward (Kvff ≤ Kd) expect no speed: judge the
        // direction and the wiring only.
        let judged = expected.is_finite() && expected > 0.0;
        let (other, other_moved) = r.others_moved;
        let crossed = other > 0 && other_moved > (0.1 * moved.abs()).max(10.0);
        let still = if judged { rate.abs() < STILL_SHARE * expected } else { moved.abs() < 2.0 };
        let scale_ok =
            !judged || (expected / SCALE_TOLERANCE..=expected * SCALE_TOLERANCE).contains(&rate);
        let advice = if !r.done {
            format!("motor {}: its pulse was cut short: see the fault", r.motor)
        } else if still {
            format!(
                "motor {}: did not move ({moved:.0} counts for {} V over {} s): its amplifier \
                 is off, not wired or not in velocity mode, or the safety chain holds it",
                r.motor, r.volts, r.seconds
            )
        } else if rate < 0.0 {
            let toward_top = if s.safety[m].top_direction < 0.0 { "down" } else { "up" };
            format!(
                "motor {}: counted DOWN ({moved:.0} counts) for a positive voltage: a closed \
                 loop would run away. If the motor turned away from its top switch (counts {} \
                 that way) the encoder counts backwards: set motor {}'s entry of \
                 s626.counter_sign to -1; if it turned toward it, the amplifier is wired \
                 backwards: set motor {}'s entry of s626.dac_sign to -1",
                r.motor,
                if toward_top == "down" { "going up" } else { "going down" },
                r.motor,
                r.motor
            )
        } else if crossed {
            format!(
                "motor {}: motor {other} moved {other_moved:.0} counts while motor {} was \
                 driven: its DAC or its counter is crossed with motor {other}'s \
                 (s626.dac_channels, s626.counter_channels)",
                r.motor, r.motor
            )
        } else if !judged {
            format!(
                "motor {}: counts up at {rate:.0} counts/s per V; its gains have no velocity \
                 feed-forward to compare with (Kvff ≤ Kd)",
                r.motor
            )
        } else if !scale_ok {
            format!(
                "motor {}: counts up at {rate:.0} counts/s per V, but the feed-forward expects \
                 {expected:.0}: the amplifier's speed scale and the gains disagree {:.1}×; set \
                 the amplifier to {expected:.0} counts/s per V, or scale Kvff by {:.2}",
                r.motor,
                (rate / expected).max(expected / rate),
                expected / rate
            )
        } else {
            format!(
                "motor {}: counts up at {rate:.0} counts/s per V, {:.2}× what the feed-forward \
                 expects: direction and scale agree",
                r.motor,
                rate / expected
            )
        };
        let ok = r.done && !still && rate > 0.0 && scale_ok && !crossed;
        MotorCheck {
            motor: r.motor,
            volts: r.volts,
            seconds: r.seconds,
            moved_counts: moved,
            counts_per_volt_second: rate,
            expected_counts_per_volt_second: expected,
            other_motor: other,
            other_moved_counts: other_moved,
            ok,
            advice,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped() -> Settings {
        let names = qmarc_config::Names {
            laws: vec!["pidff"],
            methods: vec!["step", "spline", "pvt"],
            any_plugin: false,
        };
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
        Settings::load(&path, &names).unwrap()
    }

    fn report(moved: f64, others: (usize, f64), done: bool) -> MotorCheckReport {
        MotorCheckReport {
            motor: 1,
            volts: 0.2,
            seconds: 0.1,
            moved_counts: moved,
            coasted_counts: 0.0,
            others_moved: others,
            done,
        }
    }

    /// Issue 27, item 3: the verdicts, from the shipped gains (motor 1 expects 26 037
    /// counts/s per V of its amplifier: 0.2 V for 0.1 s is 521 counts).
    #[test]
    fn the_check_judges_direction_scale_wiring_and_gains_without_feed_forward() {
        let s = shipped();
        let expected = expected_counts_per_volt_second(&s, 0);
        assert!((expected - 26_037.0).abs() < 1.0, "{expected}");
        let verdict = |r: MotorCheckReport| {
            let c = MotorCheck::of(&s, &r);
            (c.ok, c.advice)
        };
        let (ok, advice) = verdict(report(473.0, (0, 0.0), true));
        assert!(ok && advice.contains("0.91× what the feed-forward expects"), "{advice}");
        let (ok, advice) = verdict(report(-473.0, (0, 0.0), true));
        assert!(!ok && advice.contains("counted DOWN"), "{advice}");
        let (ok, advice) = verdict(report(3.0, (0, 0.0), true));
        assert!(!ok && advice.contains("did not move"), "{advice}");
        let (ok, advice) = verdict(report(473.0, (2, 200.0), true));
        assert!(!ok && advice.contains("motor 2 moved 200 counts while motor 1"), "{advice}");
        let (ok, advice) = verdict(report(100.0, (0, 0.0), true));
        assert!(!ok && advice.contains("disagree 5.2×"), "{advice}");
        let (ok, advice) = verdict(report(473.0, (0, 0.0), false));
        assert!(!ok && advice.contains("cut short"), "{advice}");
        // Kvff = 0: nothing to compare the speed with; the direction still counts.
        let mut no_ff = s.clone();
        no_ff.motors[0].kvff = 0.0;
        let c = MotorCheck::of(&no_ff, &report(473.0, (0, 0.0), true));
        assert!(c.ok && c.advice.contains("no velocity feed-forward"), "{c:?}");
        let c = MotorCheck::of(&no_ff, &report(-473.0, (0, 0.0), true));
        assert!(!c.ok && c.advice.contains("counted DOWN"), "{c:?}");
    }
}
