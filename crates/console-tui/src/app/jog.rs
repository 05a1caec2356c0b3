//! The console's jog keys: Ctrl-↑/↓ choose the motor, Ctrl-←/→ jog it by `[jog] counts`
//! through the starter's `jog` (README, "Running moves").

use super::{App, Page};
use crate::starter_process::Mode;

impl App {
    /// Whether the page shown takes the jog keys: the log, the results and the history.
    pub(super) fn jog_page(&self) -> bool {
        matches!(self.page, Page::Log | Page::Results | Page::History)
    }

    /// The jog keys' motor count and distance, from the settings as they are (none while they
    /// do not validate).
    fn jog_settings(&self) -> Option<(usize, i64)> {
        self.form.checked.as_ref().map(|s| (s.n_motors, s.jog.counts))
    }

    /// Ctrl-↑/↓: the motor the jog keys move.
    pub(super) fn jog_motor_by(&mut self, step: isize) {
        let Some((n, counts)) = self.jog_settings() else {
            return self.say("jog: the settings do not validate", true);
        };
        self.jog_motor = (self.jog_motor as isize + step).clamp(1, n as isize) as usize;
        let m = self.jog_motor;
        self.say(format!("jog: motor {m} (Ctrl-← / Ctrl-→ move it ∓{counts} counts)"), false);
    }

    /// Ctrl-←/→: jogs the selected motor by `[jog] counts` one way (`sign`) or the other.
    pub(super) fn jog(&mut self, sign: i64) {
        let Some((n, counts)) = self.jog_settings() else {
            return self.say("jog: the settings do not validate", true);
        };
        self.start(Mode::Jog { motor: self.jog_motor.min(n), counts: sign * counts });
    }
}
