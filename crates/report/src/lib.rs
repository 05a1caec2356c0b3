//! What a move leaves behind, written after it: `summary.json` (its schema, [`summary`], and
//! how it is made from the loop's figures, [`summarize`]), `gather.csv` and `gather.m`
//! ([`files`]) and read back ([`series`]), the Cartesian figures ([`effector`]), the open-loop
//! check's ([`check`]), the output folder's rules ([`output`]: checked, locked, replaced as one set,
//! a rescue folder), the table the starter prints ([`table`]) and the rows of repeated trials ([`trials`]).
//!
//! ```
//! use qmarc_report::table::human_us;
//! assert_eq!(human_us(1_240.0), "1.24 ms");
//! ```
#![deny(missing_docs)]

/// The open-loop check's report.
pub mod check;
pub mod effector;
pub mod figures;
pub mod files;
pub mod output;
pub mod series;
pub mod summarize;
pub mod summary;
pub mod table;
pub mod trials;

pub use summary::Summary;
