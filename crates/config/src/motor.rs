//! `[[motor]]`: the gains (thesis eq. 3-1, Table 5-1), the notch (eq. 3-2) and the limits and
//! homing offsets of each motor.
//!
//! Gains are checked against what eq. 3-1 makes of them (see [`gains_problem`]): finite, not
//! negative, and none so large that the encoder's resolution alone asks more than the DAC's
//! full scale. The motion limits (PMAC Ixx16/Ixx17, LinuxCNC MAX_VELOCITY/MAX_ACCELERATION)
//! bound what any generator may ask of the motor.

use crate::ConfigLoadError;
use crate::source::{S, Source, num, positive, within};
use serde::{Deserialize, Serialize};
use toml::Spanned;

/// Gains of one motor for the PID feed-forward law (thesis eq. 3-1, PMAC Ix30–Ix35) and its
/// notch (eq. 3-2, PMAC Ix36–Ix39).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct MotorGains {
    /// Proportional gain Kp.
    pub kp: f64,
    /// Integral gain Ki.
    pub ki: f64,
    /// Derivative gain Kd (on the actual velocity).
    pub kd: f64,
    /// Velocity feed-forward gain Kvff.
    pub kvff: f64,
    /// Acceleration feed-forward gain Kaff.
    pub kaff: f64,
    /// Jerk feed-forward gain Kjff: not in eq. 3-1 (0, the default, is eq. 3-1). A velocity-
    /// mode amplifier whose velocity loop is second order lags the command by its jerk too
    /// (docs/tuning.md, "Jerk feed-forward"); online moves at the motors' limits need it.
    #[serde(default)]
    pub kjff: f64,
    /// Notch coefficients `[n1, n2, d1, d2]`; all zero = no notch.
    pub notch: [f64; 4],
}

/// Limits and homing of one motor (thesis 3.10; PMAC Ixx11 for the instantaneous limit).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotorSafety {
    /// Software position limits `[min, max]`, counts in the homed frame (active once homed).
    pub soft_limits: [f64; 2],
    /// Largest |command − actual|, counts, before the move is stopped.
    pub max_following_error_counts: f64,
    /// Largest |Σ (command − actual)| over the move (eq. 3-1's IE), counts.
    pub max_integrated_error_counts: f64,
    /// Homing: where home is, counts from the top switch (away from it).
    pub home_offset_counts: f64,
    /// Homing: the direction of the top switch, −1 or +1 counts.
    pub top_direction: f64,
    /// The fastest any command may move the motor, counts/s (PMAC Ixx16, LinuxCNC
    /// MAX_VELOCITY): paths are refused before the move, knots of a stream as they arrive.
    pub max_velocity_counts_per_s: f64,
    /// The largest acceleration any command may ask, counts/s² (PMAC Ixx17, LinuxCNC
    /// MAX_ACCELERATION), from rest at the start of a path to rest at its end.
    pub max_acceleration_counts_per_s2: f64,
    /// The largest jerk of a jerk-limited move (the approach to a path, jog), counts/s³.
    pub max_jerk_counts_per_s3: f64,
}

impl Default for MotorSafety {
    /// The thesis' robot at 4× counting: its two paths (5.2.1, 5.2.2) ask up to 64 000
    /// counts/s, 3.4·10⁶ counts/s² and 1.2·10⁹ counts/s³ of a motor; the limits are those with
    /// margin.
    fn default() -> MotorSafety {
        MotorSafety {
            soft_limits: [-9_000.0, 10_000.0],
            max_following_error_counts: 2_000.0,
            max_integrated_error_counts: 200_000.0,
            home_offset_counts: 9_500.0,
            top_direction: -1.0,
            max_velocity_counts_per_s: 80_000.0,
            max_acceleration_counts_per_s2: 5.0e6,
            max_jerk_counts_per_s3: 2.0e9,
        }
    }
}

/// The DAC's full scale, codes (±8191 = ±10 V).
const FULL_SCALE: f64 = qmarc_proto::DAC_MAX as f64;

