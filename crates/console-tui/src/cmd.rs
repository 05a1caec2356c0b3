//! `qmarc cmd move|path|stop|grip|wait|status|quit`: one command to a serving controller
//! (`qmarc-starter serve`) over `qmarc/command`, its answer printed. The session is the one of
//! `--iox-prefix`, or your newest serving run found in /dev/shm.
//!
//! Exit codes: 0 accepted (or, for `wait`, the move ended at rest), 3 refused (the reason is
//! printed), 1 no serving controller or no answer, 64 bad options.

use clap::{Parser, Subcommand};
use qmarc_proto::service::IpcLocation;
use qmarc_proto::state::{FaultKind, Phase};
use qmarc_session::client::{CommandClient, Fate, OrderLedger};
use qmarc_session::discovery::{LiveRun, SessionFindError, serving, serving_session};
use qmarc_session::wire::{
    CommandKind, CommandRequest, CommandResponse, MAX_PATH_KNOTS, PathKnot, PathRequest,
};
use std::ffi::OsString;
use std::process::ExitCode;
use std::time::Duration;

/// Command line of `qmarc cmd`.
#[derive(Debug, Parser)]
#[command(name = "qmarc cmd", about = "Command a serving controller (qmarc-starter serve)")]
struct CmdArgs {
    /// The session's iceoryx2 prefix (default: your newest serving run in /dev/shm).
    #[arg(long, global = true)]
    iox_prefix: Option<String>,
    /// The session's iceoryx2 root (default: the one its run file names).
    #[arg(long, global = true)]
    iox_root: Option<String>,
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Move to a target from wherever the robot is, moving or not: the new target takes over
    /// in the next servo cycle, without a jump.
    Move {
        /// Joint counts, one per motor: `--to 1000,-500,250`.
        #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_name = "C1,C2,C3")]
        to: Option<Vec<f64>>,
        /// The effector's point in mm: `--xyz 0,50,-650`.
        #[arg(
            long,
            value_delimiter = ',',
            allow_hyphen_values = true,
            value_name = "X,Y,Z",
            conflicts_with = "to"
        )]
        xyz: Option<Vec<f64>>,
        /// A straight line to the --xyz point (from rest).
        #[arg(long, requires = "xyz")]
        linear: bool,
        /// A fraction of the motors' limits, 0 < F ≤ 1.
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
    },
    /// Follow a PVT knot file (thesis A.2.3.2) from rest: its first knot is where the robot
    /// rests (time 0), each next one the previous knot's time on. Checked as `qmarc-starter
    /// run --method pvt --knots FILE` checks it, then by the controller as any path
    /// (`qmarc/path`, at most 1024 knots).
    Path {
        /// The PVT knot file.
        file: std::path::PathBuf,
        /// First a jerk-limited move from where the robot rests to the path's first knot
        /// (`trajectory.approach_speed` of the limits), as `run --approach`.
        #[arg(long)]
        approach: bool,
    },
    /// A jerk-limited stop to rest.
    Stop,
    /// Close (`on`) or open (`off`) the gripper now; `wait` then waits until it is there.
    Grip {
        /// `on` closes it, `off` opens it.
        #[arg(value_name = "on|off", value_parser = qmarc_program::cli::parse_on_off, action = clap::ArgAction::Set)]
        close: bool,
    },
    /// Wait until the robot is at rest at the end of the last move accepted.
    Wait {
        /// Give up after S seconds (exit 1).
        #[arg(long, default_value_t = 60.0)]
        timeout: f64,
    },
    /// Where the robot is.
    Status,
    /// Stop, then end the session as a move ends (data files written).
    Quit,
}

/// The serving session `qmarc cmd` addresses: where, its settings, and how to name it.
struct Session {
    location: IpcLocation,
    settings: qmarc_config::Settings,
    /// What runs it, when its processes were found.
    live: Option<LiveRun>,
}

impl Session {
    /// The session of `--iox-prefix`, else the only one that serves; several serving and no
    /// prefix to choose is refused (the error lists them).
    fn find(args: &CmdArgs) -> Result<Session, SessionFindError> {
        let (location, spec, live) =
            serving_session(args.iox_prefix.as_deref(), args.iox_root.as_deref())?;
        Ok(Session { location, settings: spec.settings, live })
    }

    /// The line that names it, printed under every answer.
    fn named(&self) -> String {
        match &self.live {
            Some(run) => format!("  session {}: {}", self.location.prefix, run.brief()),
            None => format!("  session {}", self.location.prefix),
        }
    }
}

