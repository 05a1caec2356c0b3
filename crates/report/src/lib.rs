//! What a move leaves behind, written after it: `summary.json` (its schema, [`summary`], and
//! how it is made from the loop's figures, [`summarize`]), `gather.csv` and `gather.m`
//! ([`files`]), the Cartesian figures ([`effector`]), the output folder's rules ([`output`]: checked, locked, replaced as one set,
//! a rescue folder) and the table the starter prints ([`table`]).
//!
//! ```
//! use qmarc_report::table::human_us;
//! assert_eq!(human_us(1_240.0), "1.24 ms");
//! ```
#![deny(missing_docs)]

pub mod effector;
pub mod files;
pub mod output;
pub mod summarize;
pub mod summary;
pub mod table;

pub use summary::Summary;