/// 2⁻²¹: eq. 3-1's output scale 2⁻¹⁹ and the ÷ 4 of the 14-bit DAC.
const OUTPUT_SCALE: f64 = 1.0 / 2_097_152.0;

/// `x` rounded for a message: whole below 10⁷, three decimals in exponent notation beyond.
fn short(x: f64) -> String {
    if x.abs() >= 1e7 { format!("{x:.3e}") } else { format!("{}", x.round()) }
}

/// What is wrong with the gains `g` of a law whose error terms are scaled by `fe_scale`, if
/// anything: the gain's key and why.
///
/// Every gain must be finite and ≥ 0 (a negative one drives the motor away from its
/// command). And since eq. 3-1 is DAC = 2⁻²¹·Kp·(s·FE + (Kvff·CV + Kaff·CA)/128 +
/// s·Ki·IE/2²³ − Kd·AV/128), each term's unit input — one count of following error, one
/// count·period of integrated error, one count per period of velocity, one count per period²
/// of acceleration: the smallest step of the counts the law works in (what the encoder
/// resolves, and the steps of a path in whole counts) — must ask less than the DAC's full
/// scale (8191 codes) of the output. A gain that breaks this turns single counts into
/// full-scale jumps: a bang-bang output, not a servo. (The thesis' gains ask 8 codes per count
/// of following error, 2 for Kd and 81 for Kvff.) A sanity bound, not a tuning rule.
pub fn gains_problem(g: &MotorGains, fe_scale: f64) -> Option<(&'static str, String)> {
    let all = [
        ("kp", g.kp),
        ("ki", g.ki),
        ("kd", g.kd),
        ("kvff", g.kvff),
        ("kaff", g.kaff),
        ("kjff", g.kjff),
    ];
    for (key, v) in all {
        if !v.is_finite() {
            return Some((key, format!("must be a finite number, found {}", num(v))));
        }
        if v < 0.0 {
            return Some((
                key,
                format!(
                    "must be ≥ 0, found {}: a negative gain drives the motor away from its \
                     command",
                    num(v)
                ),
            ));
        }
    }
    let terms = [
        ("kp", g.kp, fe_scale, "one count of following error", "2⁻²¹·Kp·fe_scale"),
        (
            "ki",
            g.ki,
            g.kp * fe_scale / 8_388_608.0,
            "one count·period of integrated error",
            "2⁻²¹·Kp·fe_scale·Ki/2²³",
        ),
        ("kd", g.kd, g.kp / 128.0, "one count per period of actual velocity", "2⁻²¹·Kp·Kd/128"),
        (
            "kvff",
            g.kvff,
            g.kp / 128.0,
            "one count per period of commanded velocity",
            "2⁻²¹·Kp·Kvff/128",
        ),
        (
            "kaff",
            g.kaff,
            g.kp / 128.0,
            "one count per period² of commanded acceleration",
            "2⁻²¹·Kp·Kaff/128",
        ),
        (
            "kjff",
            g.kjff,
            g.kp / 128.0,
            "one count per period³ of commanded jerk",
            "2⁻²¹·Kp·Kjff/128",
        ),
    ];
    for (key, v, per_unit, input, formula) in terms {
        let codes = OUTPUT_SCALE * v * per_unit;
        if codes > FULL_SCALE {
            let most = FULL_SCALE / (OUTPUT_SCALE * per_unit);
            return Some((
                key,
                format!(
                    "{} makes {input} alone ask {} DAC codes ({formula}, eq. 3-1), more than \
                     the full scale {FULL_SCALE}: the encoder's resolution would jump the \
                     output from end to end; at most {} here",
                    num(v),
                    short(codes),
                    short(most)
                ),
            ));
        }
    }
    None
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMotor {
    kp: S<f64>,
    ki: S<f64>,
    kd: S<f64>,
    kvff: S<f64>,
    kaff: S<f64>,
    kjff: S<f64>,
    notch: S<Vec<f64>>,
    soft_limits: S<Vec<f64>>,
    max_following_error_counts: S<f64>,
    max_integrated_error_counts: S<f64>,
    home_offset_counts: S<f64>,
    top_direction: S<i64>,
    max_velocity_counts_per_s: S<f64>,
    max_acceleration_counts_per_s2: S<f64>,
    max_jerk_counts_per_s3: S<f64>,
}

impl RawMotor {
    /// Where the gain `key` is in the file (the table's start if it is not there).
    fn gain_span(&self, key: &str, table: std::ops::Range<usize>) -> std::ops::Range<usize> {
        let v = match key {
            "kp" => &self.kp,
            "ki" => &self.ki,
            "kd" => &self.kd,
            "kvff" => &self.kvff,
            "kaff" => &self.kaff,
            _ => &self.kjff,
        };
        v.as_ref().map_or(table, Spanned::span)
    }
}

/// What the checks of one `[[motor]]` table need from the rest of the file.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MotorContext {
    /// `general.fe_scale`.
    pub fe_scale: f64,
    /// `general.gains_period_us` and `general.period_us`: the gains are checked as the law
    /// runs them, rescaled to the period.
    pub periods_us: (u32, u32),
    /// `hwserver.max_counts_per_s`: a faster encoder is a fault, so no motion may ask it.
    pub encoder_max_counts_per_s: f64,
}