/// The path request of the PVT knot file `file`, checked by the session's `settings`.
fn path_request(
    file: &std::path::Path,
    settings: &qmarc_config::Settings,
) -> anyhow::Result<Box<PathRequest>> {
    use qmarc_knots::{KnotRules, parse_pvt, read_knot_file};
    let text = read_knot_file(file)?;
    let knots = parse_pvt(&file.display().to_string(), &text, &KnotRules::from_settings(settings))?;
    let mut t_s = 0.0;
    let path: Vec<PathKnot> = knots
        .iter()
        .map(|k| {
            let knot = PathKnot { t_s, pos: k.pos, vel: k.vel };
            t_s += k.dt_s;
            knot
        })
        .collect();
    PathRequest::new(&path, true).ok_or_else(|| {
        anyhow::anyhow!(
            "{}: {} knots: a path sent to a session has at most {MAX_PATH_KNOTS}",
            file.display(),
            path.len()
        )
    })
}

/// The words of a status.
fn describe(s: &CommandResponse, n: usize) -> String {
    let phase = Phase::from_wire(s.robot.phase).map_or("?", Phase::name_serving);
    let fault =
        FaultKind::from_wire(s.robot.fault).map_or(String::new(), |f| format!(", fault {f}"));
    let counts = |v: &[f64]| v[..n].iter().map(|c| format!("{c:.1}")).collect::<Vec<_>>().join(" ");
    let mut out = format!(
        "{}; loop {phase}{fault}; moves accepted {}, settled {}\n  command {} cnt\n  actual  {} cnt",
        if s.orders.moving == 1 { "moving" } else { "at rest" },
        s.orders.accepted,
        s.orders.settled,
        counts(&s.robot.command),
        counts(&s.robot.actual),
    );
    if s.robot.effector_mm.iter().all(|v| v.is_finite()) {
        let [x, y, z] = s.robot.effector_mm;
        out.push_str(&format!("\n  effector {x:.2} {y:.2} {z:.2} mm"));
    }
    let gripper = qmarc_proto::Gripper(s.robot.gripper);
    if gripper.code() >= 0 {
        out.push_str(&format!("\n  gripper {}", gripper.name()));
    }
    if s.conveyor.active == 1 {
        out.push_str(&format!("\n  {}", s.conveyor.describe()));
    }
    let unhomed: Vec<String> =
        (0..n).filter(|m| s.robot.homed & (1 << m) == 0).map(|m| (m + 1).to_string()).collect();
    if !unhomed.is_empty() {
        out.push_str(&format!("\n  not homed: motor {}", unhomed.join(", ")));
    }
    out
}

/// The request of a `move`.
fn move_request(
    to: &Option<Vec<f64>>,
    xyz: &Option<Vec<f64>>,
    linear: bool,
    speed: f64,
) -> anyhow::Result<CommandRequest> {
    match (to, xyz) {
        (Some(c), None) if !c.is_empty() && c.len() <= qmarc_proto::MAX_MOTORS => {
            Ok(CommandRequest::move_to(c, speed))
        }
        (None, Some(p)) if p.len() == 3 => {
            Ok(CommandRequest::move_xyz([p[0], p[1], p[2]], linear, speed))
        }
        (None, Some(p)) => {
            anyhow::bail!("--xyz: a point is three numbers X,Y,Z in mm, found {}", p.len())
        }
        (Some(c), None) => {
            anyhow::bail!("--to: 1 to {} joint counts, found {}", qmarc_proto::MAX_MOTORS, c.len())
        }
        _ => anyhow::bail!("move needs a target: --to C1,C2,C3 or --xyz X,Y,Z"),
    }
}

