//! [`Backend`]: the hardware behind the server. Swapping hardware means writing one of these.

use qmarc_proto::{MAX_MOTORS, Status};

/// What one input read latches: every counter and every limit switch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Inputs {
    /// Raw 24-bit quadrature counter per motor ([`qmarc_proto::COUNTER_MASK`] wide, wraps).
    pub counters: [u32; MAX_MOTORS],
    /// Limit switches that are active now, as [`Status::limit_top`]/[`Status::limit_bottom`]
    /// bits (not latched: the server latches).
    pub limits: Status,
    /// The emergency-stop chain reads open now (pressed, or a broken wire); false for a
    /// backend without one.
    pub estop_open: bool,
    /// The free outputs ([`Backend::free_outputs`]) that are on now, as the pins read (bit c:
    /// DIO channel c); 0 for a backend without outputs.
    pub outputs: u32,
    /// The belt encoder's raw 24-bit counter (`conveyor.counter_channel`; wraps like the
    /// motors'); [`qmarc_proto::COUNTER_ZERO`] for a backend without one.
    pub belt: u32,
}

impl Default for Inputs {
    /// Nothing read: counters at 0, no switch, the chain closed, no output, the belt's
    /// counter at [`qmarc_proto::COUNTER_ZERO`] (a backend without a belt reads 0 counts).
    fn default() -> Inputs {
        Inputs {
            counters: [0; MAX_MOTORS],
            limits: Status::OK,
            estop_open: false,
            outputs: 0,
            belt: qmarc_proto::COUNTER_ZERO,
        }
    }
}

/// The hardware operations a [`Backend`] does per exchange, as a [`HwFault`] names them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HwOp {
    /// [`Backend::read_inputs`].
    ReadInputs,
    /// [`Backend::write_dacs`].
    WriteDacs,
    /// [`Backend::set_amp_enable`].
    Enable,
    /// [`Backend::load_counter`].
    LoadCounter,
    /// [`Backend::write_outputs`].
    WriteOutputs,
}

impl std::fmt::Display for HwOp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            HwOp::ReadInputs => "read inputs",
            HwOp::WriteDacs => "write DACs",
            HwOp::Enable => "enable",
            HwOp::LoadCounter => "load counter",
            HwOp::WriteOutputs => "write outputs",
        })
    }
}

/// A hardware operation failed (a short ioctl, a device error). Carries plain data only.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("hardware operation `{op}` failed with code {code}")]
pub struct HwFault {
    /// Which operation.
    pub op: HwOp,
    /// Backend-specific code (an errno for ioctl backends).
    pub code: i32,
}

/// A homed frame could not be kept where the backend keeps it (its state file): the homing
/// then fails, for the next run would find the motor unhomed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "cannot keep the homed frame in {} ({key}): {reason}: the next run would find motor \
     {motor} unhomed",
    path.display()
)]
pub struct FrameNotKept {
    /// The motor, 1-based.
    pub motor: usize,
    /// The state file.
    pub path: std::path::PathBuf,
    /// The setting that names it (`sim.state_file`, `s626.state_dir`).
    pub key: &'static str,
    /// Why, in words.
    pub reason: String,
}

/// What the hardware outputs now, as far as the backend can read it back: the conformance
/// suite checks that every way out of a move leaves it at 0 V with the amplifiers off.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Outputs {
    /// The DAC code of every motor.
    pub dac: [i32; MAX_MOTORS],
    /// Whether each amplifier is enabled.
    pub enabled: [bool; MAX_MOTORS],
}

/// A backend could not be opened (a device that is not there, settings it cannot use).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BackendOpenError {
    /// The hardware cannot be used, or the settings do not describe hardware this backend
    /// can drive: the message names what and says what to do.
    #[error("{0}")]
    Invalid(String),
    /// The device could not be opened.
    #[error("{device}: {reason}")]
    Device {
        /// The device, e.g. `/dev/comedi0`.
        device: String,
        /// Why.
        reason: String,
    },
    /// No backend has this name.
    #[error("no backend `{name}`; available: {available}")]
    Unknown {
        /// The name asked for.
        name: String,
        /// The registered names.
        available: String,
    },
}

