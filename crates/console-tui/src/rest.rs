//! Where the robot is while no move runs, whether each motor is homed, and the gripper — each
//! from the one source that knows it, named with it ([`Rest`]), and "not known" with the
//! reason where none does:
//!
//! - **The simulated robot** (`[hwserver] backend = "sim"`) is made anew for every move: it
//!   starts at `[sim] start_counts`, homed when `[sim] homed` says so or its state file
//!   (`[sim] state_file`) keeps a homed frame, the gripper open. That is where the next move
//!   finds it, whatever the last move did.
//! - **The fake card** (`--device fake`) starts every move at `[sim] start_counts`, homed, the
//!   gripper open.
//! - **The Sensoray 626** keeps counting while it is powered and keeps its outputs: the motors
//!   and the gripper are where the last move left them (the last row of its `gather.csv`, or,
//!   after a homing, what the hwserver read once the counters were preset), and a motor is
//!   homed when the card's state file (`<[s626] state_dir>/s626-<device>.state`) keeps its
//!   frame for this very card.
//!
//! The effector's place (the forward kinematics of `[robot]`) is given only where every motor
//! is homed: in another frame the counts say nothing about it.

use crate::results::{EndRow, MoveResult};
use qmarc_config::{BackendKind, Settings};
use qmarc_proto::{Gripper, MAX_MOTORS};
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use qmarc_hwserver::backends::s626::{FAKE_DEVICE, card_identity};
use qmarc_hwserver::backends::sim::SIM_IDENTITY;

/// The robot at rest, as far as it is known.
#[derive(Debug, Clone, PartialEq)]
pub struct Rest {
    /// Position per motor, counts, or why it is not known.
    pub counts: Result<Vec<f64>, String>,
    /// Where the effector is, mm, where the settings describe the Delta (`None`: they do
    /// not), or why it is not known.
    pub effector_mm: Option<Result<[f64; 3], String>>,
    /// Per motor, whether its frame is homed, or why it is not known.
    pub homed: Result<Vec<bool>, String>,
    /// The gripper ([`Gripper::ABSENT`]: none wired), or why its state is not known.
    pub gripper: Result<Gripper, String>,
    /// Where the positions and the gripper come from.
    pub whence: String,
    /// Where the homed flags come from.
    pub homed_whence: String,
}

impl Rest {
    /// Nothing known, for `why`.
    pub fn unknown(why: &str) -> Rest {
        Rest {
            counts: Err(why.to_string()),
            effector_mm: None,
            homed: Err(why.to_string()),
            gripper: Err(why.to_string()),
            whence: String::new(),
            homed_whence: String::new(),
        }
    }

    /// The robot at rest for the settings `s` as the starter is given them (`starter_args`
    /// may choose another `--backend` or `--device`), relative paths from `workdir`, after
    /// the last move's results `last` (the newest in the output folder).
    pub fn of(
        s: &Settings,
        starter_args: &[String],
        workdir: &Path,
        last: Option<&MoveResult>,
        now: SystemTime,
    ) -> Rest {
        let arg = |name: &str| {
            starter_args.iter().rev().find_map(|a| a.strip_prefix(name)).map(str::to_string)
        };
        let backend = arg("--backend=").and_then(|b| b.parse().ok()).unwrap_or(s.hwserver.backend);
        let device = arg("--device=").map_or_else(|| s.s626.device.clone(), PathBuf::from);
        let n = s.n_motors;
        let mut rest = match backend {
            BackendKind::Sim => sim(s, workdir),
            BackendKind::S626 if device.as_os_str() == FAKE_DEVICE => Rest {
                counts: Ok(start_counts(s, &vec![true; n.min(MAX_MOTORS)])),
                effector_mm: None,
                homed: Ok(vec![true; n]),
                gripper: Ok(open_gripper(s)),
                whence: "the fake card: every move starts at [sim] start_counts, homed, gripper \
                         open"
                    .to_string(),
                homed_whence: String::new(),
            },
            BackendKind::S626 => card(s, &device, workdir, last, now),
        };
        rest.effector_mm = s.robot().map(|robot| {
            let counts = rest.counts.as_ref().map_err(|_| "not known".to_string())?;
            match &rest.homed {
                Ok(h) if h.iter().all(|&h| h) => {}
                Ok(_) => return Err("not known: the frame is not homed".to_string()),
                Err(_) => return Err("not known".to_string()),
            }
            let [a, b, c] = [0, 1, 2].map(|m| counts.get(m).copied().unwrap_or(f64::NAN));
            robot.mm_of(&[a, b, c]).map_err(|e| format!("not known: {e}"))
        });
        rest
    }