/// What `qmarc cmd` sends, made from its command line before anything is sent.
enum Outgoing {
    /// A path request (`path`).
    Path(Box<PathRequest>),
    /// An order, and its word in the answer (`move`, `stop`, `grip`, `quit`).
    Order(CommandRequest, &'static str),
    /// `status`.
    Status,
    /// `wait`, giving up after this many seconds.
    Wait(f64),
}

/// The request of `args` for the session's `settings`: a knot file read and checked, a
/// target of the session's motors. An error is the user's input, refused before anything is
/// sent, in the starter's words where the starter checks the same (a `--to` of another
/// length than the motors: the wire carries up to [`qmarc_proto::MAX_MOTORS`], so it is
/// checked here; everything else of a move the controller checks, with the same settings'
/// checks).
fn outgoing(args: &CmdArgs, settings: &qmarc_config::Settings) -> anyhow::Result<Outgoing> {
    Ok(match &args.command {
        Cmd::Path { file, approach } => {
            let mut request = path_request(file, settings)?;
            if *approach {
                request.flags |= PathRequest::APPROACH;
            }
            Outgoing::Path(request)
        }
        Cmd::Move { to, xyz, linear, speed } => {
            if let Some(to) = to.as_ref().filter(|to| to.len() != settings.n_motors) {
                settings.clone().set_move_to(to)?;
            }
            Outgoing::Order(move_request(to, xyz, *linear, *speed)?, "move")
        }
        Cmd::Stop => Outgoing::Order(CommandRequest::of(CommandKind::Stop), "stop"),
        Cmd::Grip { close } => Outgoing::Order(CommandRequest::grip(*close), "grip"),
        Cmd::Quit => Outgoing::Order(CommandRequest::of(CommandKind::Quit), "quit"),
        Cmd::Status => Outgoing::Status,
        Cmd::Wait { timeout } => Outgoing::Wait(*timeout),
    })
}

/// Sends `out` to `session` and prints the answer; the exit code.
fn run(session: &Session, out: Outgoing) -> anyhow::Result<u8> {
    let (location, n) = (&session.location, session.settings.n_motors);
    let mut client = match CommandClient::connect(location) {
        Ok(c) => c,
        Err(e) => {
            // The session ended meanwhile: what the node made goes with the run's files.
            if serving(&location.prefix).is_none() {
                location.remove_files();
            }
            return Err(e.into());
        }
    };
    match out {
        Outgoing::Path(request) => Ok(said(&client.send_path(&request)?, "path")),
        Outgoing::Order(request, what) => Ok(said(&client.send(request)?, what)),
        Outgoing::Status => {
            let answer = client.send(CommandRequest::of(CommandKind::Status))?;
            let ended = if answer.refused().is_some() { " (the session has ended)" } else { "" };
            println!("{}{ended}", describe(&answer, n));
            Ok(0)
        }
        Outgoing::Wait(timeout) => {
            let s = client.wait(Duration::from_secs_f64(timeout.max(0.0)))?;
            println!("{}", describe(&s, n));
            if OrderLedger::of(&s).fate(s.orders.accepted) == Fate::NotTaken {
                println!(
                    "move {} was not taken: {}; the robot went on as it was",
                    s.orders.accepted,
                    s.reason()
                );
                return Ok(qmarc_proto::exit::REFUSED);
            }
            Ok(if s.robot.fault == 0 { 0 } else { qmarc_proto::exit::FAULT })
        }
    }
}

/// Prints whether `answer` accepted the order `what` (`move`, `path`, `stop`, `grip`, `quit`)
/// and the id it has (a quit has none: the session ends); its exit code.
fn said(answer: &CommandResponse, what: &str) -> u8 {
    match answer.refused() {
        None if what == "quit" => {
            println!("accepted (quit): the robot stops, then the session ends");
            0
        }
        None => {
            println!("accepted ({what} {})", answer.orders.accepted);
            0
        }
        Some(r) => {
            println!("refused ({}): {}", r.name(), answer.reason());
            qmarc_proto::exit::REFUSED
        }
    }
}

/// `qmarc cmd ARGS…`.
pub fn main(args: &[OsString]) -> ExitCode {
    let all = std::iter::once(OsString::from("qmarc cmd")).chain(args.iter().cloned());
    let args = match CmdArgs::try_parse_from(all) {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { qmarc_proto::exit::USAGE } else { 0 });
        }
    };
    let session = match Session::find(&args) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("qmarc cmd: {e}");
            // Several sessions and none chosen: refused (nothing was sent); none: no session.
            let code = match e {
                SessionFindError::Ambiguous(_) => qmarc_proto::exit::REFUSED,
                _ => qmarc_proto::exit::INTERNAL,
            };
            return ExitCode::from(code);
        }
    };
    // Bad input is refused before anything is sent (exit 3, as the starter refuses it).
    let out = match outgoing(&args, &session.settings) {
        Ok(out) => out,
        Err(e) => {
            println!("refused (bad_request): {e:#}");
            println!("{}", session.named());
            return ExitCode::from(qmarc_proto::exit::REFUSED);
        }
    };
    let outcome = run(&session, out);
    println!("{}", session.named());
    match outcome {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            eprintln!("qmarc cmd: {e:#}");
            ExitCode::from(qmarc_proto::exit::INTERNAL)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_well_formed_and_grip_takes_on_or_off() {
        CmdArgs::command().debug_assert();
        let parse = |args: &[&str]| CmdArgs::try_parse_from(args);
        let grip = |args: &[&str]| match parse(args).map(|a| a.command) {
            Ok(Cmd::Grip { close }) => Some(close),
            _ => None,
        };
        assert_eq!(grip(&["cmd", "grip", "on"]), Some(true));
        assert_eq!(grip(&["cmd", "grip", "off"]), Some(false));
        assert!(parse(&["cmd", "grip", "half"]).is_err());
        assert!(parse(&["cmd", "grip"]).is_err());
    }

    /// Issue 42: `path --help` names the check that exists (`run --method pvt --knots`, not
    /// a `move --knots` there is none of), and coordinates are typed as they are.
    #[test]
    fn the_help_names_real_commands_and_negative_numbers_are_values() {
        let mut cmd = CmdArgs::command();
        let help = cmd.find_subcommand_mut("path").expect("path").render_long_help().to_string();
        assert!(help.contains("run --method pvt --knots FILE") && !help.contains("move --knots"));
        assert!(help.contains("--approach"), "{help}");
        let xyz = CmdArgs::try_parse_from(["cmd", "move", "--xyz", "-60,0,-650"]).unwrap();
        let Cmd::Move { xyz, .. } = xyz.command else { panic!("a move") };
        assert_eq!(xyz, Some(vec![-60.0, 0.0, -650.0]));
    }
}