/// The notch denominator 1 + d1·z⁻¹ + d2·z⁻² is stable iff |d2| < 1 and |d1| < 1 + d2.
fn check_notch(n: &[f64]) -> Result<(), String> {
    if n.len() != 4 {
        return Err(format!("must be 4 numbers [n1, n2, d1, d2], found {}", n.len()));
    }
    if let Some(bad) = n.iter().find(|x| !x.is_finite()) {
        return Err(format!("must be finite numbers, found {bad}"));
    }
    let (d1, d2) = (n[2], n[3]);
    if !(d2.abs() < 1.0 && d1.abs() < 1.0 + d2) {
        return Err(format!(
            "the denominator 1 + d1·z⁻¹ + d2·z⁻² with d1 = {d1}, d2 = {d2} is unstable \
             (needs |d2| < 1 and |d1| < 1 + d2)"
        ));
    }
    Ok(())
}

/// The gains `g`, tuned at `gains_period_us`, as the law runs them at `period_us` (Kd, Kvff
/// × T₀/T, Kaff × (T₀/T)², Kjff × (T₀/T)³, Ki × T/T₀; Kp and the notch as they are): see
/// `Settings::effective_gains`.
pub(crate) fn rescaled(g: MotorGains, (gains_period_us, period_us): (u32, u32)) -> MotorGains {
    let r = f64::from(gains_period_us) / f64::from(period_us);
    MotorGains {
        ki: g.ki / r,
        kd: g.kd * r,
        kvff: g.kvff * r,
        kaff: g.kaff * r * r,
        kjff: g.kjff * r * r * r,
        ..g
    }
}

/// [`gains_problem`] of the gains `g`, tuned at `periods_us.0`, as the law runs them at
/// `periods_us.1`: with a note of the rescaling when the two differ.
pub fn effective_gains_problem(
    g: &MotorGains,
    fe_scale: f64,
    periods_us: (u32, u32),
) -> Option<(&'static str, String)> {
    let (key, why) = gains_problem(&rescaled(*g, periods_us), fe_scale)?;
    let (tuned, period) = periods_us;
    Some(match tuned == period {
        true => (key, why),
        false => {
            (key, format!("rescaled from gains_period_us = {tuned} to period_us = {period}, {why}"))
        }
    })
}

