//! The PNG plots of a move and of repeated trials — thesis chapter 5's figures, drawn right
//! after the move from the files it left (`gather.csv`, `summary.json`), so nobody needs
//! Matlab to see them.
//!
//! - [`move_plots`]: arm command vs actual, following error, command velocity and
//!   acceleration, servo period and DAC output (Fig. 5-1) and, with a `[robot]`, the
//!   end-effector path in 3-D and its X-Z projection (Fig. 5-2, 5-4), command vs actual.
//! - [`trial_plots`]: the accumulated error per trial and arm (Fig. 5-17) and the periods
//!   more than 40 µs off per trial (Fig. 5-18).
//! - [`convergence_plot`]: `qmarc-starter tune`'s best objective per evaluation and motor.
//!
//! Every axis is labelled with its unit. Text is drawn with an embedded font (DejaVu Sans),
//! so the plots look the same on every machine and need no font installed. A PNG is drawn
//! under a temporary name and renamed into place: a reader never sees half a plot.
//!
//! ```no_run
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let dir = std::path::Path::new("out");
//! let summary = qmarc_report::Summary::read(dir)?;
//! for png in qmarc_plots::move_plots(dir, &summary, None)? {
//!     println!("{}", png.display());
//! }
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

mod chart;
mod moves;
mod trials;
mod tuning;

pub use moves::move_plots;
pub use trials::{TRIAL_PLOT_FILES, trial_plots};
pub use tuning::{CONVERGENCE_PLOT_FILE, convergence_plot};

use std::path::PathBuf;

/// A plot could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The move's data could not be read.
    #[error("cannot plot the move: {0}")]
    Data(String),
    /// Drawing or writing a PNG failed.
    #[error("cannot draw {path}: {why}")]
    Draw {
        /// The PNG.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
}

#[cfg(test)]
mod tests;
