//! `qmarc-bench files`: what `gather.mcap` costs a move's ending (issue 45's goal: the files
//! of a move with `gather.mcap` on written in at most 1.5× the time with it off).
//!
//! One move is made in lock-step inside this process (a step held `--seconds`, gathering every
//! cycle), then its set of files is written `--rounds` times with `gather.mcap` off and on,
//! alternating, each into a fresh folder exactly as the controller writes it
//! (`write_results_with`: gather.csv, gather.m, [gather.mcap], summary.json, synced). The
//! figures: each kind's median time, the median of the rounds' on ÷ off ratios, the files'
//! sizes.

use crate::stats::median;
use qmarc_config::{Mode, Settings};
use qmarc_foxglove::recording::Recording;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// Options of `files`.
#[derive(Debug, Clone, clap::Args)]
pub struct FilesArgs {
    /// How long the step is held, s (2500 rows a second at the default period).
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Rounds, each writing the set with gather.mcap off and on.
    #[arg(long, default_value_t = 5)]
    pub rounds: u32,
    /// Settings file of the move.
    #[arg(long, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Also print the figures as one JSON line.
    #[arg(long)]
    pub json: bool,
}

/// Runs `files`.
pub fn run(a: &FilesArgs) -> anyhow::Result<()> {
    let mut s = Settings::load(&a.config, &qmarc_plugins::registry::names())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    s.step.duration_s = a.seconds;
    s.gather.every = 1;
    let spec = qmarc_tune::local::local_spec(s, Mode::Step);
    let done = qmarc_tune::local::run_local(&spec, &AtomicBool::new(false))?;
    let rows = done.record.gather.rows().len();
    println!("qmarc-bench files: a {} s step, {rows} rows, {} rounds", a.seconds, a.rounds);
    let root = std::env::temp_dir().join(format!("qmarc-bench-files-{}", std::process::id()));
    let (mut off, mut on, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    let mut sizes = (0, 0, 0);
    for round in 0..a.rounds {
        let mut pair = [0.0; 2];
        // Alternate which kind goes first, so neither always meets a warm cache first.
        let order = if round % 2 == 0 { [false, true] } else { [true, false] };
        for mcap in order {
            let mut settings = spec.settings.clone();
            settings.gather.mcap = mcap;
            let dir = root.join(format!("{round}-{mcap}"));
            std::fs::create_dir_all(&dir)?;
            let mut summary = done.summary.clone();
            let frozen = summary.clone();
            let recording = Recording::of(&settings, &done.record, &frozen, &[]);
            let t = Instant::now();
            recording.write_results(&dir, &mut summary, std::process::id(), &[])?;
            pair[usize::from(mcap)] = t.elapsed().as_secs_f64();
            let size = |f: &str| std::fs::metadata(dir.join(f)).map_or(0, |m| m.len());
            sizes = (size("gather.csv"), size("gather.m"), sizes.2.max(size("gather.mcap")));
            std::fs::remove_dir_all(&dir)?;
        }
        println!(
            "  round {round}: off {:.3} s, on {:.3} s, ratio {:.2}",
            pair[0],
            pair[1],
            pair[1] / pair[0]
        );
        off.push(pair[0]);
        on.push(pair[1]);
        ratios.push(pair[1] / pair[0]);
    }
    let _ = std::fs::remove_dir_all(&root);
    let (off_s, on_s, ratio) = (median(&off), median(&on), median(&ratios));
    println!(
        "  median: gather.mcap off {off_s:.3} s, on {on_s:.3} s; on ÷ off {ratio:.2} (goal ≤ 1.5)"
    );
    println!(
        "  sizes: gather.csv {} kB, gather.m {} kB, gather.mcap {} kB",
        sizes.0 / 1000,
        sizes.1 / 1000,
        sizes.2 / 1000
    );
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "rows": rows, "off_s": off_s, "on_s": on_s, "ratio": ratio,
                "csv_bytes": sizes.0, "m_bytes": sizes.1, "mcap_bytes": sizes.2,
            })
        );
    }
    Ok(())
}