/// The hardware: counters, DACs, amplifier enables, limit switches, an external watchdog.
///
/// Real-time contract: construction may allocate and fail and takes validated parameters;
/// every method called per exchange ([`Backend::read_inputs`], [`Backend::write_dacs`]) takes
/// `&mut self`, writes into the caller's buffer and never allocates, locks, does I/O other
/// than the hardware access itself, or panics. The server clamps DAC codes to
/// ±[`qmarc_proto::DAC_MAX`] before they arrive here.
pub trait Backend: Send {
    /// Short name for messages (`sim`, `s626`).
    fn name(&self) -> &'static str;

    /// Number of motors driven (≤ [`MAX_MOTORS`]).
    fn n_motors(&self) -> usize;

    /// Latches every counter and limit switch into `inputs`.
    fn read_inputs(&mut self, inputs: &mut Inputs) -> Result<(), HwFault>;

    /// Writes the DAC code of every driven motor (`codes[n_motors..]` are ignored).
    fn write_dacs(&mut self, codes: &[i32; MAX_MOTORS]) -> Result<(), HwFault>;

    /// Switches the amplifier of `motor` on or off.
    fn set_amp_enable(&mut self, motor: usize, on: bool) -> Result<(), HwFault>;

    /// Loads the hardware counter of `motor` with `raw`.
    fn load_counter(&mut self, motor: usize, raw: u32) -> Result<(), HwFault>;

    /// The digital outputs message 13 may write (bit c: DIO channel c of the first bank):
    /// every output the backend does not keep for itself (amplifier enables, a charge pump,
    /// reserved channels, inputs). Default: none.
    fn free_outputs(&self) -> u32 {
        0
    }

    /// Sets the outputs of `mask` (always within [`Backend::free_outputs`], the server checks)
    /// to the bits of `values`, leaving every other output as it is. Same real-time contract
    /// as [`Backend::write_dacs`]. Default: a backend without outputs fails.
    fn write_outputs(&mut self, mask: u32, values: u32) -> Result<(), HwFault> {
        let _ = (mask, values);
        Err(HwFault { op: HwOp::WriteOutputs, code: nix::errno::Errno::ENOTSUP as i32 })
    }

    /// All DACs to 0 V and all amplifiers off, as far as the hardware still obeys. Never fails:
    /// it is what every fault path calls.
    fn safe_state(&mut self);

    /// The backend's clock in ns: the response timestamp. Hardware uses `CLOCK_MONOTONIC`;
    /// the simulator its own (simulated in lock-step mode).
    fn now_ns(&self) -> u64;

    /// The run's world (the simulated belt and the parts on it) started at `epoch_ns` of
    /// `CLOCK_MONOTONIC` ([`qmarc_config::RunSpec::epoch_ns`]): a simulated belt runs from
    /// then, so that it is the belt the simulated camera sees. Default: nothing (a real belt
    /// moves on its own).
    fn set_epoch(&mut self, epoch_ns: u64) {
        let _ = epoch_ns;
    }

    /// Called on every exchange: toggle the output of an external charge pump or safety relay
    /// that drops amplifier enable when the toggling stops. Default: no such output.
    fn kick_charge_pump(&mut self) {}

    /// Stop toggling the charge pump for good (its relay drops). Default: no such output.
    fn stop_charge_pump(&mut self) {}

    /// Whether `motor`'s counter frame is homed when the server starts. A card whose counters
    /// keep counting while it is powered keeps the frame a homing set (the 626); the
    /// simulator says what its settings say. Default: not homed.
    fn homed(&self, motor: usize) -> bool {
        let _ = motor;
        false
    }

    /// Homing has just set `motor`'s counter frame (persist it where the hardware does; this
    /// hook runs after homing, outside the servo loop, and may do I/O). An error says where
    /// and why it could not be kept: the homing then fails.
    fn set_homed(&mut self, motor: usize) -> Result<(), FrameNotKept> {
        let _ = motor;
        Ok(())
    }

    /// Writes what the backend recorded (the simulator's event log).
    fn write_log(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        let _ = w;
        Ok(())
    }

    /// What the outputs are now, if the backend can read them back. Default: it cannot.
    fn outputs(&self) -> Option<Outputs> {
        None
    }

    /// Called once when the server ends, the hardware already safe: flush what the backend
    /// keeps (a log, a state file). Default: nothing.
    fn finish(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}
