//! `qmarc-bench cell`: a cell of two robots on one belt (issue 47, docs/cell.md) as its user
//! measures it. In this process tree: a Zenoh router (`qmarc-cell router`), the cell's camera
//! (`qmarc-cell camera`) and two `qmarc-starter conveyor --cell` sessions, each its own
//! serving session and iceoryx2 prefix, every one a Zenoh client of the router. The figures
//! are read back from each robot's `parts.csv` (the camera's part ids, who picked each, when
//! each claim was seen) and `summary.json`:
//!
//! - the share: the cell's picks a minute, missed, picked twice, how the work splits;
//! - one robot killed (SIGKILL to its starter) mid-run: the survivor's rate from then on,
//!   what was missed and why;
//! - two hosts, the second robot in a network namespace of its own: the claim latency, a
//!   part's exposure to its claim seen by the other robot, and the claim's way there.

use anyhow::Context;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Options of `cell`.
#[derive(Debug, clap::Args)]
pub struct CellArgs {
    /// Settings file of the robots and the camera.
    #[arg(long, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Length of each run, s.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// The belt's speed, mm/s.
    #[arg(long, default_value_t = 500.0)]
    pub belt_mm_s: f64,
    /// Parts a minute the camera sees (300: more than one robot picks, 240 a minute and more
    /// for the cell).
    #[arg(long, default_value_t = 300.0)]
    pub parts_per_min: f64,
    /// When the upstream robot is killed, s after both move (0: no such run).
    #[arg(long, default_value_t = 30.0)]
    pub kill_at_s: f64,
    /// Where the downstream robot stands along the cell's belt, mm.
    #[arg(long, default_value_t = 600.0)]
    pub offset_mm: f64,
    /// Leave out the two-host run (it makes a network namespace: root only).
    #[arg(long)]
    pub one_host: bool,
    /// Directory holding qmarc-starter, qmarc-cell and their children (default: next to
    /// this program).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
}

/// One robot's parts.csv row, as far as the cell goes.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Row {
    t_seen_s: f64,
    state: String,
    /// From the exposure to the claim seen there, ms.
    claimed_ms: Option<f64>,
}

/// A robot's `parts.csv` (a cell's: `claimed_ms` and `by` its last columns): id → row.
pub(crate) fn rows(csv: &str) -> anyhow::Result<BTreeMap<u32, Row>> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col = |name: &str| {
        header.iter().position(|h| *h == name).with_context(|| format!("no column {name}"))
    };
    let (id, t, state, claimed) = (col("id")?, col("t_seen_s")?, col("state")?, col("claimed_ms")?);
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let field = |k: usize| f.get(k).copied().unwrap_or_default();
            Ok((
                field(id).parse().with_context(|| format!("parts.csv: `{l}`"))?,
                Row {
                    t_seen_s: field(t).parse().unwrap_or(f64::NAN),
                    state: field(state).to_string(),
                    claimed_ms: field(claimed).parse().ok(),
                },
            ))
        })
        .collect()
}

/// What a run of two robots (upstream `a`, downstream `b`) did, from their parts.csv.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Share {
    /// Parts both listed, ended on both (not pending).
    pub ended: usize,
    /// Picked by each, and by both.
    pub picked: [usize; 2],
    pub twice: usize,
    /// Ended parts neither picked.
    pub missed: usize,
    /// The span of the ended parts' exposures, s.
    pub span_s: f64,
    /// Each robot's picks: exposure → its claim made there, ms; → heard by the other, ms.
    pub made_ms: [Vec<f64>; 2],
    pub heard_ms: [Vec<f64>; 2],
}

impl Share {
    /// The cell's picks a minute over the ended parts' span.
    pub fn per_min(&self) -> f64 {
        let n = self.picked[0] + self.picked[1] - self.twice;
        if self.span_s > 0.0 { 60.0 * n as f64 / self.span_s } else { 0.0 }
    }
}

