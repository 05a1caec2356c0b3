//! The message line's hints: the keys of the page shown, or the focused field's error.

use super::{App, Page};
use crate::form::Kind;

impl App {
    /// What the message line says when no message is due: the keys of the page shown (on
    /// the setup page, the focused field's error or keys). A hint never outlives its page.
    pub(super) fn hint(&mut self) {
        let keys = match self.page {
            Page::Setup => return self.field_hint(),
            Page::Log => {
                "↑↓ PgUp PgDn scroll · Home: first line · End: follow the output · ^←/^→ jog, \
                 ^↑/^↓ motor or axis"
            }
            Page::Charts => "←/→ or 1–4: the motor charted",
            Page::Results | Page::History => {
                "↑↓ PgUp PgDn Home End scroll · F7 charts · F8 history · ^←/^→ jog, ^↑/^↓ motor \
                 or axis"
            }
        };
        self.status = (keys.to_string(), false);
    }

    /// The focused field's error or the keys, on the message line.
    fn field_hint(&mut self) {
        match self.form.fields.get(self.focus).and_then(|f| f.error.clone()) {
            Some(e) => self.status = (e, true),
            None => match &self.form.file_error {
                Some(e) => self.status = (e.clone(), true),
                None => {
                    let Some(f) = self.form.fields.get(self.focus) else { return };
                    let keys = match (f.kind, f.place.motor()) {
                        (Kind::Choice, _) => "←→ or space chooses · Tab/↑↓ next field".to_string(),
                        (_, Some(_)) => {
                            "type a value, Esc undoes · Tab/↑↓ next field · ←→ motor".to_string()
                        }
                        (_, None) => "type a value, Esc undoes · Tab/↑↓ next field".to_string(),
                    };
                    // A gain cell may be too narrow for its value: the message line has it whole.
                    let name = match f.place.motor() {
                        Some(_) => format!("{} = {}", f.name(), f.text),
                        None => f.name(),
                    };
                    self.status = (format!("{name}: {keys}"), false)
                }
            },
        }
    }
}
