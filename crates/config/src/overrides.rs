//! A timing-overrides file (`--timing-overrides FILE`): the timing bounds a rehearsal on the
//! fake card (`--device fake`) needs on a machine without PREEMPT_RT, given explicitly in a
//! file of their own instead of widened in the card's settings. Only those bounds may be
//! in it: `[hwserver] watchdog_periods`, `response_timeout_periods` and
//! `[safety] max_missed_in_row`; anything else is refused naming its line.

use crate::source::{S, Source};
use crate::{ConfigLoadError, Settings};
use serde::Deserialize;
use std::path::{Path, PathBuf};

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawOverrides {
    #[serde(default)]
    hwserver: RawHwTiming,
    #[serde(default)]
    safety: RawSafetyTiming,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawHwTiming {
    watchdog_periods: S<i64>,
    response_timeout_periods: S<i64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawSafetyTiming {
    max_missed_in_row: S<i64>,
}

/// The timing bounds a file overrides (each `None` where it says nothing).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TimingOverrides {
    /// The file.
    pub file: PathBuf,
    /// `hwserver.watchdog_periods`.
    pub watchdog_periods: Option<u32>,
    /// `hwserver.response_timeout_periods`.
    pub response_timeout_periods: Option<u32>,
    /// `safety.max_missed_in_row`.
    pub max_missed_in_row: Option<u64>,
}

impl TimingOverrides {
    /// Reads and checks the file `path` (the bounds' own ranges; errors name file, line and
    /// field).
    pub fn load(path: &Path) -> Result<TimingOverrides, ConfigLoadError> {
        let text = crate::read_config(path)?;
        let src = Source { path, text: &text };
        let raw: RawOverrides = toml::from_str(&text).map_err(|e| src.toml_error(&e))?;
        let int = |v: &S<i64>, field: &str, lo: i64| -> Result<Option<i64>, ConfigLoadError> {
            v.as_ref().map(|_| src.int(v, field, 0, lo, 1_000_000)).transpose()
        };
        Ok(TimingOverrides {
            file: path.to_path_buf(),
            watchdog_periods: int(&raw.hwserver.watchdog_periods, "hwserver.watchdog_periods", 2)?
                .map(|v| v as u32),
            response_timeout_periods: int(
                &raw.hwserver.response_timeout_periods,
                "hwserver.response_timeout_periods",
                1,
            )?
            .map(|v| v as u32),
            max_missed_in_row: int(&raw.safety.max_missed_in_row, "safety.max_missed_in_row", 1)?
                .map(|v| v as u64),
        })
    }

    /// What it sets, as `hwserver.watchdog_periods = 250, …`.
    pub fn describe(&self) -> String {
        let mut said = Vec::new();
        if let Some(v) = self.watchdog_periods {
            said.push(format!("hwserver.watchdog_periods = {v}"));
        }
        if let Some(v) = self.response_timeout_periods {
            said.push(format!("hwserver.response_timeout_periods = {v}"));
        }
        if let Some(v) = self.max_missed_in_row {
            said.push(format!("safety.max_missed_in_row = {v}"));
        }
        said.join(", ")
    }
}

impl Settings {
    /// Applies the timing bounds of `o` over the file's: only on the simulated robot or the
    /// fake card (a rehearsal), never on a card that drives a robot.
    pub fn apply_timing_overrides(&mut self, o: &TimingOverrides) -> Result<(), ConfigLoadError> {
        let fake = self.s626.device == Path::new("fake");
        if self.hwserver.backend == crate::BackendKind::S626 && !fake {
            return Err(ConfigLoadError::Override {
                flag: "--timing-overrides",
                message: format!(
                    "{} relaxes the timing bounds, which is for a rehearsal on the fake card \
                     (--device fake) or the simulated robot, not for the card {} that drives \
                     the robot: its bounds are the settings file's",
                    o.file.display(),
                    self.s626.device.display()
                ),
            });
        }
        if let Some(v) = o.watchdog_periods {
            self.hwserver.watchdog_periods = v;
            self.explicit.watchdog_periods = true;
        }
        if let Some(v) = o.response_timeout_periods {
            if v < self.hwserver.deadline_periods {
                return Err(ConfigLoadError::Override {
                    flag: "--timing-overrides",
                    message: format!(
                        "{}: hwserver.response_timeout_periods = {v} is below \
                         hwserver.deadline_periods = {}",
                        o.file.display(),
                        self.hwserver.deadline_periods
                    ),
                });
            }
            self.hwserver.response_timeout_periods = v;
        }
        if let Some(v) = o.max_missed_in_row {
            self.max_missed_in_row = v;
            self.explicit.max_missed_in_row = true;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> Result<TimingOverrides, String> {
        let dir = std::env::temp_dir().join(format!("qmarc-overrides-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join(format!("o{}.toml", text.len()));
        std::fs::write(&f, text).unwrap();
        let r = TimingOverrides::load(&f).map_err(|e| e.to_string());
        let _ = std::fs::remove_file(&f);
        r
    }

    #[test]
    fn only_the_timing_bounds_are_taken_each_checked_where_it_is() {
        let o = load("[hwserver]\nwatchdog_periods = 250\n[safety]\nmax_missed_in_row = 300\n")
            .unwrap();
        assert_eq!(
            (o.watchdog_periods, o.response_timeout_periods, o.max_missed_in_row),
            (Some(250), None, Some(300))
        );
        assert_eq!(o.describe(), "hwserver.watchdog_periods = 250, safety.max_missed_in_row = 300");
        let e = load("[hwserver]\nwatchdog_periods = 250\nbackend = \"sim\"\n").unwrap_err();
        assert!(e.contains(":3:") && e.contains("backend"), "{e}");
        let e = load("[safety]\nmax_missed_in_row = 0\n").unwrap_err();
        assert!(e.contains(":2:") && e.contains("safety.max_missed_in_row"), "{e}");
        let e = load("[general]\nperiod_us = 100\n").unwrap_err();
        assert!(e.contains("general"), "{e}");
    }
}
