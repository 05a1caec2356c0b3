//! `qmarc-starter path`: a Cartesian waypoint file into a knot file for `run`
//! ([`qmarc_waypoints`]), on the robot the settings describe.

use crate::cli::MoveOptions;
use anyhow::{Context, anyhow, bail};
use clap::Args;
use qmarc_waypoints::KnotFormat;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Options of `path`. The knot file goes to `--out FILE`.
#[derive(Debug, Clone, PartialEq, Args)]
pub struct PathArgs {
    /// Waypoint file: one line per waypoint, `t_s x_m y_m z_m`, times strictly increasing.
    #[arg(long)]
    pub waypoints: PathBuf,
    /// The knot file to make: `spline` (thesis A.2.3.1) or `pvt` (A.2.3.2).
    #[arg(long)]
    pub method: String,
    /// Resample the Cartesian path every T ms (default: a knot at each waypoint).
    #[arg(long, value_name = "T")]
    pub every_ms: Option<f64>,
}

/// Makes the knot file of `args` and writes it to `opts.out`, a file that must not exist yet
/// (as `tune --write`: nothing is ever written over); returns what it did, for the terminal.
pub fn make(opts: &MoveOptions, args: &PathArgs) -> anyhow::Result<String> {
    let out = opts.out.as_deref().context("--out FILE: where to write the knot file")?;
    let format = KnotFormat::of_method(&args.method).ok_or_else(|| {
        anyhow!("--method: `{}` has no knot file; use spline or pvt", args.method)
    })?;
    if same_file(out, &args.waypoints) {
        bail!("--out {}: that is the waypoint file; write the knots elsewhere", out.display());
    }
    if out.symlink_metadata().is_ok() {
        bail!(already_there(out));
    }
    let settings = opts.load(&qmarc_plugins::registry::names())?;
    let made = qmarc_waypoints::generate(&settings, &args.waypoints, format, args.every_ms)?;
    write_atomically(out, made.text.as_bytes())?;
    Ok(format!("wrote {} {} knots to {}", made.knots, args.method, out.display()))
}

/// True when `a` and `b` name one existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// Why `--out` is refused when it names something that exists.
fn already_there(out: &Path) -> String {
    format!(
        "--out {}: it exists; path never writes over a file (remove it, or give another name)",
        out.display()
    )
}

/// Writes `bytes` to the new file `path` through a temporary file beside it, so a reader
/// never sees half a knot file; the temporary file is linked into place only if nothing has
/// appeared there meanwhile.
fn write_atomically(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let name =
        path.file_name().with_context(|| format!("--out {}: not a file name", path.display()))?;
    let tmp =
        path.with_file_name(format!(".{}.{}.tmp", name.to_string_lossy(), std::process::id()));
    let written = std::fs::File::create(&tmp)
        .and_then(|mut f| f.write_all(bytes).and_then(|()| f.sync_all()))
        .and_then(|()| std::fs::hard_link(&tmp, path));
    let _ = std::fs::remove_file(&tmp);
    match written {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => bail!(already_there(path)),
        Err(e) => bail!("cannot write {}: {e}", path.display()),
    }
}
