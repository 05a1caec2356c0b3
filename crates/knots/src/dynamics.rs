//! What a path asks of each motor, against its limits (`[[motor]]`
//! `max_velocity_counts_per_s`, `max_acceleration_counts_per_s2`): every segment of a path is
//! a cubic, whose acceleration is linear and whose velocity is a parabola, so its largest
//! velocity and acceleration are found exactly from its ends and the velocity's vertex — a
//! bound on every sample the loop takes of it. (A path may start or end moving, as the thesis'
//! natural splines do: the loop's first cycle starts it from rest, and after it the last
//! command is held with the loop closed; both within the velocity limit.)

use super::KnotRules;

/// A motion limit a path breaks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Excess {
    /// 0-based motor.
    pub motor: usize,
    /// What was asked: a velocity (counts/s) or an acceleration (counts/s²).
    pub value: f64,
    /// The limit.
    pub limit: f64,
    /// Which.
    pub kind: ExcessKind,
}

/// Which limit an [`Excess`] breaks, and where.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExcessKind {
    /// A segment's velocity.
    Velocity,
    /// A segment's acceleration.
    Acceleration,
}

/// `x` for a message: whole below 10⁷, in exponent notation with up to four digits beyond
/// (`1.2e7`, `1e308`).
fn rounded(x: f64) -> String {
    if x.abs() < 1e7 || !x.is_finite() {
        return format!("{}", x.round());
    }
    let s = format!("{x:.3e}");
    let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
    let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
    format!("{mantissa}e{exp}")
}

impl Excess {
    /// The words for it, motors 1-based, naming the setting it breaks.
    pub fn describe(&self) -> String {
        let (m, v, lim) = (self.motor + 1, rounded(self.value), super::num(self.limit));
        match self.kind {
            ExcessKind::Velocity => format!(
                "motor {m}: the path moves at {v} counts/s on its way to this knot, faster than \
                 motor {m}'s max_velocity_counts_per_s = {lim}"
            ),
            ExcessKind::Acceleration => format!(
                "motor {m}: the path accelerates at {v} counts/s² on its way to this knot, more \
                 than motor {m}'s max_acceleration_counts_per_s2 = {lim}"
            ),
        }
    }
}

/// The accelerations at both ends of the cubic from position `x0` at velocity `v0` to `x1` at
/// `v1` in `h` seconds (a PVT segment: with p = Aτ³ + Bτ² + Cτ + D, a(0) = 2B and
/// a(h) = 6Ah + 2B).
pub fn hermite_end_accelerations(x0: f64, v0: f64, x1: f64, v1: f64, h: f64) -> (f64, f64) {
    let d = 6.0 * (x1 - x0) / (h * h);
    (d - (4.0 * v0 + 2.0 * v1) / h, -d + (2.0 * v0 + 4.0 * v1) / h)
}

/// The largest |velocity| and |acceleration| of a cubic segment `h` seconds long that starts
/// at velocity `v0` with acceleration `a0` and ends with acceleration `a1`.
pub fn cubic_extremes(v0: f64, a0: f64, a1: f64, h: f64) -> (f64, f64) {
    let jerk = (a1 - a0) / h;
    let v = |tau: f64| v0 + a0 * tau + 0.5 * jerk * tau * tau;
    let mut v_max = v0.abs().max(v(h).abs());
    if jerk != 0.0 {
        let vertex = -a0 / jerk;
        if vertex > 0.0 && vertex < h {
            v_max = v_max.max(v(vertex).abs());
        }
    }
    (v_max, a0.abs().max(a1.abs()))
}

/// Checks one segment of `motor` (see [`cubic_extremes`]) against `rules`. A value that is not
/// finite breaks every limit.
pub fn check_segment(
    rules: &KnotRules,
    motor: usize,
    (v0, a0, a1, h): (f64, f64, f64, f64),
) -> Result<(), Excess> {
    let (v, a) = cubic_extremes(v0, a0, a1, h);
    let (v_lim, a_lim) = (rules.max_velocity[motor], rules.max_acceleration[motor]);
    if v.is_nan() || v > v_lim {
        return Err(Excess { motor, value: v, limit: v_lim, kind: ExcessKind::Velocity });
    }
    if a.is_nan() || a > a_lim {
        return Err(Excess { motor, value: a, limit: a_lim, kind: ExcessKind::Acceleration });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The extremes bound a dense sweep of the segment and are reached by it.
        #[test]
        fn extremes_bound_and_touch_the_segment(
            v0 in -5e4f64..5e4, a0 in -5e6f64..5e6, a1 in -5e6f64..5e6, h in 0.001f64..0.2,
        ) {
            let (v_max, a_max) = cubic_extremes(v0, a0, a1, h);
            let (mut v_seen, mut a_seen) = (0.0f64, 0.0f64);
            for i in 0..=10_000 {
                let tau = h * f64::from(i) / 10_000.0;
                let a = a0 + (a1 - a0) * tau / h;
                let v = v0 + a0 * tau + 0.5 * (a1 - a0) / h * tau * tau;
                v_seen = v_seen.max(v.abs());
                a_seen = a_seen.max(a.abs());
            }
            let scale = 1.0 + v0.abs() + (a0.abs() + a1.abs()) * h;
            prop_assert!(v_seen <= v_max + 1e-9 * scale && v_max - v_seen <= 1e-6 * scale);
            prop_assert!(a_seen <= a_max * (1.0 + 1e-12) && a_max - a_seen <= 1e-6 * a_max);
        }
    }

    /// Issue 32: what a message quotes — whole counts below 10⁷, exponent notation from
    /// there (`1e7`, not `10000000`), non-finite values as they are.
    #[test]
    fn values_are_quoted_whole_below_ten_million() {
        assert_eq!(rounded(9_999_999.4), "9999999");
        assert_eq!(rounded(-270_000.6), "-270001");
        assert_eq!(rounded(1e7), "1e7");
        assert_eq!(rounded(-1.23456e8), "-1.235e8");
        assert_eq!(rounded(1e308), "1e308");
        assert_eq!(rounded(f64::INFINITY), "inf");
    }

    #[test]
    fn limits_are_checked_and_nan_breaks_them() {
        let mut rules = KnotRules::new(1);
        rules.max_velocity[0] = 1000.0;
        rules.max_acceleration[0] = 1e5;
        assert!(check_segment(&rules, 0, (1000.0, 0.0, 0.0, 0.1)).is_ok());
        let e = check_segment(&rules, 0, (900.0, 3000.0, 0.0, 0.1)).unwrap_err();
        assert_eq!((e.kind, e.value), (ExcessKind::Velocity, 1050.0));
        let e = check_segment(&rules, 0, (0.0, 0.0, -2e5, 0.001)).unwrap_err();
        assert_eq!(e.kind, ExcessKind::Acceleration);
        assert!(check_segment(&rules, 0, (f64::NAN, 0.0, 0.0, 0.1)).is_err());
        assert_eq!(
            e.describe(),
            "motor 1: the path accelerates at 200000 counts/s² on its way to this knot, more \
             than motor 1's max_acceleration_counts_per_s2 = 100000"
        );
    }
}
