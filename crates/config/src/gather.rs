//! `[gather]`: what is recorded every N-th cycle (thesis 3.4, 4.2), and where it goes.

use crate::ConfigLoadError;
use crate::source::{S, Source, not_empty, within};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Data gathering.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GatherSettings {
    /// Gather every N-th servo cycle.
    pub every: u32,
    /// Directory the data files go to.
    pub out_dir: PathBuf,
    /// Which fields go into the files (thesis 3.4: time, DAC, command, actual position).
    pub fields: GatherFields,
    /// How much of a stream (a path of unknown length: PVT from a pipe or a FIFO) the buffer
    /// holds, s; rows beyond are counted and reported, not kept.
    pub stream_max_s: f64,
    /// Also write `gather.mcap` (the same rows, the robot drawn, its log: Foxglove,
    /// PlotJuggler and `ros2 bag` open it).
    pub mcap: bool,
}

impl Default for GatherSettings {
    fn default() -> GatherSettings {
        GatherSettings {
            every: 1,
            out_dir: PathBuf::from("out"),
            fields: GatherFields::default(),
            stream_max_s: 60.0,
            mcap: true,
        }
    }
}

/// Which per-cycle fields the data files carry; `cycle` is always there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct GatherFields {
    /// `time_s`.
    pub time: bool,
    /// `cmdM`.
    pub cmd: bool,
    /// `actM`.
    pub act: bool,
    /// `dacM`.
    pub dac: bool,
    /// `grip`: the gripper's state (0 open, 1 closing, 2 closed, 3 opening), when one is
    /// wired (`s626.gripper_dio`).
    #[serde(default)]
    pub grip: bool,
    /// `conv`: the belt encoder's counts, when the run reads a belt (`conveyor`).
    #[serde(default)]
    pub conv: bool,
}

impl Default for GatherFields {
    fn default() -> GatherFields {
        GatherFields { time: true, cmd: true, act: true, dac: true, grip: true, conv: true }
    }
}

impl GatherFields {
    /// The names used in `gather.fields`.
    pub const NAMES: [&'static str; 6] = ["time", "cmd", "act", "dac", "grip", "conv"];

    /// Parses a list of names; the error names the first unknown one.
    pub fn from_names<'a>(
        names: impl IntoIterator<Item = &'a str>,
    ) -> Result<GatherFields, String> {
        let mut f = GatherFields {
            time: false,
            cmd: false,
            act: false,
            dac: false,
            grip: false,
            conv: false,
        };
        for n in names {
            match n {
                "time" => f.time = true,
                "cmd" => f.cmd = true,
                "act" => f.act = true,
                "dac" => f.dac = true,
                "grip" => f.grip = true,
                "conv" => f.conv = true,
                other => {
                    return Err(format!(
                        "unknown field `{other}`: the fields are time, cmd, act, dac, grip, conv"
                    ));
                }
            }
        }
        Ok(f)
    }

    /// The names of the selected fields.
    pub fn names(&self) -> Vec<&'static str> {
        let on = [self.time, self.cmd, self.act, self.dac, self.grip, self.conv];
        GatherFields::NAMES.iter().zip(on).filter(|(_, on)| *on).map(|(n, _)| *n).collect()
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawGather {
    every: S<i64>,
    out_dir: S<String>,
    fields: S<Vec<String>>,
    stream_max_s: S<f64>,
    mcap: S<bool>,
}

impl RawGather {
    pub(crate) fn check(&self, src: &Source<'_>) -> Result<GatherSettings, ConfigLoadError> {
        let d = GatherSettings::default();
        let out_dir = d.out_dir.display().to_string();
        let all = d.fields.names().into_iter().map(str::to_string).collect();
        let names = src.take(&self.fields, "gather.fields", all, |v| {
            GatherFields::from_names(v.iter().map(String::as_str)).map(|_| ())
        })?;
        Ok(GatherSettings {
            every: src.int(&self.every, "gather.every", d.every.into(), 1, 1_000_000)? as u32,
            out_dir: src.take(&self.out_dir, "gather.out_dir", out_dir, not_empty)?.into(),
            fields: GatherFields::from_names(names.iter().map(String::as_str)).unwrap_or_default(),
            stream_max_s: src.take(
                &self.stream_max_s,
                "gather.stream_max_s",
                d.stream_max_s,
                within(0.001, crate::DEFAULT_MAX_DURATION_S, "s"),
            )?,
            mcap: src.take(&self.mcap, "gather.mcap", d.mcap, |_| Ok(()))?,
        })
    }
}
