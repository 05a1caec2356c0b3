//! A conveyor session's results: `parts.csv`, one row per part the camera saw, and
//! `summary.json`'s `conveyor` section, both from the dispatcher's records and the gathered
//! rows — the grip error measured as its user would: the forward kinematics of the actual
//! motor positions in the gathered row of the cycle the gripper was told to close, against
//! the part's grip point where the belt (that row's `conv`) had carried it.

use qmarc_config::Settings;
use qmarc_controller::gather::{Gather, GatherRow};
use qmarc_foxglove::recording::Part;
use qmarc_report::summary::{
    CellSummary, ConveyorLatency, ConveyorSummary, ErrorFigures, Latencies,
};
use qmarc_session::conveyor::BeltFrame;
use qmarc_session::conveyor::dispatch::{Dispatched, PartRecord};
use std::fmt::Write;

/// `parts.csv`'s header.
pub const PARTS_HEADER: &str =
    "id,t_seen_s,latched_counts,belt_mm,across_mm,state,grip_cycle,place_cycle,error_mm";

/// `parts.csv`'s last columns in a cell: from the part's exposure to its claim as this robot
/// saw it, ms (made here, or heard from another; empty: none), and the robot that picked the
/// part (empty: none did, or its pick was not heard).
pub const CELL_COLUMNS: &str = "claimed_ms,by";

/// The gathered row of `cycle`, or the first after it (gathering every N-th cycle).
fn row(rows: &[GatherRow], cycle: u64) -> Option<&GatherRow> {
    rows.get(rows.partition_point(|r| r.cycle < cycle))
}

/// The effector against part `p`'s grip point in gathered row `r`, mm.
fn error_mm(frame: &BeltFrame, p: &PartRecord, r: &GatherRow) -> Option<f64> {
    let act = [r.act[0], r.act[1], r.act[2]];
    let part = (p.belt_mm, p.across_mm, p.latched_counts as f64);
    frame.effector_error_mm(act, r.conv as f64, part)
}

/// The latencies of the parts `parts` (none when the session did not measure them).
fn latency(parts: &[PartRecord]) -> Option<ConveyorLatency> {
    let queued: Vec<u64> = parts.iter().filter_map(|p| p.queued_after_ns).collect();
    let commanded: Vec<u64> = parts.iter().filter_map(|p| p.commanded_after_ns).collect();
    (!queued.is_empty()).then(|| ConveyorLatency {
        exposure_to_queue: Latencies::of_ns(&queued),
        queue_to_command: Latencies::of_ns(&commanded),
    })
}

/// What a conveyor session's results are made of: `parts.csv`, the summary's sections (a
/// cell's too) and the parts as gather.mcap draws them.
pub type Results = (String, ConveyorSummary, Option<CellSummary>, Vec<Part>);

/// The results of the session whose dispatcher saw `d` and whose loop gathered `gather` (in
/// order), with the settings `s`. In a cell `parts.csv` has two more columns, [`CELL_COLUMNS`].
pub fn results(d: &Dispatched, gather: &Gather, s: &Settings) -> Results {
    let rows = gather.rows();
    let frame = BeltFrame::of(s);
    let mut csv = String::from(PARTS_HEADER);
    if d.cell.is_some() {
        csv = format!("{csv},{CELL_COLUMNS}");
    }
    csv.push('\n');
    let (mut grip, mut closing) = (Vec::new(), 0.0f64);
    let mut drawn = Vec::with_capacity(d.parts.len());
    for p in &d.parts {
        let at_grip = p.grip_cycle.and_then(|c| row(rows, c));
        let error = frame.as_ref().zip(at_grip).and_then(|(f, r)| error_mm(f, p, r));
        if p.state == "picked" {
            if let Some(e) = error {
                grip.push(e);
            }
            // Every row from the closing order until the gripper reads closed (2).
            if let (Some(f), Some(c)) = (&frame, p.grip_cycle) {
                let from = rows.partition_point(|r| r.cycle < c);
                for r in rows[from..].iter().take_while(|r| r.grip != 2) {
                    closing = closing.max(error_mm(f, p, r).unwrap_or(f64::INFINITY));
                }
            }
        }
        let cycle = |c: Option<u64>| c.map_or(-1, |c| c as i64);
        let _ = write!(
            csv,
            "{},{},{},{},{},{},{},{},{}",
            p.id,
            p.t_seen_s,
            p.latched_counts,
            p.belt_mm,
            p.across_mm,
            p.state,
            cycle(p.grip_cycle),
            cycle(p.place_cycle),
            error.map_or("nan".to_string(), |e| e.to_string()),
        );
        if d.cell.is_some() {
            let ms = p.claimed_after_ns.map_or(String::new(), |ns| format!("{}", ns as f64 * 1e-6));
            let _ = write!(csv, ",{ms},{}", p.by.as_deref().unwrap_or(""));
        }
        csv.push('\n');
        drawn.push(Part {
            id: p.id,
            belt_mm: p.belt_mm,
            across_mm: p.across_mm,
            latched_counts: p.latched_counts,
            state: p.state.to_string(),
            grip_cycle: p.grip_cycle,
            place_cycle: p.place_cycle,
            error_mm: error,
        });
    }
    let count = |state: &str| d.parts.iter().filter(|p| p.state == state).count();
    let span_s = match (rows.first(), rows.last()) {
        (Some(a), Some(b)) if b.time_s > a.time_s => b.time_s - a.time_s,
        _ => 0.0,
    };
    let picked = count("picked");
    let summary = ConveyorSummary {
        picked,
        missed: count("missed"),
        pending: count("pending"),
        picks_per_min: if span_s > 0.0 { 60.0 * picked as f64 / span_s } else { 0.0 },
        grip_error_mm: ErrorFigures::of(&grip),
        closing_error_max_mm: closing,
        detections: d.detections,
        latency_ms: latency(&d.parts),
    };
    let cell = d.cell.as_ref().map(|c| CellSummary {
        name: c.name.clone(),
        robot: c.robot.clone(),
        picked,
        passed: count("passed"),
        missed: count("missed"),
    });
    (csv, summary, cell, drawn)
}
