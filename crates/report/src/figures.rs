//! The error figures `summary.json` holds for each motor ([`MotorSummary`]), and how a figure
//! that is not a number is read back.

use qmarc_controller::stats::AxisErrors;
use serde::{Deserialize, Serialize};

/// A figure as `summary.json` holds it: a number, or null for one that is not (serde_json
/// writes NaN and ±∞ as null), read back as NaN — so a summary with such a figure can still be
/// read, and says the move is not ok ([`Summary::figures_not_numbers`](crate::Summary::figures_not_numbers)).
pub(crate) fn figure<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// Error figures of one motor in `summary.json`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotorSummary {
    /// Smallest error, counts.
    #[serde(deserialize_with = "figure")]
    pub min_error_counts: f64,
    /// Largest error, counts.
    #[serde(deserialize_with = "figure")]
    pub max_error_counts: f64,
    /// Σ |error|, counts.
    #[serde(deserialize_with = "figure")]
    pub accumulated_abs_error_counts: f64,
    /// Σ error², counts².
    #[serde(deserialize_with = "figure")]
    pub sum_squares_error_counts2: f64,
    /// Smallest error, rad at the arm.
    #[serde(deserialize_with = "figure")]
    pub min_error_rad: f64,
    /// Largest error, rad.
    #[serde(deserialize_with = "figure")]
    pub max_error_rad: f64,
    /// Σ |error|, rad.
    #[serde(deserialize_with = "figure")]
    pub accumulated_abs_error_rad: f64,
    /// Σ error², rad².
    #[serde(deserialize_with = "figure")]
    pub sum_squares_error_rad2: f64,
    /// False when the motor did not follow its command ([`Travel::not_followed`](qmarc_controller::stats::Travel::not_followed)): a seized
    /// joint, a dead amplifier. Such a motor is never reported ok.
    #[serde(default = "yes")]
    pub followed: bool,
}

fn yes() -> bool {
    true
}

impl MotorSummary {
    /// The figures of `e`, with `counts_per_rad` to convert (rad = counts / counts_per_rad).
    pub fn new(e: &AxisErrors, counts_per_rad: f64) -> MotorSummary {
        MotorSummary {
            min_error_counts: e.min,
            max_error_counts: e.max,
            accumulated_abs_error_counts: e.sum_abs,
            sum_squares_error_counts2: e.sum_sq,
            min_error_rad: e.min / counts_per_rad,
            max_error_rad: e.max / counts_per_rad,
            accumulated_abs_error_rad: e.sum_abs / counts_per_rad,
            sum_squares_error_rad2: e.sum_sq / (counts_per_rad * counts_per_rad),
            followed: true,
        }
    }
}
