//! The console's hand controls: Ctrl-↑/↓ choose what the jog keys move — motor 1‥n, then
//! the effector along x, y and z (where the settings describe the Delta) — and Ctrl-←/→ jog
//! it by `[jog] counts` or `[jog] mm` through the starter's `jog`; Ctrl-G goes to a point
//! typed as `X Y Z` (mm, `move --xyz`); Ctrl-O closes or opens the gripper where the robot is
//! (`move --grip on|off`). docs/usage.md, "The commands".

use super::{App, Page};
use crate::starter_process::Mode;
use qmarc_config::AXES;
use ratatui::crossterm::event::KeyCode;

/// What the jog keys move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JogTarget {
    /// A motor, 1-based, by `counts`.
    Motor(usize, i64),
    /// The effector along an axis (0 x, 1 y, 2 z), by `mm`.
    Axis(usize, f64),
}

impl App {
    /// Whether the page shown takes the jog keys: the log, the results and the history.
    pub(super) fn jog_page(&self) -> bool {
        matches!(self.page, Page::Log | Page::Results | Page::History)
    }

    /// What the jog keys can move and how far: the motors, and the axes where the settings
    /// describe the Delta (none while the settings do not validate).
    fn jog_choices(&self) -> Option<(usize, usize, i64, f64)> {
        let s = self.form.checked.as_ref()?;
        let axes = if s.robot().is_some() { AXES.len() } else { 0 };
        Some((s.n_motors, axes, s.jog.counts, s.jog.mm))
    }

    /// What the jog keys move now.
    pub fn jog_target(&self) -> Option<JogTarget> {
        let (n, axes, counts, mm) = self.jog_choices()?;
        let k = self.jog_motor.clamp(1, n + axes);
        Some(if k <= n { JogTarget::Motor(k, counts) } else { JogTarget::Axis(k - n - 1, mm) })
    }

    /// Ctrl-↑/↓: the next or previous motor or axis.
    pub(super) fn jog_motor_by(&mut self, step: isize) {
        let Some((n, axes, ..)) = self.jog_choices() else {
            return self.say("jog: the settings do not validate", true);
        };
        self.jog_motor = (self.jog_motor as isize + step).clamp(1, (n + axes) as isize) as usize;
        match self.jog_target() {
            Some(JogTarget::Motor(m, counts)) => self
                .say(format!("jog: motor {m} (Ctrl-← / Ctrl-→ move it ∓{counts} counts)"), false),
            Some(JogTarget::Axis(a, mm)) => self.say(
                format!("jog: the effector along {} (Ctrl-← / Ctrl-→ move it ∓{mm} mm)", AXES[a]),
                false,
            ),
            None => {}
        }
    }

    /// Ctrl-←/→: jogs what is chosen one way (`sign` −1) or the other.
    pub(super) fn jog(&mut self, sign: i64) {
        match self.jog_target() {
            None => self.say("jog: the settings do not validate", true),
            Some(JogTarget::Motor(motor, counts)) => {
                self.start(Mode::Jog { motor, counts: sign * counts })
            }
            Some(JogTarget::Axis(axis, mm)) => {
                self.start(Mode::JogAxis { axis, mm: sign as f64 * mm })
            }
        }
    }

    /// Ctrl-G: asks for the point to go to.
    pub(super) fn open_prompt(&mut self) {
        if self.form.checked.as_ref().and_then(|s| s.robot()).is_none() {
            return self.say("go to: the settings describe no Delta ([robot], 3 motors)", true);
        }
        self.prompt = Some(String::new());
        self.say("go to X Y Z (mm), Enter goes, Esc cancels:", false);
    }

    /// A key while the point is typed.
    pub(super) fn on_prompt_key(&mut self, code: KeyCode) {
        let Some(text) = self.prompt.as_mut() else { return };
        match code {
            KeyCode::Esc => {
                self.prompt = None;
                return self.say("go to: cancelled", false);
            }
            KeyCode::Backspace => {
                text.pop();
            }
            KeyCode::Char(c) if c.is_ascii_digit() || " ,.-+eE".contains(c) => text.push(c),
            KeyCode::Enter => {
                let typed = text.clone();
                return match parse_point(&typed) {
                    Ok(xyz) => {
                        self.prompt = None;
                        self.start(Mode::GoTo { xyz });
                    }
                    Err(e) => self.say(format!("go to X Y Z (mm): {e}"), true),
                };
            }
            _ => {}
        }
        self.say("go to X Y Z (mm), Enter goes, Esc cancels:", false);
    }

    /// Ctrl-O: closes the gripper, or opens it if it was closed from here.
    pub(super) fn toggle_gripper(&mut self) {
        match self.form.checked.as_ref().map(|s| s.s626.gripper_dio) {
            None => self.say("gripper: the settings do not validate", true),
            Some(None) => self.say("gripper: none is wired ([s626] gripper_dio)", true),
            Some(Some(_)) => self.start(Mode::Grip { close: !self.grip_closed }),
        }
    }
}

/// Three numbers, by spaces or commas: a point in mm.
pub fn parse_point(text: &str) -> Result<[f64; 3], String> {
    let numbers: Vec<f64> = text
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|w| !w.is_empty())
        .map(|w| w.parse::<f64>().map_err(|_| format!("`{w}` is not a number")))
        .collect::<Result<_, _>>()?;
    match numbers[..] {
        [x, y, z] if numbers.iter().all(|v| v.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("three numbers, found {}", numbers.len())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_is_three_numbers_by_spaces_or_commas() {
        assert_eq!(parse_point("20 -10 -640"), Ok([20.0, -10.0, -640.0]));
        assert_eq!(parse_point(" 1.5, 2e1 ,-3 "), Ok([1.5, 20.0, -3.0]));
        assert_eq!(parse_point("1 2"), Err("three numbers, found 2".into()));
        assert_eq!(parse_point("1 2 x"), Err("`x` is not a number".into()));
        assert!(parse_point("1 2 inf").is_err());
    }
}
