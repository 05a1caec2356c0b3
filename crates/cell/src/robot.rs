//! `qmarc-cell robot --settings RUN`: a robot's companion, started by `qmarc-starter conveyor
//! --cell NAME` before its hardware server. It joins the cell — refused, saying why, when a
//! robot of its name is alive there, no camera answers, or the robot's belt is not the cell's
//! — and says on standard output when the cell's world began ([`JOINED`]), which the starter
//! gives the run. Then it relays, every millisecond, between the cell and its session's
//! dispatcher (iceoryx2 [`CELL_IN`] and [`CELL_OUT`]): the camera's parts, the robots alive
//! and gone, their claims; this robot's claims, picks, give-ups and the parts it lets pass.
//! It holds the robot's liveliness token and answers for its open claims, and for its window
//! once its session's dispatcher runs (the others count it in the turns from then).

use crate::Refused;
use crate::keys::{key, robot_key, robot_of};
use crate::session::{self, failed, json};
use crate::wire::{CellBelt, WireClaim, WireMember, WirePart, disagreement};
use qmarc_config::RunSpec;
use qmarc_proto::cell::{CELL_IN, CELL_OUT, CellKind, CellMsg, JOINED, open_cell_service};
use qmarc_proto::service::{IpcLocation, create_node};
use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::sample::SampleKind;

/// How long a robot waits for the cell's camera to answer.
pub const JOIN_WAIT: Duration = Duration::from_secs(30);
/// How often the members are said again to the dispatcher (one that started late, or lost
/// one).
const RESAY: Duration = Duration::from_millis(500);
/// How long after a robot's token went it is said gone: the camera's token, which goes with
/// it when this robot is the one cut off, has had time to go too.
const GONE_GRACE: Duration = Duration::from_millis(300);
/// How much longer, after an outage, a robot that vanished with the camera has to come back
/// before it is said gone.
const GONE_AFTER_OUTAGE: Duration = Duration::from_secs(5);
/// How long after the cell's camera came back a robot takes parts handed on to it again:
/// the others' tokens are back, and their claims and picks asked and had.
const RESYNC: Duration = Duration::from_secs(1);
/// A robot's answer for its window while its session's dispatcher does not run yet.
const NOT_READY: &str = "not ready";
/// How long a query of another robot may take.
const ASK: Duration = Duration::from_millis(500);

/// A question to the cell whose answers are awaited.
enum Ask {
    /// A robot's window.
    Member(String),
    /// A robot's open claims.
    Ledger,
    /// The camera's recent parts.
    Recent,
}

