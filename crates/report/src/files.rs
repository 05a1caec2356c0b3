//! The data files of a move: `gather.csv` and `gather.m` (Octave/Matlab), written from the
//! gather buffer after the move.

use qmarc_config::GatherFields;
use qmarc_controller::gather::{Gather, GatherRow};
use std::io::{self, Write};

/// Column names: `cycle,time_s,cmd1,act1,dac1,cmd2,…`, then `grip` when a gripper is wired
/// and `conv` (the belt encoder's counts) when the run reads a belt.
pub fn columns(g: &Gather) -> Vec<String> {
    columns_of(g.fields(), g.n_motors())
}

/// [`columns`] of rows with `fields` of `n_motors` motors.
pub fn columns_of(f: GatherFields, n_motors: usize) -> Vec<String> {
    let mut c = vec!["cycle".to_string()];
    if f.time {
        c.push("time_s".to_string());
    }
    for m in 1..=n_motors {
        for (on, name) in [(f.cmd, "cmd"), (f.act, "act"), (f.dac, "dac")] {
            if on {
                c.push(format!("{name}{m}"));
            }
        }
    }
    if f.grip {
        c.push("grip".to_string());
    }
    if f.conv {
        c.push("conv".to_string());
    }
    c
}

/// One value of a gathered row, in [`columns`]' order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Cell {
    /// A whole number (cycle, DAC code, gripper state, belt counts).
    Int(i64),
    /// A measurement (time, command, position).
    Float(f64),
}

impl std::fmt::Display for Cell {
    /// `{}` on f64 is the shortest text that parses back to the same value, so figures
    /// recomputed from the file equal the ones computed in the loop.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Cell::Int(v) => write!(f, "{v}"),
            Cell::Float(v) => write!(f, "{v}"),
        }
    }
}

/// Calls `each` with the values of row `r`, in [`columns`]' order.
pub fn cells(
    g: &Gather,
    r: &GatherRow,
    each: impl FnMut(Cell) -> io::Result<()>,
) -> io::Result<()> {
    cells_of(g.fields(), g.n_motors(), r, each)
}

/// [`cells`] of a row with `fields` of `n_motors` motors.
pub fn cells_of(
    f: GatherFields,
    n_motors: usize,
    r: &GatherRow,
    mut each: impl FnMut(Cell) -> io::Result<()>,
) -> io::Result<()> {
    each(Cell::Int(r.cycle as i64))?;
    if f.time {
        each(Cell::Float(r.time_s))?;
    }
    for m in 0..n_motors {
        if f.cmd {
            each(Cell::Float(r.cmd[m]))?;
        }
        if f.act {
            each(Cell::Float(r.act[m]))?;
        }
        if f.dac {
            each(Cell::Int(r.dac[m].into()))?;
        }
    }
    if f.grip {
        each(Cell::Int(r.grip.into()))?;
    }
    if f.conv {
        each(Cell::Int(r.conv))?;
    }
    Ok(())
}

fn write_row(
    g: &Gather,
    w: &mut (impl Write + ?Sized),
    r: &GatherRow,
    sep: &str,
) -> io::Result<()> {
    let mut first = true;
    cells(g, r, |c| {
        let sep = if std::mem::take(&mut first) { "" } else { sep };
        write!(w, "{sep}{c}")
    })?;
    writeln!(w)
}

/// Writes `gather.csv`: a header line, then one line per row.
pub fn write_csv(g: &Gather, w: &mut (impl Write + ?Sized)) -> io::Result<()> {
    writeln!(w, "{}", columns(g).join(","))?;
    for r in g.rows() {
        write_row(g, w, r, ",")?;
    }
    Ok(())
}

