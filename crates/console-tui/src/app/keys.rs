//! What each key does: the pages' keys, the setup form's editing (focus, typing, choices)
//! and the log's and charts' scrolling — `App::on_key` and what it calls.

use super::{App, Page, Quit};
use crate::form::Kind;
use crate::starter_process::Mode;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};

impl App {
    fn move_focus(&mut self, forward: bool) {
        self.commit_edit();
        let n = self.form.fields.len();
        let mut i = self.focus;
        for _ in 0..n {
            i = if forward { (i + 1) % n } else { (i + n - 1) % n };
            if self.form.enabled(i) {
                break;
            }
        }
        self.focus = i;
        self.hint();
    }

    /// Left/right in the gains table: the same row of the neighbouring motor.
    fn move_column(&mut self, right: bool) {
        self.commit_edit();
        let f = &self.form.fields[self.focus];
        let Some(m) = f.place.motor() else { return };
        let target = if right { m + 1 } else { m.wrapping_sub(1) };
        let want = match f.place {
            crate::form::Place::Motor(_, k) => crate::form::Place::Motor(target, k),
            crate::form::Place::Notch(_, k) => crate::form::Place::Notch(target, k),
            other => other,
        };
        if let Some(i) = self.form.index(want).filter(|&i| self.form.enabled(i)) {
            self.focus = i;
        }
        self.hint();
    }

    pub(crate) fn commit_edit(&mut self) {
        if self.editing.take().is_some() {
            self.form.validate();
        }
    }

    fn type_char(&mut self, c: char) {
        let i = self.focus;
        if !self.form.enabled(i) {
            return;
        }
        let field = &self.form.fields[i];
        if field.kind == Kind::Choice {
            return;
        }
        // The first key replaces the value, as in a spreadsheet; later keys append.
        let mut text = if self.editing.is_none() {
            self.editing = Some(field.text.clone());
            String::new()
        } else {
            field.text.clone()
        };
        text.push(c);
        self.form.set_text(i, &text);
        self.hint();
    }

    /// Ctrl-U: empties the focused field (the terminal convention), Esc brings it back.
    fn clear_field(&mut self) {
        let i = self.focus;
        if !self.form.enabled(i) || self.form.fields[i].kind == Kind::Choice {
            return;
        }
        if self.editing.is_none() {
            self.editing = Some(self.form.fields[i].text.clone());
        }
        self.form.set_text(i, "");
        self.hint();
    }

    fn backspace(&mut self) {
        let i = self.focus;
        if !self.form.enabled(i) || self.form.fields[i].kind == Kind::Choice {
            return;
        }
        if self.editing.is_none() {
            self.editing = Some(self.form.fields[i].text.clone());
        }
        let mut text = self.form.fields[i].text.clone();
        text.pop();
        self.form.set_text(i, &text);
        self.hint();
    }

    fn cycle_choice(&mut self, forward: bool) {
        let f = &self.form.fields[self.focus];
        if f.kind != Kind::Choice || f.choices.is_empty() {
            return;
        }
        let n = f.choices.len();
        let at = f.choices.iter().position(|c| *c == f.text).unwrap_or(0);
        let next = f.choices[if forward { (at + 1) % n } else { (at + n - 1) % n }].clone();
        self.form.set_text(self.focus, &next);
        self.hint();
    }

    /// Handles one key. Afterwards the message line says what the key did, or else the
    /// page's keys: a message never outlives the next key.
    pub fn on_key(&mut self, key: KeyEvent) {
        self.said = false;
        self.handle_key(key);
        if !self.said {
            self.hint();
        }
    }