/// The share of the robots whose parts are `a` and `b` (the camera's ids on both).
pub(crate) fn share(a: &BTreeMap<u32, Row>, b: &BTreeMap<u32, Row>) -> Share {
    let mut s = Share::default();
    let (mut first, mut last) = (f64::INFINITY, f64::NEG_INFINITY);
    for (id, ra) in a.range(..) {
        let Some(rb) = b.get(id) else { continue };
        if ra.state == "pending" || rb.state == "pending" {
            continue;
        }
        s.ended += 1;
        (first, last) = (first.min(ra.t_seen_s), last.max(ra.t_seen_s));
        let by = [ra.state == "picked", rb.state == "picked"];
        for (k, _) in by.iter().enumerate().filter(|(_, picked)| **picked) {
            s.picked[k] += 1;
            let (mine, other) = if k == 0 { (ra, rb) } else { (rb, ra) };
            if let (Some(m), Some(h)) = (mine.claimed_ms, other.claimed_ms) {
                s.made_ms[k].push(m);
                s.heard_ms[k].push(h);
            }
        }
        s.twice += usize::from(by[0] && by[1]);
        s.missed += usize::from(!by[0] && !by[1]);
    }
    s.span_s = if last > first { last - first } else { 0.0 };
    s
}

/// p50 and p99 of `v` (nearest rank), `(0, 0)` when empty.
fn p50_p99(v: &[f64]) -> (f64, f64) {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        return (0.0, 0.0);
    }
    (crate::stats::nearest_rank(&s, 0.5), crate::stats::nearest_rank(&s, 0.99))
}

/// The router and the camera of one run, and where its files go; stopped (SIGTERM, then
/// SIGKILL) and removed on drop.
struct Rig {
    dir: PathBuf,
    name: String,
    bin: PathBuf,
    /// The Zenoh client files: on this host, on the second.
    here: PathBuf,
    there: PathBuf,
    host: Option<qmarc_program::net::Netns>,
    children: Vec<Child>,
}

