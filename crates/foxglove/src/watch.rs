//! What the live view's log says of a serving session beyond its telemetry: the session's
//! own status (`qmarc/command`'s answer to a status request, 10 times a second) — each order
//! accepted, done or not taken, each part picked or missed — and where the belt is.

use crate::channels::Channels;
use foxglove::messages::log::Level;
use qmarc_proto::service::IpcLocation;
use qmarc_session::client::CommandClient;
use qmarc_session::wire::{CommandKind, CommandRequest, CommandResponse, ConveyorStatus, Orders};
use std::time::{Duration, Instant};

/// How often the session's status is asked.
pub const EVERY: Duration = Duration::from_millis(100);

/// The session's status, asked now and then, and what its log has said of it.
pub struct Watch {
    location: IpcLocation,
    client: Option<CommandClient>,
    asked: Option<Instant>,
    said: Option<(Orders, ConveyorStatus)>,
}

impl Watch {
    /// The session at `location`, not asked yet.
    pub fn new(location: &IpcLocation) -> Watch {
        Watch { location: location.clone(), client: None, asked: None, said: None }
    }

    /// Asks the session for its status if [`EVERY`] has passed, and logs on `ch` at `ns`
    /// what changed since the last answer; the belt as this answer has it, if it came.
    pub fn poll(&mut self, ch: &Channels, ns: u64) -> Option<ConveyorStatus> {
        if self.asked.is_some_and(|t| t.elapsed() < EVERY) {
            return None;
        }
        self.asked = Some(Instant::now());
        if self.client.is_none() {
            self.client = CommandClient::connect(&self.location).ok();
        }
        let client = self.client.as_mut()?;
        match client.send(CommandRequest::of(CommandKind::Status)) {
            Ok(r) => {
                self.answer(ch, ns, &r);
                Some(r.conveyor)
            }
            // The session may be ending: ask again with a new client.
            Err(_) => {
                self.client = None;
                None
            }
        }
    }

    fn answer(&mut self, ch: &Channels, ns: u64, r: &CommandResponse) {
        let (o, c) = (r.orders, r.conveyor);
        if let Some((was, belt)) = self.said {
            for (line, level) in changes(&was, &belt, &o, &c) {
                ch.say(ns, level, &line);
            }
        }
        self.said = Some((o, c));
    }
}

/// The log's lines for a status that went from (`was`, `belt`) to (`o`, `c`).
pub fn changes(
    was: &Orders,
    belt: &ConveyorStatus,
    o: &Orders,
    c: &ConveyorStatus,
) -> Vec<(String, Level)> {
    let mut lines = Vec::new();
    if o.accepted > was.accepted {
        lines.push((format!("order {} accepted", o.accepted), Level::Info));
    }
    if o.not_taken > was.not_taken {
        let why = "its profile would leave the soft limits from where the robot was";
        lines.push((format!("order {} not taken: {why}", o.not_taken), Level::Warning));
    }
    if o.settled > was.settled {
        lines.push((format!("at rest: order {} done", o.settled), Level::Info));
    }
    if c.picked > belt.picked {
        lines.push((format!("part picked ({} so far)", c.picked), Level::Info));
    }
    if c.missed > belt.missed {
        lines.push((format!("part missed ({} so far)", c.missed), Level::Warning));
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_change_is_said_once_at_its_level() {
        let was = Orders::default();
        let belt = ConveyorStatus::default();
        assert!(changes(&was, &belt, &was, &belt).is_empty());
        let o = Orders { accepted: 2, settled: 1, not_taken: 2, ..was };
        let c = ConveyorStatus { picked: 3, missed: 1, ..belt };
        let said = changes(&was, &belt, &o, &c);
        let levels: Vec<i32> = said.iter().map(|(_, l)| *l as i32).collect();
        let lines: Vec<&str> = said.iter().map(|(s, _)| s.as_str()).collect();
        assert_eq!(
            lines,
            [
                "order 2 accepted",
                "order 2 not taken: its profile would leave the soft limits from where the robot was",
                "at rest: order 1 done",
                "part picked (3 so far)",
                "part missed (1 so far)"
            ]
        );
        assert_eq!(levels, [2, 3, 2, 2, 3]);
        assert!(changes(&o, &c, &o, &c).is_empty());
    }
}