/// Writes `gather.m`: the same data as an Octave/Matlab script defining `qmarc_data`,
/// `qmarc_columns` and one column vector per column name.
pub fn write_octave(g: &Gather, w: &mut (impl Write + ?Sized)) -> io::Result<()> {
    let cols = columns(g);
    writeln!(w, "% QMARC gathered data, written by qmarc-controller after the move.")?;
    writeln!(w, "% One row per gathered servo cycle (every {} cycles).", g.every())?;
    writeln!(
        w,
        "% cycle: servo sample n; time_s: s; cmdM/actM: counts; dacM: DAC codes (±8191 = ±10 V)."
    )?;
    if g.fields().grip {
        writeln!(w, "% grip: the gripper, 0 open, 1 closing, 2 closed, 3 opening.")?;
    }
    if g.fields().conv {
        writeln!(w, "% conv: the belt encoder, counts (conveyor.mm_per_count mm each).")?;
    }
    let quoted: Vec<String> = cols.iter().map(|c| format!("'{c}'")).collect();
    writeln!(w, "qmarc_columns = {{{}}};", quoted.join(", "))?;
    writeln!(w, "qmarc_data = [")?;
    for r in g.rows() {
        write_row(g, w, r, " ")?;
    }
    writeln!(w, "];")?;
    for (i, c) in cols.iter().enumerate() {
        writeln!(w, "{c} = qmarc_data(:, {});", i + 1)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(cycle: u64) -> GatherRow {
        GatherRow {
            cycle,
            time_s: cycle as f64 * 0.0004,
            cmd: [1000.5, -3.0, 0.0, 0.0],
            act: [998.0, -1.0, 0.0, 0.0],
            dac: [12, -8191, 0, 0],
            grip: 2,
            conv: -70_001,
        }
    }

    #[test]
    fn csv_and_octave_carry_the_same_rows() {
        let mut g = Gather::for_move(3, 1, 2);
        for k in 0..3 {
            g.push(row(k));
        }
        let mut csv = Vec::new();
        write_csv(&g, &mut csv).unwrap();
        let csv = String::from_utf8(csv).unwrap();
        assert_eq!(
            csv,
            "cycle,time_s,cmd1,act1,dac1,cmd2,act2,dac2\n\
             0,0,1000.5,998,12,-3,-1,-8191\n\
             1,0.0004,1000.5,998,12,-3,-1,-8191\n\
             2,0.0008,1000.5,998,12,-3,-1,-8191\n"
        );
        let mut m = Vec::new();
        write_octave(&g, &mut m).unwrap();
        let m = String::from_utf8(m).unwrap();
        assert!(m.contains(
            "qmarc_columns = {'cycle', 'time_s', 'cmd1', 'act1', 'dac1', 'cmd2', 'act2', 'dac2'};\n"
        ));
        let data: Vec<&str> = m
            .split("qmarc_data = [\n")
            .nth(1)
            .unwrap()
            .split("];")
            .next()
            .unwrap()
            .lines()
            .collect();
        let csv_rows: Vec<String> = csv.lines().skip(1).map(|l| l.replace(',', " ")).collect();
        assert_eq!(data, csv_rows);
        assert!(m.ends_with("dac2 = qmarc_data(:, 8);\n"));
    }

    #[test]
    fn only_the_chosen_fields_are_written() {
        let mut g = Gather::for_move(1, 1, 2).with_fields(GatherFields {
            time: false,
            cmd: true,
            act: true,
            dac: false,
            grip: false,
            conv: false,
        });
        g.push(row(7));
        let mut csv = Vec::new();
        write_csv(&g, &mut csv).unwrap();
        assert_eq!(
            String::from_utf8(csv).unwrap(),
            "cycle,cmd1,act1,cmd2,act2\n7,1000.5,998,-3,-1\n"
        );
        // Issue 30: the gripper's state last, when one is wired.
        let fields = GatherFields {
            time: false,
            cmd: false,
            act: false,
            dac: true,
            grip: true,
            conv: false,
        };
        let mut g = Gather::for_move(1, 1, 2).with_fields(fields);
        g.push(row(7));
        let mut csv = Vec::new();
        write_csv(&g, &mut csv).unwrap();
        assert_eq!(String::from_utf8(csv).unwrap(), "cycle,dac1,dac2,grip\n7,12,-8191,2\n");
        let mut m = Vec::new();
        write_octave(&g, &mut m).unwrap();
        assert!(String::from_utf8(m).unwrap().contains("% grip: the gripper, 0 open"));
        // Issue 44: the belt's counts after it, when the run reads a belt.
        let fields = GatherFields { conv: true, ..fields };
        let mut g = Gather::for_move(1, 1, 2).with_fields(fields);
        g.push(row(7));
        let mut csv = Vec::new();
        write_csv(&g, &mut csv).unwrap();
        assert_eq!(
            String::from_utf8(csv).unwrap(),
            "cycle,dac1,dac2,grip,conv\n7,12,-8191,2,-70001\n"
        );
    }
}
