//! The exit codes of every QMARC program: one table, shared by `qmarc-starter`, `qmarc`, and
//! the two children the starter reads them from. docs/usage.md "Exit codes" is this table.
//!
//! | code | meaning |
//! |---|---|
//! | 0 | ok: the move ran to its end (or the console ended normally) |
//! | 1 | internal: something failed that is not the user's input (a process that could not start or died, a file that could not be written, a bug) |
//! | 2 | fault: a fault ended the move; the summary names it, the motors are disabled |
//! | 3 | refused: nothing moved — bad settings, knots or output folder, an unhomed frame, a path off the limits, another run on the same output |
//! | 4 | rescued: the move ran to its end, but its results could not be written to the output folder: they are in the rescue folder the message names |
//! | 64 | usage: the command line is wrong (`EX_USAGE`) |
//! | 130 | interrupted: a stop signal (Ctrl-C, SIGTERM, the terminal gone) ended it, motors disabled first |
//!
//! ```
//! assert_eq!(qmarc_proto::exit::describe(130), "interrupted");
//! ```

/// The move ran to its end.
pub const OK: u8 = 0;
/// Something failed that is not the user's input.
pub const INTERNAL: u8 = 1;
/// A fault ended the move (motors disabled; the summary names it).
pub const FAULT: u8 = 2;
/// Refused before anything moved.
pub const REFUSED: u8 = 3;
/// The move ran to its end, but its results are in the rescue folder, not the output folder
/// (a full disk): not a success.
pub const RESCUED: u8 = 4;
/// The command line is wrong (BSD `EX_USAGE`).
pub const USAGE: u8 = 64;
/// A stop signal ended it (128 + SIGINT, the shell's code for Ctrl-C).
pub const INTERRUPTED: u8 = 130;

/// The table's word for `code`.
pub fn describe(code: i32) -> &'static str {
    match code {
        0 => "ok",
        1 => "internal error",
        2 => "fault",
        3 => "refused",
        4 => "results rescued",
        64 => "usage error",
        130 => "interrupted",
        _ => "unknown exit code",
    }
}
