//! `[s626]`: the Sensoray 626 through the kernel's comedi driver (`--backend s626`) — its
//! device, how it is wired to the amplifiers and switches (thesis Table A-5), its polarities
//! and its counting (`docs/hardware.md`).

use crate::source::{S, Source, positive, span_of};
use crate::{BackendKind, ConfigLoadError};
use qmarc_proto::MAX_MOTORS;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// DIO channels of a bank of the 626 (bank 0 = comedi subdevice 2).
pub const S626_DIO_CHANNELS: u32 = 16;

/// The 626's wiring and counting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct S626Settings {
    /// The comedi device file (`--device`).
    pub device: PathBuf,
    /// Encoder counts per motor revolution as the driver counts them: 1× (one count per
    /// quadrature cycle), a quarter of the 4× the thesis counted.
    pub counts_per_rev: f64,
    /// Amplifier enable output per motor, DIO channel of bank 0.
    pub enable_dio: Vec<u32>,
    /// The bit that enables an amplifier: 1 drives the pin to 0 V, which the thesis' buffer
    /// board (A.4.2.1) turns into 24 V, "enabled".
    pub enable_bit: u32,
    /// Top limit switch input per motor, DIO channel of bank 0.
    pub limit_top_dio: Vec<u32>,
    /// Bottom limit switch input per motor, DIO channel of bank 0.
    pub limit_bottom_dio: Vec<u32>,
    /// What a closed (not tripped) switch reads: 1 for switches wired normally closed to
    /// ground (a tripped switch or a broken wire then reads 0).
    pub switch_closed_bit: u32,
    /// DIO channels never written (the counters' index inputs).
    pub reserved_dio: Vec<u32>,
    /// Output toggled once per servo cycle for an external charge-pump relay in series with
    /// the amplifier enables; `None`: no charge pump.
    pub charge_pump_dio: Option<u32>,
    /// The emergency-stop chain's input, wired normally closed like the limit switches (it
    /// reads as `switch_closed_bit` while closed; pressed or broken, every motor goes off at
    /// once and stays off until it closes again); `None`: none wired.
    #[serde(default)]
    pub estop_dio: Option<u32>,
    /// The gripper's output (thesis 6.2.2), a free DIO channel of bank 0: on (1, 0 V) closes
    /// it. The simulated robot's gripper is wired here too. `None`: no gripper.
    #[serde(default)]
    pub gripper_dio: Option<u32>,
    /// How long the gripper takes to close or to open, s: the simulated gripper's travel,
    /// and on the card (no sensor) the time after which it counts as closed or open.
    #[serde(default = "default_gripper_close_s")]
    pub gripper_close_s: f64,
    /// DAC channel per motor.
    pub dac_channels: Vec<u32>,
    /// Counter channel per motor (0‥2 are counters 0A‥2A).
    pub counter_channels: Vec<u32>,
    /// Per motor, −1 to reverse the DAC's sign (an amplifier wired the other way round).
    pub dac_sign: Vec<i32>,
    /// Per motor, −1 to reverse the counting direction.
    pub counter_sign: Vec<i32>,
    /// Where the homed frame is kept between runs (a tmpfs that a reboot clears, as a power
    /// cycle clears the card's counters).
    pub state_dir: PathBuf,
}

/// [`S626Settings::gripper_close_s`] when the file does not say: a small pneumatic gripper.
fn default_gripper_close_s() -> f64 {
    0.05
}

/// The longest [`S626Settings::gripper_close_s`] taken, s.
pub const MAX_GRIPPER_CLOSE_S: f64 = 10.0;