    fn handle_key(&mut self, key: KeyEvent) {
        let ctrl = key.modifiers.contains(KeyModifiers::CONTROL);
        if self.prompt.is_some() && !(ctrl && key.code == KeyCode::Char('c')) {
            return self.on_prompt_key(key.code);
        }
        match key.code {
            KeyCode::Char('c') if ctrl => {
                if self.running.is_some() {
                    self.abort();
                } else {
                    self.quit = Some(Quit::Cancelled);
                }
            }
            KeyCode::F(1) => self.show(Page::Setup),
            KeyCode::F(3) => self.show(Page::Log),
            KeyCode::F(4) => self.show(Page::Results),
            KeyCode::F(7) => self.show(Page::Charts),
            KeyCode::F(8) => self.show(Page::History),
            KeyCode::F(2) => self.start(Mode::Home),
            KeyCode::F(5) => self.start(Mode::Run),
            KeyCode::F(6) => self.start(Mode::Step),
            KeyCode::F(9) => self.abort_key(),
            KeyCode::Char('t') if ctrl => self.start(Mode::Tune),
            KeyCode::Char('b') if ctrl => self.start(Mode::Conveyor),
            // Jog keys where no arrow edits or chooses anything: not while a field is typed
            // (Setup) nor where ←/→ choose the motor charted (Charts).
            KeyCode::Left if ctrl && self.jog_page() => self.jog(-1),
            KeyCode::Right if ctrl && self.jog_page() => self.jog(1),
            KeyCode::Up if ctrl && self.jog_page() => self.jog_motor_by(-1),
            KeyCode::Down if ctrl && self.jog_page() => self.jog_motor_by(1),
            KeyCode::Char('a') if ctrl => self.apply_tuned(),
            KeyCode::Char('g') if ctrl => self.open_prompt(),
            KeyCode::Char('o') if ctrl => self.toggle_gripper(),
            KeyCode::F(10) => {
                if self.running.is_some() {
                    return self.say("a move is running: F9 aborts it first", true);
                }
                self.commit_edit();
                match self.form.save() {
                    Ok(()) => self.quit = Some(Quit::Saved),
                    Err(e) => self.say(format!("not saved: {e} (F12 leaves without saving)"), true),
                }
            }
            KeyCode::F(12) => {
                if self.running.is_some() {
                    return self.say("a move is running: F9 aborts it first", true);
                }
                self.quit = Some(Quit::Cancelled);
            }
            KeyCode::Char('u') if ctrl && self.page == Page::Setup => self.clear_field(),
            // Other control and Alt combinations are not text.
            KeyCode::Char(_)
                if key.modifiers.intersects(KeyModifiers::CONTROL | KeyModifiers::ALT) => {}
            _ if self.page == Page::Charts => self.on_chart_key(key.code),
            _ if self.page == Page::Setup => self.on_setup_key(key.code),
            _ if self.page == Page::Log => self.on_log_key(key.code),
            _ => self.on_page_key(key.code),
        }
    }

    /// Scrolls the results or history page (from its top).
    fn on_page_key(&mut self, code: KeyCode) {
        const PAGE: usize = 10;
        self.page_scroll = match code {
            KeyCode::Up => self.page_scroll.saturating_sub(1),
            KeyCode::Down => self.page_scroll + 1,
            KeyCode::PageUp => self.page_scroll.saturating_sub(PAGE),
            KeyCode::PageDown => self.page_scroll + PAGE,
            KeyCode::Home => 0,
            KeyCode::End => usize::MAX / 2,
            _ => self.page_scroll,
        };
    }

    /// Shows `page` from its top.
    pub(crate) fn show(&mut self, page: Page) {
        if page != self.page {
            self.page_scroll = 0;
        }
        self.page = page;
    }

    /// Scrolls the log: by a row, by a page (`LOG_PAGE` rows), to the first line, back to
    /// following the output.
    fn on_log_key(&mut self, code: KeyCode) {
        const LOG_PAGE: usize = 10;
        self.log_scroll = match code {
            KeyCode::Up => self.log_scroll + 1,
            KeyCode::Down => self.log_scroll.saturating_sub(1),
            KeyCode::PageUp => self.log_scroll + LOG_PAGE,
            KeyCode::PageDown => self.log_scroll.saturating_sub(LOG_PAGE),
            KeyCode::Home => usize::MAX,
            KeyCode::End => 0,
            _ => self.log_scroll,
        };
    }

    fn on_chart_key(&mut self, code: KeyCode) {
        let n = self
            .last
            .as_ref()
            .and_then(|r| r.series.as_ref().ok())
            .map_or(1, |s| s.cmd.len().max(s.act.len()).max(1));
        match code {
            KeyCode::Right | KeyCode::Tab => self.chart_motor = (self.chart_motor + 1) % n,
            KeyCode::Left | KeyCode::BackTab => self.chart_motor = (self.chart_motor + n - 1) % n,
            KeyCode::Char(c @ '1'..='4') => {
                self.chart_motor = (c as usize - '1' as usize).min(n - 1)
            }
            _ => {}
        }
    }

    fn on_setup_key(&mut self, code: KeyCode) {
        match code {
            KeyCode::Tab | KeyCode::Down | KeyCode::Enter => self.move_focus(true),
            KeyCode::BackTab | KeyCode::Up => self.move_focus(false),
            KeyCode::Left if self.form.fields[self.focus].kind == Kind::Choice => {
                self.cycle_choice(false)
            }
            KeyCode::Right if self.form.fields[self.focus].kind == Kind::Choice => {
                self.cycle_choice(true)
            }
            KeyCode::Char(' ') if self.form.fields[self.focus].kind == Kind::Choice => {
                self.cycle_choice(true)
            }
            KeyCode::Left => self.move_column(false),
            KeyCode::Right => self.move_column(true),
            KeyCode::Esc => {
                if let Some(old) = self.editing.take() {
                    self.form.set_text(self.focus, &old);
                }
                self.hint();
            }
            KeyCode::Backspace => self.backspace(),
            KeyCode::Char(c) => self.type_char(c),
            _ => {}
        }
    }
}
