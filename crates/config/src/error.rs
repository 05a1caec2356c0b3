//! [`ConfigLoadError`]: why settings could not be loaded, naming file, line, column and field.

use std::path::PathBuf;

/// The settings file could not be loaded, or an override is out of range.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigLoadError {
    /// The file could not be read. (The OS error is part of the message, not a source: each
    /// error is printed on one line, its reason once.)
    #[error("{file}: cannot read the settings file: {reason}")]
    Read {
        /// The file.
        file: PathBuf,
        /// Why.
        reason: std::io::Error,
    },
    /// The file is larger than a settings file may be.
    #[error("{file}: the file has more than {limit} bytes, the most a settings file may have")]
    TooLarge {
        /// The file.
        file: PathBuf,
        /// [`crate::MAX_CONFIG_BYTES`].
        limit: u64,
    },
    /// A value is missing, unknown, of the wrong type or out of range.
    #[error("{file}:{line}:{column}: {field}: {message}")]
    Invalid {
        /// The file.
        file: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// Dotted path of the field, e.g. `motor[2].kp` (motors 1-based).
        field: String,
        /// What is wrong and what is expected.
        message: String,
    },
    /// A command-line override is out of range.
    #[error("{flag}: {message}")]
    Override {
        /// The flag, e.g. `--period-us`.
        flag: &'static str,
        /// What is wrong.
        message: String,
    },
}
