//! `[cell]`: this robot in a cell of robots on one belt (issue 47; `qmarc-starter conveyor
//! --cell NAME`): its name among them and where it stands along the cell's belt. The cell
//! itself (its name, the Zenoh session) is the command line's: a robot's file says what the
//! robot is, not which cell it joins.

use crate::ConfigLoadError;
use crate::conveyor::MAX_BELT_MM;
use crate::source::{S, Source, num};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Longest robot or cell name: a chunk of a Zenoh key expression, in a fixed-size message.
pub const MAX_CELL_NAME: usize = 31;

/// This robot in a cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellSettings {
    /// This robot's name in the cell: unique among its robots.
    pub robot: String,
    /// Where this robot's belt coordinate 0 lies on the cell's belt, mm (the cell's belt
    /// coordinates are the camera's).
    pub belt_offset_mm: f64,
    /// The cell joined (`--cell NAME`); `None`: a robot on its own.
    #[serde(default)]
    pub name: Option<String>,
    /// The Zenoh session's configuration file (`--zenoh-config`); `None`: rmw_zenoh's
    /// default session (peer mode, a router at `tcp/localhost:7447`).
    #[serde(default)]
    pub zenoh_config: Option<PathBuf>,
}

impl Default for CellSettings {
    /// A robot named `deltabot` at the cell's belt coordinate 0.
    fn default() -> CellSettings {
        CellSettings {
            robot: "deltabot".into(),
            belt_offset_mm: 0.0,
            name: None,
            zenoh_config: None,
        }
    }
}

/// Why `name` cannot name a robot or a cell, if it cannot: 1‥[`MAX_CELL_NAME`] characters
/// of letters, digits, `-` and `_` (a chunk of a Zenoh key expression).
pub fn cell_name_problem(name: &str) -> Option<String> {
    let ok = (1..=MAX_CELL_NAME).contains(&name.len())
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    (!ok).then(|| {
        format!(
            "must be 1‥{MAX_CELL_NAME} letters, digits, `-` or `_`, found {:?}",
            name.chars().take(64).collect::<String>()
        )
    })
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCell {
    robot: S<String>,
    belt_offset_mm: S<f64>,
}

impl RawCell {
    /// Checked.
    pub(crate) fn check(&self, src: &Source<'_>) -> Result<CellSettings, ConfigLoadError> {
        let d = CellSettings::default();
        Ok(CellSettings {
            robot: src.take(&self.robot, "cell.robot", d.robot, |n| {
                cell_name_problem(n).map_or(Ok(()), Err)
            })?,
            belt_offset_mm: src.take(&self.belt_offset_mm, "cell.belt_offset_mm", 0.0, |v| {
                if v.is_finite() && v.abs() <= MAX_BELT_MM {
                    Ok(())
                } else {
                    Err(format!("must be within ±{} mm, found {}", num(MAX_BELT_MM), num(*v)))
                }
            })?,
            name: None,
            zenoh_config: None,
        })
    }
}

impl crate::Settings {
    /// Joins the cell `name` (`--cell`), over the Zenoh session `zenoh_config` describes
    /// (`--zenoh-config`; `None`: rmw_zenoh's default).
    pub fn set_cell(
        &mut self,
        name: &str,
        zenoh_config: Option<&Path>,
    ) -> Result<(), ConfigLoadError> {
        if let Some(message) = cell_name_problem(name) {
            return Err(ConfigLoadError::Override { flag: "--cell", message });
        }
        if let Some(p) = zenoh_config.filter(|p| !p.is_file()) {
            return Err(ConfigLoadError::Override {
                flag: "--zenoh-config",
                message: format!("{} is not a file", p.display()),
            });
        }
        self.cell.name = Some(name.to_string());
        self.cell.zenoh_config = zenoh_config.map(Path::to_path_buf);
        Ok(())
    }
}