    /// What is known, item by item, for the screen: the positions, the effector, the homed
    /// motors and the gripper (a `false` second: not known).
    pub fn items(&self) -> Vec<(String, bool)> {
        if let (Err(a), Err(b), Err(c)) = (&self.counts, &self.homed, &self.gripper)
            && a == b
            && b == c
        {
            // Nothing known, for one reason: said once.
            return vec![(a.clone(), false)];
        }
        let mut items = Vec::new();
        items.push(match &self.counts {
            Ok(c) => {
                let list: Vec<String> =
                    c.iter().enumerate().map(|(m, v)| format!("M{} {v:.0}", m + 1)).collect();
                (format!("{} counts", list.join("  ")), true)
            }
            Err(e) => (format!("positions {e}"), false),
        });
        match &self.effector_mm {
            Some(Ok([x, y, z])) => items.push((format!("effector {x:.1} {y:.1} {z:.1} mm"), true)),
            Some(Err(e)) => items.push((format!("effector {e}"), false)),
            None => {}
        }
        items.push(match &self.homed {
            Ok(h) => {
                let of = |want: bool| -> Vec<String> {
                    h.iter()
                        .enumerate()
                        .filter(|(_, x)| **x == want)
                        .map(|(m, _)| format!("M{}", m + 1))
                        .collect()
                };
                let (yes, no) = (of(true), of(false));
                let text = match (yes.is_empty(), no.is_empty()) {
                    (_, true) => format!("homed {}", yes.join(" ")),
                    (true, false) => format!("not homed {}", no.join(" ")),
                    (false, false) => {
                        format!("homed {}, not homed {}", yes.join(" "), no.join(" "))
                    }
                };
                (text, true)
            }
            Err(e) => (format!("homed {e}"), false),
        });
        items.push(match &self.gripper {
            Ok(g) if g.code() < 0 => ("no gripper wired".to_string(), true),
            Ok(g) => (format!("gripper {}", g.name()), true),
            Err(e) => (format!("gripper {e}"), false),
        });
        items
    }

    /// Where the figures come from, in words.
    pub fn source(&self) -> String {
        if self.whence.is_empty() {
            String::new()
        } else if self.homed_whence.is_empty() {
            format!("from {}", self.whence)
        } else {
            format!("from {}; homed: {}", self.whence, self.homed_whence)
        }
    }
}

/// The simulated robot of `s`: where every move starts.
fn sim(s: &Settings, workdir: &Path) -> Rest {
    let n = s.n_motors.min(MAX_MOTORS);
    let kept = if s.sim.plant.homed {
        Ok((vec![true; n], "[sim] homed = true".to_string()))
    } else {
        match &s.sim.state_file {
            Some(path) => {
                let path = workdir.join(path);
                kept_homed(&path, n, SIM_IDENTITY)
                    .map(|h| (h, format!("kept in {}", path.display())))
            }
            None => Ok((vec![false; n], "[sim] homed = false, no state_file".to_string())),
        }
    };
    let whence = "the simulator: every move starts at [sim] start_counts, gripper open".to_string();
    match kept {
        Ok((homed, homed_whence)) => Rest {
            counts: Ok(start_counts(s, &homed)),
            effector_mm: None,
            homed: Ok(homed),
            gripper: Ok(open_gripper(s)),
            whence,
            homed_whence,
        },
        // Its counters read in a frame that is not known.
        Err(e) => Rest {
            counts: Err("not known: the frame is not known".to_string()),
            effector_mm: None,
            homed: Err(format!("not known: {e}")),
            gripper: Ok(open_gripper(s)),
            whence,
            homed_whence: String::new(),
        },
    }
}