/// Checks the `[[motor]]` table `m` (its 1-based number `i`): every gain of eq. 3-1 must be
/// there (`kjff`, not of eq. 3-1, is 0 when left out).
pub(crate) fn check_motor(
    src: &Source<'_>,
    m: &Spanned<RawMotor>,
    i: usize,
    cx: MotorContext,
) -> Result<(MotorGains, MotorSafety), ConfigLoadError> {
    let name = |k: &str| format!("motor[{i}].{k}");
    let need = |v: &S<f64>, k: &str| -> Result<f64, ConfigLoadError> {
        match v {
            None => Err(src.invalid(m.span(), &name(k), format!("missing key `{k}`"))),
            Some(_) => src.take(v, &name(k), 0.0, |_| Ok(())),
        }
    };
    let r = m.get_ref();
    let notch = src.take(&r.notch, &name("notch"), vec![0.0; 4], |v| check_notch(v))?;
    let gains = MotorGains {
        kp: need(&r.kp, "kp")?,
        ki: need(&r.ki, "ki")?,
        kd: need(&r.kd, "kd")?,
        kvff: need(&r.kvff, "kvff")?,
        kaff: need(&r.kaff, "kaff")?,
        kjff: src.take(&r.kjff, &name("kjff"), 0.0, |_| Ok(()))?,
        notch: [notch[0], notch[1], notch[2], notch[3]],
    };
    if let Some((key, why)) = effective_gains_problem(&gains, cx.fe_scale, cx.periods_us) {
        return Err(src.invalid(r.gain_span(key, m.span()), &name(key), why));
    }
    let d = MotorSafety::default();
    let limit = |v: &S<f64>, k: &str, default: f64| src.take(v, &name(k), default, positive);
    let max_velocity = limit(
        &r.max_velocity_counts_per_s,
        "max_velocity_counts_per_s",
        d.max_velocity_counts_per_s,
    )?;
    if max_velocity >= cx.encoder_max_counts_per_s {
        let span = r.max_velocity_counts_per_s.as_ref().map_or(m.span(), Spanned::span);
        return Err(src.invalid(
            span,
            &name("max_velocity_counts_per_s"),
            format!(
                "{} counts/s is not below hwserver.max_counts_per_s = {}, the speed at which \
                 the hwserver takes an encoder for broken: a motion that fast would fault",
                num(max_velocity),
                num(cx.encoder_max_counts_per_s)
            ),
        ));
    }
    let soft =
        src.take(&r.soft_limits, &name("soft_limits"), d.soft_limits.to_vec(), |v| {
            match v.as_slice() {
                [lo, hi] if lo.is_finite() && hi.is_finite() && lo < hi => Ok(()),
                _ => Err(format!("must be [min, max] with min < max, found {v:?}")),
            }
        })?;
    let safety = MotorSafety {
        soft_limits: [soft[0], soft[1]],
        max_following_error_counts: src.take(
            &r.max_following_error_counts,
            &name("max_following_error_counts"),
            d.max_following_error_counts,
            positive,
        )?,
        max_integrated_error_counts: src.take(
            &r.max_integrated_error_counts,
            &name("max_integrated_error_counts"),
            d.max_integrated_error_counts,
            positive,
        )?,
        home_offset_counts: src.take(
            &r.home_offset_counts,
            &name("home_offset_counts"),
            d.home_offset_counts,
            within(0.0, crate::homing::MAX_HOMING_COUNTS, "counts"),
        )?,
        top_direction: src.take(&r.top_direction, &name("top_direction"), -1, |v| {
            if *v == 1 || *v == -1 { Ok(()) } else { Err(format!("must be -1 or 1, found {v}")) }
        })? as f64,
        max_velocity_counts_per_s: max_velocity,
        max_acceleration_counts_per_s2: limit(
            &r.max_acceleration_counts_per_s2,
            "max_acceleration_counts_per_s2",
            d.max_acceleration_counts_per_s2,
        )?,
        max_jerk_counts_per_s3: limit(
            &r.max_jerk_counts_per_s3,
            "max_jerk_counts_per_s3",
            d.max_jerk_counts_per_s3,
        )?,
    };
    Ok((gains, safety))
}