impl Default for S626Settings {
    fn default() -> S626Settings {
        S626Settings {
            device: PathBuf::from("/dev/comedi0"),
            counts_per_rev: 1024.0,
            enable_dio: vec![0, 1, 3],
            enable_bit: 1,
            limit_top_dio: vec![9, 11, 13],
            limit_bottom_dio: vec![10, 12, 15],
            switch_closed_bit: 1,
            reserved_dio: vec![2, 8, 14],
            charge_pump_dio: Some(4),
            estop_dio: None,
            gripper_dio: None,
            gripper_close_s: default_gripper_close_s(),
            dac_channels: vec![0, 1, 2],
            counter_channels: vec![0, 1, 2],
            dac_sign: vec![1, 1, 1],
            counter_sign: vec![1, 1, 1],
            state_dir: PathBuf::from("/run/qmarc"),
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawS626 {
    device: S<String>,
    counts_per_rev: S<f64>,
    enable_dio: S<Vec<i64>>,
    enable_bit: S<i64>,
    limit_top_dio: S<Vec<i64>>,
    limit_bottom_dio: S<Vec<i64>>,
    switch_closed_bit: S<i64>,
    reserved_dio: S<Vec<i64>>,
    charge_pump_dio: S<i64>,
    estop_dio: S<i64>,
    gripper_dio: S<i64>,
    gripper_close_s: S<f64>,
    dac_channels: S<Vec<i64>>,
    counter_channels: S<Vec<i64>>,
    dac_sign: S<Vec<i64>>,
    counter_sign: S<Vec<i64>>,
    state_dir: S<String>,
}

/// A per-motor list of integers within `lo‥=hi`, at most [`MAX_MOTORS`] long.
fn list(lo: i64, hi: i64) -> impl Fn(&Vec<i64>) -> Result<(), String> {
    move |v| {
        if v.len() > MAX_MOTORS {
            return Err(format!("at most {MAX_MOTORS} entries, found {}", v.len()));
        }
        match v.iter().find(|x| !(lo..=hi).contains(*x)) {
            Some(bad) => Err(format!("entries must be {lo}‥{hi}, found {bad}")),
            None => Ok(()),
        }
    }
}

/// The channels of `mask`, as `DIO6, DIO7` ("none" when empty).
fn channels(mask: u32) -> String {
    let names: Vec<String> =
        (0..32).filter(|c| mask & 1 << c != 0).map(|c| format!("DIO{c}")).collect();
    if names.is_empty() { "none".into() } else { names.join(", ") }
}

fn to_u32(v: Vec<i64>) -> Vec<u32> {
    v.into_iter().map(|x| x as u32).collect()
}

impl RawS626 {
    /// Where `key` is set (the file's start when it is not).
    fn span_of_key(&self, key: &str) -> std::ops::Range<usize> {
        match key {
            "enable_dio" => span_of(&self.enable_dio),
            "limit_top_dio" => span_of(&self.limit_top_dio),
            "limit_bottom_dio" => span_of(&self.limit_bottom_dio),
            "charge_pump_dio" => span_of(&self.charge_pump_dio),
            "estop_dio" => span_of(&self.estop_dio),
            "gripper_dio" => span_of(&self.gripper_dio),
            "dac_channels" => span_of(&self.dac_channels),
            "counter_channels" => span_of(&self.counter_channels),
            "dac_sign" => span_of(&self.dac_sign),
            "counter_sign" => span_of(&self.counter_sign),
            // Not a key the wiring's checks name: the file's start.
            _ => 0..0,
        }
    }

    /// Checked for `n_motors` motors when the 626 is the backend (`used`): each per-motor
    /// list must name a channel for every motor, and no DIO channel may serve twice or be a
    /// reserved one.
    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        n_motors: usize,
        used: bool,
    ) -> Result<S626Settings, ConfigLoadError> {
        let d = S626Settings::default();
        let dio = list(0, i64::from(S626_DIO_CHANNELS) - 1);
        let ints = |v: &S<Vec<i64>>,
                    key: &str,
                    default: &[u32],
                    ok: &dyn Fn(&Vec<i64>) -> Result<(), String>| {
            let default = default.iter().map(|&x| i64::from(x)).collect();
            src.take(v, &format!("s626.{key}"), default, ok).map(to_u32)
        };
        let sign = |v: &S<Vec<i64>>, key: &str, default: &[i32]| {
            let default = default.iter().map(|&x| i64::from(x)).collect();
            src.take(v, &format!("s626.{key}"), default, |v: &Vec<i64>| {
                list(-1, 1)(v)?;
                if v.contains(&0) { Err("entries must be 1 or -1, found 0".into()) } else { Ok(()) }
            })
            .map(|v| v.into_iter().map(|x| x as i32).collect::<Vec<i32>>())
        };
        let bit = |v: &S<i64>, key: &str, default: u32| {
            src.int(v, &format!("s626.{key}"), i64::from(default), 0, 1).map(|b| b as u32)
        };
        let optional_dio = |v: &S<i64>, key: &str, default: Option<u32>| {
            let c = src.int(
                v,
                &format!("s626.{key}"),
                default.map_or(-1, i64::from),
                -1,
                i64::from(S626_DIO_CHANNELS) - 1,
            )?;
            Ok::<_, ConfigLoadError>((c >= 0).then_some(c as u32))
        };
        let pump = optional_dio(&self.charge_pump_dio, "charge_pump_dio", d.charge_pump_dio)?;
        let estop = optional_dio(&self.estop_dio, "estop_dio", d.estop_dio)?;
        let gripper = optional_dio(&self.gripper_dio, "gripper_dio", d.gripper_dio)?;
        let gripper_close_s =
            src.take(&self.gripper_close_s, "s626.gripper_close_s", d.gripper_close_s, |v| {
                if v.is_finite() && *v > 0.0 && *v <= MAX_GRIPPER_CLOSE_S {
                    Ok(())
                } else {
                    Err(format!("must be above 0 and at most {MAX_GRIPPER_CLOSE_S} s, found {v}"))
                }
            })?;
        let s = S626Settings {
            device: src
                .take(&self.device, "s626.device", d.device.display().to_string(), |v| {
                    crate::source::not_empty(v)
                })?
                .into(),
            counts_per_rev: src.take(
                &self.counts_per_rev,
                "s626.counts_per_rev",
                d.counts_per_rev,
                positive,
            )?,
            enable_dio: ints(&self.enable_dio, "enable_dio", &d.enable_dio, &dio)?,
            enable_bit: bit(&self.enable_bit, "enable_bit", d.enable_bit)?,
            limit_top_dio: ints(&self.limit_top_dio, "limit_top_dio", &d.limit_top_dio, &dio)?,
            limit_bottom_dio: ints(
                &self.limit_bottom_dio,
                "limit_bottom_dio",
                &d.limit_bottom_dio,
                &dio,
            )?,
            switch_closed_bit: bit(
                &self.switch_closed_bit,
                "switch_closed_bit",
                d.switch_closed_bit,
            )?,
            reserved_dio: ints(&self.reserved_dio, "reserved_dio", &d.reserved_dio, &list(0, 15))?,
            charge_pump_dio: pump,
            estop_dio: estop,
            gripper_dio: gripper,
            gripper_close_s,
            dac_channels: ints(&self.dac_channels, "dac_channels", &d.dac_channels, &list(0, 3))?,
            counter_channels: ints(
                &self.counter_channels,
                "counter_channels",
                &d.counter_channels,
                &list(0, 5),
            )?,
            dac_sign: sign(&self.dac_sign, "dac_sign", &d.dac_sign)?,
            counter_sign: sign(&self.counter_sign, "counter_sign", &d.counter_sign)?,
            state_dir: src
                .take(&self.state_dir, "s626.state_dir", d.state_dir.display().to_string(), |v| {
                    crate::source::not_empty(v)
                })?
                .into(),
        };
        let explicit = |key: &str| self.span_of_key(key) != (0..0);
        if used && let Some((key, message)) = s.wiring_problem_in(n_motors, &explicit) {
            return Err(src.invalid(self.span_of_key(key), &format!("s626.{key}"), message));
        }
        // The simulated robot's gripper is wired as the card's: checked whatever the backend.
        if let Some(message) = s.gripper_problem(n_motors) {
            let key = "gripper_dio";
            return Err(src.invalid(self.span_of_key(key), &format!("s626.{key}"), message));
        }
        Ok(s)
    }
}

impl S626Settings {
    /// The DIO channels of bank 0 that message 13 may write for `n_motors` motors (bit c:
    /// channel c): every channel but the amplifier enables, the charge pump, the reserved
    /// channels and the inputs (the limit switches, the emergency stop).
    pub fn free_outputs(&self, n_motors: usize) -> u32 {
        let n = |v: &[u32]| v.len().min(n_motors);
        let taken = self.enable_dio[..n(&self.enable_dio)]
            .iter()
            .chain(&self.limit_top_dio[..n(&self.limit_top_dio)])
            .chain(&self.limit_bottom_dio[..n(&self.limit_bottom_dio)])
            .chain(&self.reserved_dio)
            .chain(&self.charge_pump_dio)
            .chain(&self.estop_dio)
            .filter(|&&c| c < S626_DIO_CHANNELS)
            .fold(0u32, |mask, &c| mask | 1 << c);
        !taken & ((1 << S626_DIO_CHANNELS) - 1)
    }

    /// Why `gripper_dio` cannot be the gripper's output for `n_motors` motors, if it cannot.
    pub fn gripper_problem(&self, n_motors: usize) -> Option<String> {
        let c = self.gripper_dio?;
        (self.free_outputs(n_motors) & 1 << c == 0).then(|| {
            format!(
                "DIO{c} is not a free output: it is an amplifier enable, the charge pump, a \
                 reserved channel or an input (free: {})",
                channels(self.free_outputs(n_motors))
            )
        })
    }

    /// What is wrong with the wiring for `n_motors` motors, if anything: `(key, message)`.
    /// Every motor needs its channels; no DIO channel may serve twice or be a reserved one;
    /// DACs and counters are one per motor.
    pub fn wiring_problem(&self, n_motors: usize) -> Option<(&'static str, String)> {
        self.wiring_problem_in(n_motors, &|_| true)
    }

    /// [`S626Settings::wiring_problem`], a clash of two keys named at the one `explicit`
    /// says the user set (the file's position of a default would help no one).
    pub(crate) fn wiring_problem_in(
        &self,
        n_motors: usize,
        explicit: &dyn Fn(&str) -> bool,
    ) -> Option<(&'static str, String)> {
        let per_motor = [
            ("enable_dio", self.enable_dio.len()),
            ("limit_top_dio", self.limit_top_dio.len()),
            ("limit_bottom_dio", self.limit_bottom_dio.len()),
            ("dac_channels", self.dac_channels.len()),
            ("counter_channels", self.counter_channels.len()),
            ("dac_sign", self.dac_sign.len()),
            ("counter_sign", self.counter_sign.len()),
        ];
        if let Some((key, len)) = per_motor.into_iter().find(|&(_, len)| len < n_motors) {
            return Some((key, format!("{n_motors} motors need {n_motors} entries, found {len}")));
        }
        let dio = self.enable_dio[..n_motors]
            .iter()
            .map(|&c| (c, "enable_dio"))
            .chain(self.charge_pump_dio.map(|c| (c, "charge_pump_dio")))
            .chain(self.estop_dio.map(|c| (c, "estop_dio")))
            .chain(self.gripper_dio.map(|c| (c, "gripper_dio")))
            .chain(self.limit_top_dio[..n_motors].iter().map(|&c| (c, "limit_top_dio")))
            .chain(self.limit_bottom_dio[..n_motors].iter().map(|&c| (c, "limit_bottom_dio")));
        let mut seen: Vec<(u32, &str)> = Vec::new();
        for (chan, key) in dio {
            if self.reserved_dio.contains(&chan) {
                return Some((
                    key,
                    format!(
                        "DIO{chan} is reserved (s626.reserved_dio: the counters' index inputs)"
                    ),
                ));
            }
            if let Some(&(_, other)) = seen.iter().find(|(c, _)| *c == chan) {
                return Some((key, format!("DIO{chan} is already s626.{other}")))
                    .filter(|_| explicit(key) || !explicit(other))
                    .or(Some((other, format!("DIO{chan} is already s626.{key}"))));
            }
            seen.push((chan, key));
        }
        for (key, v) in
            [("dac_channels", &self.dac_channels), ("counter_channels", &self.counter_channels)]
        {
            let used = &v[..n_motors];
            if (1..used.len()).any(|i| used[..i].contains(&used[i])) {
                return Some((
                    key,
                    format!("each motor needs a channel of its own, found {used:?}"),
                ));
            }
        }
        None
    }
}

/// The settings' checks and overrides that concern the 626.
impl crate::Settings {
    /// What the 626's wiring lacks for the motors in use, when it is the backend.
    pub(crate) fn check_s626_wiring(&self, flag: &'static str) -> Result<(), ConfigLoadError> {
        match self.s626.wiring_problem(self.n_motors) {
            Some((key, message)) if self.hwserver.backend == BackendKind::S626 => {
                Err(ConfigLoadError::Override {
                    flag,
                    message: format!("s626.{key} in {}: {message}", self.source.display()),
                })
            }
            _ => Ok(()),
        }
    }

    /// Why the settings' counts are not the 626's, if they are not: every count-valued
    /// setting (limits, offsets, distances, speeds, steps) and Kp means something else
    /// on a card that counts `[s626] counts_per_rev` — 4× too far, 4× too weak for the
    /// thesis' encoders. Nothing is rescaled silently: a file for the card says its counts.
    /// The 626 backend refuses to move with such settings (its selftest, which moves
    /// nothing, does not mind).
    pub fn s626_counts_problem(&self) -> Option<String> {
        (self.counts_per_rev != self.s626.counts_per_rev).then(|| {
            format!(
                "{}: general.counts_per_rev = {} counts per revolution, but the 626 counts {} \
                 ([s626] counts_per_rev): this file's limits, offsets, distances and gains are \
                 in other counts than the card's — use a settings file written for the 626 \
                 (config/s626.toml), or give general.counts_per_rev = {} and every count in \
                 the card's counts (docs/hardware.md)",
                self.source.display(),
                self.counts_per_rev,
                self.s626.counts_per_rev,
                self.s626.counts_per_rev
            )
        })
    }

    /// Overrides the 626's device (`--device`).
    pub fn set_device(&mut self, device: &Path) -> Result<(), ConfigLoadError> {
        if device.as_os_str().is_empty() {
            return Err(ConfigLoadError::Override {
                flag: "--device",
                message: "must not be empty".into(),
            });
        }
        self.s626.device = device.to_path_buf();
        Ok(())
    }
}
