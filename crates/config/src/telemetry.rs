//! `[telemetry]`: live samples of the servo loop, published over iceoryx2 publish–subscribe
//! (`qmarc/telemetry`) for the console's live charts and `qmarc scope`.

use crate::ConfigLoadError;
use crate::source::{S, Source};
use serde::{Deserialize, Serialize};

/// Largest `telemetry.every`.
pub const MAX_TELEMETRY_EVERY: u32 = 100_000;

/// The live telemetry of a move.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TelemetrySettings {
    /// Publish at all.
    pub enabled: bool,
    /// A sample every N-th servo cycle.
    pub every: u32,
}

impl Default for TelemetrySettings {
    fn default() -> TelemetrySettings {
        TelemetrySettings { enabled: true, every: 4 }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTelemetry {
    enabled: S<bool>,
    every: S<i64>,
}

impl RawTelemetry {
    /// Checked.
    pub(crate) fn check(&self, src: &Source<'_>) -> Result<TelemetrySettings, ConfigLoadError> {
        let d = TelemetrySettings::default();
        Ok(TelemetrySettings {
            enabled: src.take(&self.enabled, "telemetry.enabled", d.enabled, |_| Ok(()))?,
            every: src.int(
                &self.every,
                "telemetry.every",
                d.every.into(),
                1,
                MAX_TELEMETRY_EVERY.into(),
            )? as u32,
        })
    }
}