/// Where the simulated robot's counters read at the start of a move: `[sim] start_counts`,
/// `[sim] counter_offset` off where the frame is not homed (`homed`, per motor).
fn start_counts(s: &Settings, homed: &[bool]) -> Vec<f64> {
    homed
        .iter()
        .enumerate()
        .map(|(m, &homed)| {
            let start = s.sim.start_counts.get(m).copied().unwrap_or(0.0).floor();
            if homed { start } else { start + s.sim.plant.counter_offset as f64 }
        })
        .collect()
}

/// An open gripper, or none when none is wired.
fn open_gripper(s: &Settings) -> Gripper {
    Gripper(if s.s626.gripper_dio.is_some() { Gripper::OPEN } else { Gripper::ABSENT })
}

/// The Sensoray 626 on `device`: where the last move left it, homed as its state file keeps.
fn card(
    s: &Settings,
    device: &Path,
    workdir: &Path,
    last: Option<&MoveResult>,
    now: SystemTime,
) -> Rest {
    let n = s.n_motors;
    let name = device.file_name().map_or_else(|| "card".into(), |n| n.to_string_lossy());
    let state = workdir.join(&s.s626.state_dir).join(format!("s626-{name}.state"));
    let identity = card_identity(&device.display().to_string(), &s.s626);
    let homed = kept_homed(&state, n, &identity).map_err(|e| format!("not known: {e}"));
    let homed_whence = format!("kept in {} for this card", state.display());
    let Some(last) = last else {
        return Rest {
            homed,
            homed_whence,
            ..Rest::unknown("not known: no move's results in the output folder")
        };
    };
    let age = last.age(now).map(|a| format!(", {a}")).unwrap_or_default();
    let gather = last.dir.join("gather.csv");
    // After a homing, what the hwserver read once the counters were preset; else the last
    // gathered row.
    let preset = last.summary.homing.as_ref().and_then(|h| h.after.as_ref());
    let (counts, at) = match (preset, &last.end) {
        (Some(after), _) => {
            (Ok(after.positions_counts.clone()), "read after its preset".to_string())
        }
        (None, Ok(end)) if end.act.len() >= n => {
            (Ok(end.act[..n].to_vec()), format!("{}, cycle {}", gather.display(), end.cycle))
        }
        (None, Ok(_)) => (
            Err("not known: the last move did not gather `act`".to_string()),
            gather.display().to_string(),
        ),
        (None, Err(e)) => (Err(format!("not known: {e}")), gather.display().to_string()),
    };
    let gripper = match (&last.end, s.s626.gripper_dio) {
        (_, None) => Ok(Gripper(Gripper::ABSENT)),
        (Ok(EndRow { grip: Some(code), .. }), Some(_)) => Ok(Gripper(match code {
            0 => Gripper::OPEN,
            1 => Gripper::CLOSE,
            2 => Gripper::CLOSE | Gripper::CLOSED,
            3 => 0,
            _ => Gripper::ABSENT,
        })),
        (Ok(_), Some(_)) => Err("not known: the last move did not gather `grip`".to_string()),
        (Err(_), Some(_)) => Err("not known".to_string()),
    };
    Rest {
        counts,
        effector_mm: None,
        homed,
        gripper,
        whence: format!("where the last move ({}{age}) left them: {at}", last.summary.what()),
        homed_whence,
    }
}

/// Which of `n` motors the state file `path` keeps homed for `identity`, as the hwserver
/// reads it (`qmarc_hwserver::backends::state::read_homed`): none when the file is missing
/// (a fresh machine), says nothing, or was written for something else; an error only when
/// it cannot be read.
pub fn kept_homed(path: &Path, n: usize, identity: &str) -> Result<Vec<bool>, String> {
    let homed = qmarc_hwserver::backends::state::read_homed(path, n, identity)?;
    Ok(homed[..n.min(MAX_MOTORS)].to_vec())
}

#[cfg(test)]
mod tests;