/// The companion of the run `spec`: joins, then relays until a stop signal.
pub fn run(spec: &RunSpec) -> anyhow::Result<()> {
    let s = &spec.settings;
    let cell =
        s.cell.name.clone().ok_or_else(|| anyhow::anyhow!("the run joins no cell (--cell)"))?;
    let me = s.cell.robot.clone();
    qmarc_timer::stop::install()?;
    let refused = |why: String| Refused { cell: cell.clone(), why };
    let zenoh = session::open(s.cell.zenoh_config.as_deref())?;
    let token_key = robot_key(&cell, "robot", &me);
    if let Some(t) = session::alive(&zenoh, &token_key, Duration::from_secs(2))?.first() {
        return Err(refused(format!(
            "a robot named {me} is alive in it already (its token {t}; one that died keeps it \
             for its session's lease): give [cell] robot another name"
        ))
        .into());
    }
    let since = Instant::now();
    let belt = loop {
        if let Some(b) = session::query::<CellBelt>(&zenoh, &key(&cell, "belt"), ASK)?.pop() {
            break b;
        }
        if qmarc_timer::stop::requested() {
            anyhow::bail!("stopped while waiting for cell {cell}'s camera");
        }
        if since.elapsed() > JOIN_WAIT {
            return Err(refused(format!(
                "no camera answered in {} s: is `qmarc-cell camera --cell {cell}` running, and \
                 its router reachable ({})?",
                JOIN_WAIT.as_secs(),
                s.cell.zenoh_config.as_ref().map_or(
                    "rmw_zenoh's default: a router at \
                     tcp/localhost:7447"
                        .to_string(),
                    |p| p.display().to_string()
                )
            ))
            .into());
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    if let Some(why) = disagreement(s, &belt) {
        return Err(refused(why).into());
    }
    let epoch = (belt.epoch_ns as i64 - qmarc_timer::clock::realtime_offset_ns()).max(0);
    // Its ports first: the session, told it joined, finds them there.
    let relay = Relay::open(&zenoh, spec, &cell, &me)?;
    let mut out = std::io::stdout();
    writeln!(out, "{JOINED}{epoch}")?;
    out.flush()?;
    relay.run()
}

/// The companion's ports, Zenoh's and iceoryx2's, and what it keeps.
struct Relay<'a> {
    zenoh: &'a zenoh::Session,
    cell: String,
    me: WireMember,
    _token: zenoh::liveliness::LivelinessToken,
    claims_out: zenoh::pubsub::Publisher<'a>,
    parts: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    claims: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    robots: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    camera: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    member_q: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
    ledger_q: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
    _node: iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
    to_session: iceoryx2::port::publisher::Publisher<iceoryx2::prelude::ipc::Service, CellMsg, ()>,
    from_session:
        iceoryx2::port::subscriber::Subscriber<iceoryx2::prelude::ipc::Service, CellMsg, ()>,
    /// The other robots alive.
    members: BTreeMap<String, WireMember>,
    /// This robot's claims not yet picked or given up (answered with its picks, `done`).
    open: BTreeMap<u32, WireClaim>,
    /// Robots alive whose window has not been had yet (asked again every [`RESAY`]).
    unanswered: Vec<String>,
    /// Robots alive whose session does not take parts yet (asked again every [`RESAY`], not
    /// counted in the turns until then, nor waited for).
    unready: BTreeSet<String>,
    /// The other robots whose token is up.
    up: BTreeSet<String>,
    /// Robots whose token went, not yet said gone: when (system clock), and since when here.
    vanished: Vec<(String, u64, Instant)>,
    /// Questions out: what, the answers' channel, whether one came.
    asked: Vec<(Ask, zenoh::handlers::FifoChannelHandler<zenoh::query::Reply>, bool)>,
    camera_lost: bool,
    /// Said to be in the cell (and not cut off since).
    in_cell: bool,
    /// Its session's dispatcher runs (it said so): the others are told its window, and so
    /// count it in the turns, only from then — a robot counted in must say what it lets pass.
    ready: bool,
    /// Since when the camera is back after being lost, until the others' claims are had.
    rejoining: Option<Instant>,
    /// This robot's picks and the parts it let pass, of the last minute, for a robot that
    /// asks after an outage or as it joins.
    done: BTreeMap<u32, WireClaim>,
}

impl<'a> Relay<'a> {
    fn open(
        zenoh: &'a zenoh::Session,
        spec: &RunSpec,
        cell: &str,
        me: &str,
    ) -> anyhow::Result<Relay<'a>> {
        let fifo = || zenoh::handlers::FifoChannel::new(4096);
        let sub = |k: String| {
            zenoh
                .declare_subscriber(k.clone())
                .with(fifo())
                .wait()
                .map_err(failed(format!("subscribing to {k}")))
        };
        let live = |k: String| {
            zenoh
                .liveliness()
                .declare_subscriber(k.clone())
                .history(true)
                .with(fifo())
                .wait()
                .map_err(failed(format!("watching {k}")))
        };
        let queryable = |k: String| {
            zenoh
                .declare_queryable(k.clone())
                .complete(true)
                .with(zenoh::handlers::FifoChannel::new(64))
                .wait()
                .map_err(failed(format!("answering {k}")))
        };
        let location = IpcLocation::new(&spec.iox_prefix, &spec.iox_root);
        let node = create_node::<iceoryx2::prelude::ipc::Service>("qmarc-cell-robot", &location)?;
        let to_session = open_cell_service(&node, CELL_IN)?
            .publisher_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("the publisher of {CELL_IN}: {e:?}"))?;
        let from_session = open_cell_service(&node, CELL_OUT)?
            .subscriber_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("the subscriber of {CELL_OUT}: {e:?}"))?;
        // What the others ask once they see this robot's token answers before it exists.
        let (member_q, ledger_q) =
            (queryable(robot_key(cell, "member", me))?, queryable(robot_key(cell, "ledger", me))?);
        Ok(Relay {
            zenoh,
            cell: cell.to_string(),
            me: WireMember::of(&spec.settings),
            member_q,
            ledger_q,
            _token: zenoh
                .liveliness()
                .declare_token(robot_key(cell, "robot", me))
                .wait()
                .map_err(failed("the robot's token"))?,
            claims_out: zenoh
                .declare_publisher(robot_key(cell, "claims", me))
                .wait()
                .map_err(failed("the claims' publisher"))?,
            parts: sub(key(cell, "parts"))?,
            claims: sub(key(cell, "claims/*"))?,
            robots: live(key(cell, "robot/*"))?,
            camera: live(key(cell, "camera"))?,
            _node: node,
            to_session,
            from_session,
            members: BTreeMap::new(),
            open: BTreeMap::new(),
            unanswered: Vec::new(),
            unready: BTreeSet::new(),
            up: BTreeSet::new(),
            vanished: Vec::new(),
            asked: Vec::new(),
            camera_lost: false,
            in_cell: false,
            ready: false,
            rejoining: None,
            done: BTreeMap::new(),
        })
    }

    /// Says `what` on standard error (the run's log), naming the cell and this robot.
    fn say(&self, what: &str) {
        eprintln!("qmarc-cell robot {} in cell {}: {what}", self.me.robot, self.cell);
    }

    /// Tells the dispatcher `m` (dropped if it cannot be sent: the session is gone).
    fn tell(&self, m: CellMsg) {
        let _ = self.to_session.send_copy(m);
    }

    /// Relays until a stop signal.
    fn run(mut self) -> anyhow::Result<()> {
        let mut said = Instant::now();
        while !qmarc_timer::stop::requested() {
            self.relay_cell();
            self.say_gone();
            if self.rejoining.is_some_and(|since| since.elapsed() >= RESYNC) {
                self.rejoining = None;
            }
            self.answers();
            self.relay_session()?;
            self.answer();
            if said.elapsed() >= RESAY {
                said = Instant::now();
                for m in self.members.values() {
                    self.tell(m.msg());
                }
                for robot in std::mem::take(&mut self.unanswered) {
                    self.joined(&robot);
                }
                // In the cell: the camera seen, every robot's window and claims had.
                let settled = !self.camera_lost && self.rejoining.is_none();
                if settled && self.asked.is_empty() && self.unanswered.is_empty() {
                    if !self.in_cell {
                        self.in_cell = true;
                        self.say("in the cell: the others' windows and claims had");
                    }
                    self.tell(CellMsg::new(CellKind::Rejoined, 0, &self.me.robot, 0));
                }
                for robot in std::mem::take(&mut self.unready) {
                    let key = robot_key(&self.cell, "member", &robot);
                    self.ask(Ask::Member(robot), key);
                }
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(())
    }

    /// The cell's news, to the dispatcher.
    fn relay_cell(&mut self) {
        while let Ok(Some(s)) = self.parts.try_recv() {
            if let Ok(p) = serde_json::from_slice::<WirePart>(&s.payload().to_bytes()) {
                self.tell(p.msg());
            }
        }
        while let Ok(Some(s)) = self.claims.try_recv() {
            let c = serde_json::from_slice::<WireClaim>(&s.payload().to_bytes()).ok();
            if let Some(m) = c.filter(|c| c.robot != self.me.robot).and_then(|c| c.msg()) {
                self.tell(m);
            }
        }
        while let Ok(Some(s)) = self.robots.try_recv() {
            let Some(robot) = robot_of(s.key_expr().as_str(), "robot").map(str::to_string) else {
                continue;
            };
            if robot == self.me.robot {
                continue;
            }
            match s.kind() {
                SampleKind::Put => {
                    self.up.insert(robot.clone());
                    self.vanished.retain(|(r, _, _)| *r != robot);
                    self.joined(&robot);
                }
                SampleKind::Delete => {
                    self.members.remove(&robot);
                    self.unanswered.retain(|r| *r != robot);
                    self.unready.remove(&robot);
                    self.up.remove(&robot);
                    let now = qmarc_timer::clock::realtime_now_ns();
                    self.vanished.push((robot, now, Instant::now()));
                }
            }
        }
        while let Ok(Some(s)) = self.camera.try_recv() {
            match s.kind() {
                SampleKind::Delete => {
                    self.camera_lost = true;
                    self.in_cell = false;
                    self.rejoining = None;
                    self.say("cut off (the camera's token went): claims nothing new");
                    self.tell(CellMsg::new(CellKind::CutOff, 0, &self.me.robot, 0));
                }
                // Back (a router restarted): the parts seen meanwhile.
                SampleKind::Put if self.camera_lost => {
                    self.camera_lost = false;
                    self.say("the camera is back: asking the others' claims again");
                    self.rejoining = Some(Instant::now());
                    // Those that vanished with it and do not come back with it are gone from now:
                    // none of their claims made before is released (they may have gripped).
                    let now = qmarc_timer::clock::realtime_now_ns();
                    // And they have longer to come back: each reconnects to the router in its
                    // own time.
                    let later = Instant::now() + GONE_AFTER_OUTAGE;
                    for (_, t, since) in &mut self.vanished {
                        (*t, *since) = (now, later);
                    }
                    let recent = key(&self.cell, "recent");
                    self.ask(Ask::Recent, recent);
                }
                SampleKind::Put => {}
            }
        }
    }

    /// Says gone the robots whose token went [`GONE_GRACE`] ago, while the cell's camera is
    /// alive. A robot that sees the camera go too is cut off from the cell (its router is
    /// down, or its host's link), not the others: it goes on with what it claimed, and says
    /// nobody gone until the camera is back.
    fn say_gone(&mut self) {
        if self.camera_lost {
            return;
        }
        let (due, wait): (Vec<_>, Vec<_>) =
            self.vanished.drain(..).partition(|(_, _, since)| since.elapsed() >= GONE_GRACE);
        self.vanished = wait;
        for (robot, t, _) in due {
            self.say(&format!("robot {robot} is gone (its token went)"));
            self.tell(CellMsg::new(CellKind::Gone, 0, &robot, t));
        }
    }

    /// Robot `robot` is alive: asks its window and the claims it holds (the answers are
    /// taken as they come, [`Relay::answers`]).
    fn joined(&mut self, robot: &str) {
        self.ask(Ask::Member(robot.to_string()), robot_key(&self.cell, "member", robot));
        self.ask(Ask::Ledger, robot_key(&self.cell, "ledger", robot));
    }

    /// Sends the question `key`, its answers to come.
    fn ask(&mut self, what: Ask, key: String) {
        match self.zenoh.get(&key).timeout(ASK).wait() {
            Ok(replies) => self.asked.push((what, replies, false)),
            Err(_) => {
                if let Ask::Member(robot) = what {
                    self.unanswered.push(robot);
                }
            }
        }
    }

    /// The answers that have come: a robot's window, its claims, the camera's recent parts.
    /// A robot that did not answer is asked again later.
    fn answers(&mut self) {
        let mut asked = std::mem::take(&mut self.asked);
        asked.retain_mut(|(what, replies, answered)| {
            loop {
                match replies.try_recv() {
                    Ok(Some(reply)) => match reply.result() {
                        Ok(sample) => {
                            let bytes = sample.payload().to_bytes();
                            *answered |= self.answer_of(what, &bytes);
                        }
                        // Its session does not take parts yet: asked again, not waited for.
                        Err(_) => {
                            if let Ask::Member(robot) = &*what {
                                self.unready.insert(robot.clone());
                                *answered = true;
                            }
                        }
                    },
                    Ok(None) => return true,
                    // Every answer is in (or the time is up).
                    Err(_) => {
                        if let (Ask::Member(robot), false) = (&*what, *answered) {
                            self.unanswered.push(robot.clone());
                        }
                        return false;
                    }
                }
            }
        });
        asked.append(&mut self.asked);
        self.asked = asked;
    }

    /// Takes in the answer `bytes` to `what`: true if it was one.
    fn answer_of(&mut self, what: &Ask, bytes: &[u8]) -> bool {
        match what {
            Ask::Member(robot) => match serde_json::from_slice::<WireMember>(bytes) {
                Ok(m) if !self.gone(robot) => {
                    self.tell(m.msg());
                    self.members.insert(robot.clone(), m);
                    true
                }
                _ => false,
            },
            Ask::Ledger => serde_json::from_slice::<Vec<WireClaim>>(bytes).is_ok_and(|list| {
                list.iter().filter_map(WireClaim::msg).for_each(|m| self.tell(m));
                true
            }),
            Ask::Recent => serde_json::from_slice::<Vec<WirePart>>(bytes).is_ok_and(|list| {
                list.iter().for_each(|p| self.tell(p.msg()));
                true
            }),
        }
    }

    /// Whether robot `robot` has gone since it was asked (its window is not taken then).
    fn gone(&self, robot: &str) -> bool {
        !self.up.contains(robot)
    }

    /// The dispatcher's claims, picks, give-ups and passes, to the cell (its first word,
    /// its window, says it takes parts: the others are told its window from then).
    fn relay_session(&mut self) -> anyhow::Result<()> {
        while let Ok(Some(sample)) = self.from_session.receive() {
            if sample.payload().kind() == Some(CellKind::Member) && !self.ready {
                // Its dispatcher runs: this robot takes its turns from now, and lets pass
                // at once the parts in flight it cannot place.
                self.ready = true;
                self.say("its session takes parts: the others count it in");
                self.ask(Ask::Recent, key(&self.cell, "recent"));
            }
            let Some(c) = WireClaim::of(sample.payload()) else { continue };
            match c.kind.as_str() {
                "claim" => {
                    self.open.insert(c.part, c.clone());
                }
                // Picked, given up (let pass with it) or let pass.
                _ => {
                    self.open.remove(&c.part);
                    self.done.insert(c.part, c.clone());
                }
            }
            self.claims_out.put(json(&c)).wait().map_err(failed("publishing a claim"))?;
        }
        // Claims whose grip is long past are done with, picked or not.
        let old = qmarc_timer::clock::realtime_now_ns().saturating_sub(60_000_000_000);
        self.open.retain(|_, c| c.grip_by_ns > old);
        self.done.retain(|_, c| c.t_ns > old);
        Ok(())
    }

    /// The others' questions: this robot's window (not ready until its dispatcher spoke),
    /// its open claims and its picks and passes of the last minute.
    fn answer(&self) {
        // Until its dispatcher runs it says it is not ready: the others ask again, and do
        // not count it in meanwhile.
        while let Ok(Some(q)) = self.member_q.try_recv() {
            let _ = match self.ready {
                true => q.reply(q.key_expr().clone(), json(&self.me)).wait(),
                false => q.reply_err(NOT_READY).wait(),
            };
        }
        while let Ok(Some(q)) = self.ledger_q.try_recv() {
            let list: Vec<&WireClaim> = self.open.values().chain(self.done.values()).collect();
            let _ = q.reply(q.key_expr().clone(), json(&list)).wait();
        }
    }
}
