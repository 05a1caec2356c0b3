//! `[[motor]]`: the gains (thesis eq. 3-1, Table 5-1), the notch (eq. 3-2) and the limits and
//! homing offsets of each motor.

use crate::ConfigLoadError;
use crate::source::{S, Source, finite, positive, within};
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
}

impl Default for MotorSafety {
    fn default() -> MotorSafety {
        MotorSafety {
            soft_limits: [-9_000.0, 10_000.0],
            max_following_error_counts: 2_000.0,
            max_integrated_error_counts: 200_000.0,
            home_offset_counts: 9_500.0,
            top_direction: -1.0,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawMotor {
    kp: S<f64>,
    ki: S<f64>,
    kd: S<f64>,
    kvff: S<f64>,
    kaff: S<f64>,
    notch: S<Vec<f64>>,
    soft_limits: S<Vec<f64>>,
    max_following_error_counts: S<f64>,
    max_integrated_error_counts: S<f64>,
    home_offset_counts: S<f64>,
    top_direction: S<i64>,
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

/// Checks the `[[motor]]` table `m` (its 1-based number `i`): every gain must be there.
pub(crate) fn check_motor(
    src: &Source<'_>,
    m: &Spanned<RawMotor>,
    i: usize,
) -> Result<(MotorGains, MotorSafety), ConfigLoadError> {
    let name = |k: &str| format!("motor[{i}].{k}");
    let need = |v: &S<f64>, k: &str| -> Result<f64, ConfigLoadError> {
        match v {
            None => Err(src.invalid(m.span(), &name(k), format!("missing key `{k}`"))),
            Some(_) => src.take(v, &name(k), 0.0, finite),
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
        notch: [notch[0], notch[1], notch[2], notch[3]],
    };
    let d = MotorSafety::default();
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
    };
    Ok((gains, safety))
}
