//! The two ends of every QMARC program's `main`: reading its command line
//! ([`parse_or_exit`]) and turning what it did into its exit code ([`conclude`]), so that
//! `qmarc-starter`, `qmarc-hwserver`, `qmarc-controller`, `qmarc`, `qmarc-bridge` and
//! `qmarc-bench` all answer a wrong command line, `--help` and an error the same way
//! (docs/usage.md "Exit codes", [`qmarc_proto::exit`]); and the values more than one
//! program's command line takes ([`parse_on_off`], [`check_ros_namespace`]).

use std::io::Write;
use std::process::ExitCode;

/// Parses the command line of a QMARC program. A wrong command line prints clap's message and
/// exits with [`qmarc_proto::exit::USAGE`] (clap's own code, 2, would read as "fault"); `--help`
/// and `--version` print and exit 0.
pub fn parse_or_exit<T: clap::Parser>() -> T {
    match T::try_parse() {
        Ok(t) => t,
        Err(e) => {
            let code =
                if e.use_stderr() { qmarc_proto::exit::USAGE } else { qmarc_proto::exit::OK };
            let _ = e.print();
            std::process::exit(i32::from(code));
        }
    }
}

/// What a program's work ended with: its exit code, or the code of the table and the error
/// that ended it.
pub type Outcome<E> = Result<ExitCode, (u8, E)>;

/// The exit code of `outcome`; an error is first said on standard error as
/// `<program>: error: <error>` (`{:#}`: an `anyhow` error with its causes), without
/// panicking when standard error is gone.
pub fn conclude<E: std::fmt::Display>(program: &str, outcome: Outcome<E>) -> ExitCode {
    match outcome {
        Ok(code) => code,
        Err((code, e)) => {
            let _ = writeln!(std::io::stderr(), "{program}: error: {e:#}");
            ExitCode::from(code)
        }
    }
}

/// `on` or `off` (`--grip`, `qmarc cmd grip`).
pub fn parse_on_off(v: &str) -> Result<bool, String> {
    match v {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("`{v}` is not on or off")),
    }
}

/// Checks a ROS namespace as given on a command line (`qmarc-bridge --namespace`, `serve
/// --bridge --namespace`): empty, or `/` then names of letters, digits and `_` (not starting
/// with a digit) joined by `/`, without a trailing `/`.
pub fn check_ros_namespace(ns: &str) -> Result<(), String> {
    let valid = ns.is_empty()
        || ns.starts_with('/')
            && !ns.ends_with('/')
            && ns[1..].split('/').all(|p| {
                p.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                    && p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            });
    if valid { Ok(()) } else { Err(format!("`{ns}` is not a ROS namespace (/robot1)")) }
}

#[cfg(test)]
mod tests {
    #[test]
    fn on_and_off_are_the_only_switch_words() {
        assert_eq!((super::parse_on_off("on"), super::parse_on_off("off")), (Ok(true), Ok(false)));
        assert_eq!(super::parse_on_off("yes"), Err("`yes` is not on or off".into()));
    }

    #[test]
    fn ros_namespaces_are_checked() {
        for ok in ["", "/robot1", "/cell_a/robot_2"] {
            assert_eq!(super::check_ros_namespace(ok), Ok(()), "{ok}");
        }
        for bad in ["robot1", "/robot1/", "/1robot", "/ro-bot", "/a//b"] {
            assert!(super::check_ros_namespace(bad).is_err(), "{bad}");
        }
    }
}
