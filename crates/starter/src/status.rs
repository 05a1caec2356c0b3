//! [`StatusLine`]: homing shown as it happens on a terminal, from the progress page.

use qmarc_proto::progress::Progress;
use std::io::{IsTerminal, Write};

/// Homing shown as it happens on a terminal: one status line on standard error, rewritten
/// in place, cleared before anything else is printed.
pub(crate) struct StatusLine<'a> {
    progress: Option<&'a Progress>,
    shown: String,
    on_terminal: bool,
}

impl<'a> StatusLine<'a> {
    pub(crate) fn new(progress: Option<&'a Progress>) -> StatusLine<'a> {
        StatusLine { progress, shown: String::new(), on_terminal: std::io::stderr().is_terminal() }
    }

    pub(crate) fn update(&mut self) {
        let Some(p) = self.progress.filter(|_| self.on_terminal) else { return };
        let text = qmarc_plugins::homing::describe_progress(p.read().detail).unwrap_or_default();
        if text != self.shown {
            let _ = write!(std::io::stderr(), "\r\x1b[K{text}");
            self.shown = text;
        }
    }

    pub(crate) fn clear(&mut self) {
        if !self.shown.is_empty() {
            let _ = write!(std::io::stderr(), "\r\x1b[K");
            self.shown.clear();
        }
    }
}