impl Rig {
    fn start(a: &CellArgs, tag: &str, two_hosts: bool) -> anyhow::Result<Rig> {
        let bin = qmarc_program::process::bin_dir(a.bin_dir.as_deref())?;
        let pid = std::process::id();
        let host = match two_hosts {
            true => Some(qmarc_program::net::Netns::new().map_err(anyhow::Error::msg)?),
            false => None,
        };
        let dir = std::env::temp_dir().join(format!("qmarc-bench-cell-{tag}-{pid}"));
        std::fs::create_dir_all(&dir)?;
        let port = qmarc_program::net::free_loopback_port();
        let lo = format!("tcp/127.0.0.1:{port}");
        let lan = host.as_ref().map(|h| format!("tcp/{}:{port}", h.here));
        let client = |file: &str, to: &str| -> anyhow::Result<PathBuf> {
            let path = dir.join(file);
            std::fs::write(
                &path,
                format!("{{ mode: \"client\", connect: {{ endpoints: [\"{to}\"] }} }}"),
            )?;
            Ok(path)
        };
        let (here, there) =
            (client("here.json5", &lo)?, client("there.json5", lan.as_deref().unwrap_or(&lo))?);
        let name = format!("bench{tag}{pid}");
        let mut rig = Rig { dir, name, bin, here, there, host, children: Vec::new() };
        let mut router = Command::new(rig.bin.join("qmarc-cell"));
        router.args(["router", "--listen", &lo]);
        if let Some(lan) = &lan {
            router.args(["--listen", lan]);
        }
        rig.children.push(router.stderr(Stdio::null()).spawn().context("qmarc-cell router")?);
        let since = Instant::now();
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            anyhow::ensure!(
                since.elapsed() < Duration::from_secs(30),
                "the router does not listen"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        let camera = Command::new(rig.bin.join("qmarc-cell"))
            .args(["camera", "--cell", &rig.name])
            .arg(format!("--parts-per-min={}", a.parts_per_min))
            .arg(format!("--belt-mm-s={}", a.belt_mm_s))
            .arg(format!("--config={}", a.config.display()))
            .arg(format!("--zenoh-config={}", rig.here.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .context("qmarc-cell camera")?;
        rig.children.push(camera);
        Ok(rig)
    }

    /// Robot `robot` at `offset_mm` along the cell's belt (on the second host: `there`), a
    /// conveyor session of `a.seconds`, kept with the rig's children (stopped with it); its
    /// place among them.
    fn robot(
        &mut self,
        a: &CellArgs,
        robot: &str,
        offset_mm: f64,
        there: bool,
    ) -> anyhow::Result<usize> {
        let text = std::fs::read_to_string(&a.config)
            .with_context(|| format!("cannot read {}", a.config.display()))?;
        let mut doc: toml_edit::DocumentMut =
            text.parse().with_context(|| format!("{}", a.config.display()))?;
        doc["cell"]["robot"] = toml_edit::value(robot);
        doc["cell"]["belt_offset_mm"] = toml_edit::value(offset_mm);
        let state = self.dir.join(format!("{robot}.state"));
        doc["sim"]["state_file"] = toml_edit::value(state.display().to_string());
        let config = self.dir.join(format!("{robot}.toml"));
        std::fs::write(&config, doc.to_string())?;
        let out = self.dir.join(robot);
        let starter = self.bin.join("qmarc-starter");
        let (mut c, client) = match (there, &self.host) {
            (true, Some(h)) => (h.command(&starter), &self.there),
            _ => (Command::new(&starter), &self.here),
        };
        c.arg(format!("--config={}", config.display()))
            .arg(format!("--out={}", out.display()))
            .arg(format!("--iox-prefix={}", prefix(robot)))
            .args(["conveyor", &format!("--seconds={}", a.seconds)])
            .arg(format!("--belt-mm-s={}", a.belt_mm_s))
            .arg(format!("--cell={}", self.name))
            .arg(format!("--zenoh-config={}", client.display()))
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(self.dir.join(format!("{robot}.log")))?);
        self.children.push(c.spawn().context("qmarc-starter conveyor --cell")?);
        Ok(self.children.len() - 1)
    }

    /// Robot `robot` (the rig's child `k`) ended — with success unless it was `killed`: its
    /// parts.csv rows, or what it said (a session that failed makes no figures).
    fn ended(&mut self, k: usize, robot: &str, killed: bool) -> anyhow::Result<BTreeMap<u32, Row>> {
        let status = self.children[k].wait()?;
        let said =
            || std::fs::read_to_string(self.dir.join(format!("{robot}.log"))).unwrap_or_default();
        anyhow::ensure!(killed || status.success(), "robot {robot} ended ({status}): {}", said());
        match std::fs::read_to_string(self.dir.join(robot).join("parts.csv")) {
            Ok(csv) => rows(&csv),
            Err(_) => {
                anyhow::bail!("robot {robot} ended ({status}) without its results: {}", said())
            }
        }
    }

    /// Waits until robot `robot` (the rig's child `k`) moves (the progress page of its
    /// prefix says so); an error if it ended first.
    fn wait_moving(&mut self, k: usize, robot: &str) -> anyhow::Result<()> {
        let since = Instant::now();
        loop {
            let moving = qmarc_proto::progress::Progress::snapshot(&prefix(robot))
                .is_some_and(|s| s.phase >= qmarc_proto::state::Phase::Homing.wire());
            if moving {
                return Ok(());
            }
            if let Ok(Some(status)) = self.children[k].try_wait() {
                let said = std::fs::read_to_string(self.dir.join(format!("{robot}.log")));
                anyhow::bail!(
                    "robot {robot} ended ({status}) before it moved: {}",
                    said.unwrap_or_default()
                );
            }
            anyhow::ensure!(
                since.elapsed() < Duration::from_secs(90),
                "{robot} not moving after 90 s"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Rig {
    fn drop(&mut self) {
        for c in self.children.iter_mut().rev() {
            // As its user stops it (the camera ends its server, removing its files).
            qmarc_program::process::terminate(c, Duration::from_secs(10));
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The iceoryx2 prefix of robot `robot`'s session.
fn prefix(robot: &str) -> String {
    format!("qmarc_benchcell_{}_{robot}_", std::process::id())
}

/// Prints the share `s` of robots `names`.
fn say(label: &str, names: [&str; 2], s: &Share) {
    let total = (s.picked[0] + s.picked[1]).max(1) as f64;
    println!(
        "  {label}: {:.1} picks/min together over {:.1} s of parts; {} parts ended on both: {} \
         picked by {}, {} by {} ({:.0} % / {:.0} %), {} picked twice, {} missed",
        s.per_min(),
        s.span_s,
        s.ended,
        s.picked[0],
        names[0],
        s.picked[1],
        names[1],
        100.0 * s.picked[0] as f64 / total,
        100.0 * s.picked[1] as f64 / total,
        s.twice,
        s.missed
    );
}

/// Prints the claim latency of the share `s`.
fn say_latency(names: [&str; 2], s: &Share) {
    for k in 0..2 {
        let (heard, made) = (&s.heard_ms[k], &s.made_ms[k]);
        let way: Vec<f64> = heard.iter().zip(made).map(|(h, m)| h - m).collect();
        let ((h50, h99), (w50, w99)) = (p50_p99(heard), p50_p99(&way));
        println!(
            "    {}'s claims seen by {} ({} claims): from the part's exposure p50 {h50:.1} ms, p99 \
             {h99:.1} ms; from the claim made p50 {w50:.2} ms, p99 {w99:.2} ms",
            names[k],
            names[1 - k],
            heard.len()
        );
    }
}

/// Runs two robots (the downstream one on the second host: `two_hosts`), killing the
/// upstream one (SIGKILL to its starter) `kill_at_s` after both move when `kill`; their
/// parts.csv rows. Whatever fails, the rig stops every process it started.
fn two_robots(
    a: &CellArgs,
    tag: &str,
    two_hosts: bool,
    kill: bool,
) -> anyhow::Result<[BTreeMap<u32, Row>; 2]> {
    let mut rig = Rig::start(a, tag, two_hosts)?;
    let west = rig.robot(a, "west", 0.0, false)?;
    let east = rig.robot(a, "east", a.offset_mm, two_hosts)?;
    if kill {
        rig.wait_moving(west, "west")?;
        rig.wait_moving(east, "east")?;
        std::thread::sleep(Duration::from_secs_f64(a.kill_at_s));
        qmarc_program::process::send(&rig.children[west], nix::sys::signal::Signal::SIGKILL);
    }
    // East first: a killed west's controller writes its files after its starter's death.
    let e = rig.ended(east, "east", false);
    let w = rig.ended(west, "west", kill);
    // What happened to the cell as each robot saw it (a robot cut off, one gone, a companion
    // ended): the figures are read with it.
    for robot in ["west", "east"] {
        let log = std::fs::read_to_string(rig.dir.join(format!("{robot}.log")));
        for line in log.unwrap_or_default().lines().filter(|l| cell_event(l)) {
            println!("    {robot}'s log: {line}");
        }
    }
    if kill {
        // A killed starter's children end on its death; its run's files are left behind.
        std::thread::sleep(Duration::from_secs(2));
        qmarc_proto::service::IpcLocation::new(&prefix("west"), qmarc_proto::service::DEFAULT_ROOT)
            .remove_files();
    }
    Ok([w?, e?])
}

/// Whether a robot's log line `l` says something happened to its cell: it was cut off, saw
/// another robot go, or its companion or session ended otherwise than done.
fn cell_event(l: &str) -> bool {
    ["cut off", "is gone", "error", "exited", "killed"].iter().any(|w| l.contains(w))
}

/// `qmarc-bench cell`.
pub fn run(a: &CellArgs) -> anyhow::Result<()> {
    let names = ["west", "east"];
    println!(
        "qmarc-bench cell: {}, two robots {} mm apart, the belt at {} mm/s, {} parts/min, {} s a \
         run; every process a Zenoh client of one router",
        a.config.display(),
        a.offset_mm,
        a.belt_mm_s,
        a.parts_per_min,
        a.seconds
    );
    anyhow::ensure!(
        a.one_host || nix::unistd::geteuid().is_root(),
        "the two-host run makes a network namespace: run as root, or with --one-host"
    );
    let [w, e] = two_robots(a, "share", false, false)?;
    let s = share(&w, &e);
    say("both on this host (loopback)", names, &s);
    say_latency(names, &s);
    if a.kill_at_s > 0.0 {
        let [w, e] = two_robots(a, "kill", false, true)?;
        // West's parts.csv ends where it died: its last part (the camera's ids are the
        // same on both robots).
        let died = w.keys().max().copied().unwrap_or(0);
        let before = share(&w, &e);
        // What west held or had queued as it died (pending in its parts.csv): east's fate.
        let held: Vec<&str> = w
            .iter()
            .filter(|(_, r)| r.state == "pending")
            .filter_map(|(id, _)| e.get(id).map(|r| r.state.as_str()))
            .collect();
        let took = held.iter().filter(|s| **s == "picked").count();
        let alone: Vec<&Row> =
            e.range(died + 1..).map(|(_, r)| r).filter(|r| r.state != "pending").collect();
        let picked = alone.iter().filter(|r| r.state == "picked").count();
        let missed = alone.iter().filter(|r| r.state == "missed").count();
        let span = match (alone.first(), alone.last()) {
            (Some(a), Some(b)) => b.t_seen_s - a.t_seen_s,
            _ => 0.0,
        };
        println!(
            "  west killed {} s after both moved: until then {} picked by west, {} by east, {} \
             twice, {} missed; of the {} parts west held or had queued as it died, east picked \
             {took}; after them (parts seen over {span:.1} s), east alone {picked} picked ({:.1} \
             picks/min), {missed} missed (one robot's pace: those it could not reach in its \
             window)",
            a.kill_at_s,
            before.picked[0],
            before.picked[1],
            before.twice,
            before.missed,
            held.len(),
            if span > 0.0 { 60.0 * picked as f64 / span } else { 0.0 }
        );
    }
    if !a.one_host {
        let [w, e] = two_robots(a, "hosts", true, false)?;
        let s = share(&w, &e);
        say("east on a second host (a network namespace, through the router)", names, &s);
        say_latency(names, &s);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const WEST: &str = "id,t_seen_s,latched_counts,belt_mm,across_mm,state,grip_cycle,place_cycle,error_mm,claimed_ms,by
1,1.0,0,0,0,passed,-1,-1,nan,310.5,east
2,1.25,0,0,0,picked,10,20,0.1,200,west
3,1.5,0,0,0,missed,-1,-1,nan,,
4,1.75,0,0,0,picked,30,40,0.2,220,west
5,2.0,0,0,0,pending,-1,-1,nan,,
";
    const EAST: &str = "id,t_seen_s,latched_counts,belt_mm,across_mm,state,grip_cycle,place_cycle,error_mm,claimed_ms,by
1,1.0,0,0,0,picked,10,20,0.1,310,east
2,1.25,0,0,0,passed,-1,-1,nan,202,west
3,1.5,0,0,0,missed,-1,-1,nan,,
4,1.75,0,0,0,picked,30,40,0.2,,west
";

    #[test]
    fn the_share_counts_each_part_once_and_the_claims_heard() {
        let (w, e) = (rows(WEST).unwrap(), rows(EAST).unwrap());
        let s = share(&w, &e);
        assert_eq!((s.ended, s.picked, s.twice, s.missed), (4, [2, 2], 1, 1));
        assert!((s.span_s - 0.75).abs() < 1e-12);
        // Three different parts picked over 0.75 s.
        assert!((s.per_min() - 240.0).abs() < 1e-9, "{}", s.per_min());
        // West's part 2 made at 200 ms, heard by east at 202; its part 4 not heard.
        assert_eq!((s.made_ms[0].clone(), s.heard_ms[0].clone()), (vec![200.0], vec![202.0]));
        assert_eq!((s.made_ms[1].clone(), s.heard_ms[1].clone()), (vec![310.0], vec![310.5]));
        assert_eq!(p50_p99(&[3.0, 1.0, 2.0]), (2.0, 3.0));
        assert!(rows("id,state\n1,picked\n").is_err(), "no claimed_ms: not a cell's");
    }
}
