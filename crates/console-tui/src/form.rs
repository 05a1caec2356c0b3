//! The settings form: the five sections of the thesis console (3.4) as editable fields, read
//! from and written back to the settings file the starter reads — its comments, order and
//! formatting kept — and checked with the very code the starter and controller use.

use qmarc_config::{ConfigLoadError, Settings};
use qmarc_plugins::registry;
use qmarc_plugins::source::KnotSource;
use std::path::{Path, PathBuf};
use toml_edit::{Array, DocumentMut, Item, Table, Value};

/// Sections of the console, as in the thesis' Figure 3-5.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Section {
    /// Number of motors, servo period, home offsets.
    General,
    /// Method and knot file.
    Trajectory,
    /// Step size and duration.
    Step,
    /// Gains and notch per motor.
    Gains,
    /// Data gathering.
    Gathering,
}

/// What a field holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A whole number.
    Int,
    /// A number.
    Float,
    /// Free text (a path).
    Text,
    /// One of [`Field::choices`].
    Choice,
    /// A comma-separated list of names.
    List,
}

/// Where a field lives in the settings file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// `[table] key`.
    Key(&'static str, &'static str),
    /// `key` of the 0-based `[[motor]]` table.
    Motor(usize, &'static str),
    /// Element of `notch = [n1, n2, d1, d2]` of the 0-based `[[motor]]` table.
    Notch(usize, usize),
}

impl Place {
    /// The field as the settings checker names it (`general.period_us`, `motor[2].kp`).
    pub fn config_path(self) -> String {
        match self {
            Place::Key(t, k) => format!("{t}.{k}"),
            Place::Motor(m, k) => format!("motor[{}].{k}", m + 1),
            Place::Notch(m, _) => format!("motor[{}].notch", m + 1),
        }
    }

    /// The motor (0-based) of a per-motor field.
    pub fn motor(self) -> Option<usize> {
        match self {
            Place::Motor(m, _) | Place::Notch(m, _) => Some(m),
            Place::Key(..) => None,
        }
    }
}

/// One editable value.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// Its section.
    pub section: Section,
    /// Its label.
    pub label: &'static str,
    /// Where it lives.
    pub place: Place,
    /// What it holds.
    pub kind: Kind,
    /// The text as edited.
    pub text: String,
    /// Why it does not validate, if it does not.
    pub error: Option<String>,
    /// Which check the error comes from (meaningless without one).
    pub check: Check,
    /// The choices of a [`Kind::Choice`].
    pub choices: Vec<String>,
}

impl Field {
    /// Its name on screen: the label, and the motor for a per-motor field (`Kp M1`).
    pub fn name(&self) -> String {
        match self.place.motor() {
            Some(m) => format!("{} M{}", self.label, m + 1),
            None => self.label.to_string(),
        }
    }
}

/// Where a field's error comes from: that decides which actions it blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Check {
    /// The settings parser refused the value: the file cannot be saved, so every action
    /// (each saves first) is blocked.
    Settings,
    /// The knot file does not exist or parse: only `run` reads it (the starter does the same).
    KnotFile,
    /// The value parses but this machine cannot do it (the servo period): no move may start;
    /// the settings can still be saved.
    Machine,
}

/// What an action needs to be valid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Home robot.
    Home,
    /// Start controller (run the trajectory).
    Run,
    /// Step motors now.
    Step,
    /// Exit, saving the settings.
    Save,
}

/// Labels of the gain rows, in order: Kp Ki Kd Kvff Kaff n1 n2 d1 d2.
pub const GAIN_ROWS: [&str; 9] = ["Kp", "Ki", "Kd", "Kvff", "Kaff", "n1", "n2", "d1", "d2"];

/// The form.
#[derive(Debug, Clone)]
pub struct Form {
    /// The settings file.
    pub path: PathBuf,
    original: String,
    /// The file as the console found it (what Cancel puts back).
    opened: String,

    doc: DocumentMut,
    /// Every field, in display order.
    pub fields: Vec<Field>,
    /// `[[motor]]` tables in the file (gain columns).
    pub motor_tables: usize,
    /// The settings as the parser checks them now (`None` while a value does not parse; the
    /// knot-file and machine checks do not clear it).
    pub checked: Option<Settings>,
    /// An error the form cannot show on one field (elsewhere in the file).
    pub file_error: Option<String>,
    /// The work of one servo cycle of the last move, µs (`MoveResult::cycle_work_us`): what
    /// a cycle needs on this machine, which the servo period must exceed.
    pub last_cycle_work_us: Option<f64>,
    /// Where moves run: relative paths in the settings (the knot file) are relative to it.
    pub base: PathBuf,
}

fn item_text(item: Option<&Item>) -> Option<String> {
    let v = item?.as_value()?;
    Some(match v {
        Value::String(s) => s.value().clone(),
        Value::Integer(i) => i.value().to_string(),
        Value::Float(f) => float_text(*f.value()),
        Value::Boolean(b) => b.value().to_string(),
        Value::Array(a) => a.iter().filter_map(|x| x.as_str()).collect::<Vec<_>>().join(","),
        _ => return None,
    })
}

impl Form {
    /// Reads `path` into a form, relative paths in it (the knot file) taken from `base`, where
    /// moves will run. Fails only when the file cannot be read or is not TOML at all (it could
    /// not be edited then); invalid values load and show their errors in place.
    pub fn load_in(path: &Path, base: &Path) -> Result<Form, String> {
        let original = qmarc_config::read_config(path).map_err(|e| e.to_string())?;
        let doc: DocumentMut = original.parse().map_err(|e| format!("{}: {e}", path.display()))?;
        let motor_tables = doc
            .get("motor")
            .and_then(Item::as_array_of_tables)
            .map_or(0, |a| a.len())
            .min(qmarc_proto::MAX_MOTORS);
        let mut form = Form {
            path: path.to_path_buf(),
            opened: original.clone(),
            original,

            doc,
            fields: Vec::new(),
            motor_tables,
            checked: None,
            file_error: None,
            last_cycle_work_us: None,
            base: base.to_path_buf(),
        };
        form.fields = form.layout();
        form.validate();
        Ok(form)
    }

    fn layout(&self) -> Vec<Field> {
        let methods: Vec<String> =
            registry::path_generator_names().into_iter().map(str::to_string).collect();
        let mut f = Vec::new();
        let mut add = |section, label, place, kind| {
            f.push(Field {
                section,
                label,
                place,
                kind,
                text: self.read(place).unwrap_or_default(),
                error: None,
                check: Check::Settings,
                choices: if kind == Kind::Choice { methods.clone() } else { Vec::new() },
            })
        };
        add(Section::General, "Motors", Place::Key("general", "n_motors"), Kind::Int);
        add(Section::General, "Period µs", Place::Key("general", "period_us"), Kind::Int);
        add(Section::Trajectory, "Method", Place::Key("trajectory", "method"), Kind::Choice);
        add(Section::Trajectory, "Knots", Place::Key("trajectory", "knots"), Kind::Text);
        add(Section::Step, "Size", Place::Key("step", "size"), Kind::Int);
        add(Section::Step, "Duration s", Place::Key("step", "duration_s"), Kind::Float);
        add(Section::Gathering, "Every", Place::Key("gather", "every"), Kind::Int);
        add(Section::Gathering, "Out dir", Place::Key("gather", "out_dir"), Kind::Text);
        add(Section::Gathering, "Fields", Place::Key("gather", "fields"), Kind::List);
        for m in 0..self.motor_tables {
            add(Section::General, "Home", Place::Motor(m, "home_offset_counts"), Kind::Float);
        }
        for (row, key) in ["kp", "ki", "kd", "kvff", "kaff"].into_iter().enumerate() {
            for m in 0..self.motor_tables {
                add(Section::Gains, GAIN_ROWS[row], Place::Motor(m, key), Kind::Float);
            }
        }
        for k in 0..4 {
            for m in 0..self.motor_tables {
                add(Section::Gains, GAIN_ROWS[5 + k], Place::Notch(m, k), Kind::Float);
            }
        }
        f
    }

    fn motor_table(&self, m: usize) -> Option<&Table> {
        self.doc.get("motor")?.as_array_of_tables()?.get(m)
    }

    /// The text of `place` in the file as loaded.
    fn read(&self, place: Place) -> Option<String> {
        match place {
            Place::Key(t, k) => item_text(self.doc.get(t).and_then(|t| t.get(k))),
            Place::Motor(m, k) => item_text(self.motor_table(m)?.get(k)),
            Place::Notch(m, k) => {
                let arr = self.motor_table(m)?.get("notch")?.as_array()?;
                let v = arr.get(k)?;
                v.as_float().map(float_text).or_else(|| v.as_integer().map(|i| i.to_string()))
            }
        }
    }

    fn value_of(field: &Field) -> Value {
        let t = field.text.trim();
        match field.kind {
            Kind::Int => t.parse::<i64>().map(Value::from).unwrap_or_else(|_| Value::from(t)),
            Kind::Float => t.parse::<f64>().map(Value::from).unwrap_or_else(|_| Value::from(t)),
            Kind::Text | Kind::Choice => Value::from(t),
            Kind::List => {
                let mut a = Array::new();
                for n in t.split(',').map(str::trim).filter(|n| !n.is_empty()) {
                    a.push(n);
                }
                Value::Array(a)
            }
        }
    }

    /// `doc` with `field` written into it (keys and tables created where missing).
    fn apply(doc: &mut DocumentMut, field: &Field) {
        let value = Form::value_of(field);
        match field.place {
            Place::Key(t, k) => {
                if !doc.contains_table(t) {
                    doc.insert(t, Item::Table(Table::new()));
                }
                set_keeping_decor(&mut doc[t][k], value);
            }
            Place::Motor(m, k) => {
                if let Some(table) = doc
                    .get_mut("motor")
                    .and_then(Item::as_array_of_tables_mut)
                    .and_then(|a| a.get_mut(m))
                {
                    set_keeping_decor(&mut table[k], value);
                }
            }
            Place::Notch(m, k) => {
                if let Some(table) = doc
                    .get_mut("motor")
                    .and_then(Item::as_array_of_tables_mut)
                    .and_then(|a| a.get_mut(m))
                {
                    if table.get("notch").and_then(Item::as_array).is_none_or(|a| a.len() != 4) {
                        table["notch"] = toml_edit::value(Array::from_iter([0.0, 0.0, 0.0, 0.0]));
                    }
                    if let Some(arr) = table["notch"].as_array_mut()
                        && arr.get(k).is_none_or(|old| !same_value(old, &value))
                    {
                        arr.replace(k, value);
                    }
                }
            }
        }
    }

    /// The file with every field written except those in `skip`.
    fn doc_with(&self, skip: &[usize]) -> DocumentMut {
        let mut doc = self.doc.clone();
        for (i, f) in self.fields.iter().enumerate() {
            if !skip.contains(&i) {
                Form::apply(&mut doc, f);
            }
        }
        doc
    }

    /// The settings file as it would be saved now.
    pub fn text(&self) -> String {
        self.doc_with(&[]).to_string()
    }

    /// True when saving would change the file.
    pub fn dirty(&self) -> bool {
        self.text() != self.original
    }

    /// Number of motors the form says (falls back to the tables in the file).
    pub fn n_motors(&self) -> usize {
        self.fields[0]
            .text
            .trim()
            .parse::<usize>()
            .ok()
            .filter(|n| (1..=self.motor_tables).contains(n))
            .unwrap_or(self.motor_tables)
    }

    /// Whether field `i` can be edited: per-motor fields of motors beyond the number of motors
    /// are not (thesis 3.4: their edit boxes are disabled).
    pub fn enabled(&self, i: usize) -> bool {
        self.fields[i].place.motor().is_none_or(|m| m < self.n_motors())
    }

    /// Sets field `i`'s text and checks everything again.
    pub fn set_text(&mut self, i: usize, text: &str) {
        self.fields[i].text = text.to_string();
        self.validate();
    }

    /// The index of the field at `place`.
    pub fn index(&self, place: Place) -> Option<usize> {
        self.fields.iter().position(|f| f.place == place)
    }

    /// Checks every field with the starter's own code: the whole file is parsed; an error
    /// names a field, which is marked, set back to its saved value, and the file parsed again,
    /// until it checks. Then the knot file is read for the chosen method and the period is
    /// compared with what the last move needed.
    pub fn validate(&mut self) {
        for f in &mut self.fields {
            f.error = None;
        }
        self.file_error = None;
        self.checked = None;
        let mut skip: Vec<usize> = Vec::new();
        for _ in 0..=self.fields.len() {
            let text = self.doc_with(&skip).to_string();
            match Settings::parse(&self.path, &text, &qmarc_plugins::registry::names()) {
                Ok(s) => {
                    if skip.is_empty() {
                        self.checked = Some(s);
                    }
                    break;
                }
                Err(ConfigLoadError::Invalid { field, message, line, .. }) => {
                    let hit: Vec<usize> = (0..self.fields.len())
                        .filter(|&i| {
                            self.fields[i].place.config_path() == field && !skip.contains(&i)
                        })
                        .collect();
                    if hit.is_empty() {
                        self.file_error =
                            Some(format!("{}:{line}: {field}: {message}", self.path.display()));
                        break;
                    }
                    for i in hit {
                        self.fields[i].error = Some(message.clone());
                        self.fields[i].check = Check::Settings;
                        skip.push(i);
                    }
                }
                Err(e) => {
                    self.file_error = Some(e.to_string());
                    break;
                }
            }
        }
        if let Some(s) = self.checked.clone() {
            self.check_knots(&s);
            self.check_period(&s);
        }
    }

    /// The knot file must exist and parse for the chosen method and motors.
    fn check_knots(&mut self, s: &Settings) {
        let Some(i) = self.index(Place::Key("trajectory", "knots")) else { return };
        let mut s = s.clone();
        s.trajectory.knots = s
            .trajectory
            .knots
            .map(|k| if k.is_relative() && k != Path::new("-") { self.base.join(k) } else { k });
        let s = &s;
        let Some(entry) = registry::generator(&s.trajectory.method) else { return };
        if !entry.needs_knots() {
            return;
        }
        let error = match &s.trajectory.knots {
            None => Some("this method needs a knot file".to_string()),
            Some(path) => match KnotSource::from_path(path) {
                Ok(KnotSource::File(_)) => (entry.build)(s).err().map(|e| e.to_string()),
                // The console gives the starter no standard input to read knots from.
                Ok(KnotSource::Stdin) => Some(
                    "\"-\" (standard input) works only with qmarc-starter run by hand: \
                     give a file or a FIFO"
                        .to_string(),
                ),
                Ok(_) => None, // a stream: read when the move starts
                Err(e) => Some(e.to_string()),
            },
        };
        if let Some(e) = error {
            self.fields[i].error = Some(e);
            self.fields[i].check = Check::KnotFile;
        }
    }

    /// The servo period must leave the loop room: more than the work of a typical cycle of the
    /// last move (medians, not tails: on a kernel without PREEMPT_RT the tails are host
    /// stalls, which no period avoids).
    fn check_period(&mut self, s: &Settings) {
        let (Some(i), Some(work)) =
            (self.index(Place::Key("general", "period_us")), self.last_cycle_work_us)
        else {
            return;
        };
        if f64::from(s.period_us) <= work {
            self.fields[i].check = Check::Machine;
            self.fields[i].error = Some(format!(
                "a cycle of the last move needed {work:.0} µs of work (two hwserver exchanges \
                 and the law, medians): a {} µs period would overrun every cycle on this machine",
                s.period_us
            ));
        }
    }

    /// The first error that stops `action`: (field index or none, message).
    pub fn blocking(&self, action: Action) -> Option<(Option<usize>, String)> {
        if let Some(e) = &self.file_error {
            return Some((None, e.clone()));
        }
        self.fields.iter().enumerate().find_map(|(i, f)| {
            let needed = match (f.check, action) {
                (Check::Settings, _) | (_, Action::Run) => true,
                (Check::Machine, Action::Step | Action::Home) => true,
                (Check::KnotFile | Check::Machine, _) => false,
            };
            let e = f.error.as_ref().filter(|_| needed)?;
            Some((Some(i), format!("{} {}: {e}", f.place.config_path(), f.label)))
        })
    }

    /// Cancel: puts the file back as it was when the form was loaded, if a move saved other
    /// settings since (moves save them before they start). Untouched otherwise.
    pub fn restore_opened(&mut self) -> Result<(), String> {
        if self.original != self.opened {
            std::fs::write(&self.path, &self.opened).map_err(|e| {
                format!("{}: cannot put back the settings: {e}", self.path.display())
            })?;
        }
        Ok(())
    }

    /// Writes the file (only when every field checks).
    pub fn save(&mut self) -> Result<(), String> {
        if let Some((_, e)) = self.blocking(Action::Save) {
            return Err(e);
        }
        let text = self.text();
        std::fs::write(&self.path, &text).map_err(|e| format!("{}: {e}", self.path.display()))?;
        self.original = text.clone();
        self.doc = text.parse().map_err(|e| format!("{e}"))?;
        Ok(())
    }
}

/// Replaces the value of `item`, keeping the comment after it.
fn set_keeping_decor(item: &mut Item, mut value: Value) {
    if let Some(old) = item.as_value() {
        if same_value(old, &value) {
            return; // unchanged: as the file writes it (`1e308` stays `1e308`)
        }
        *value.decor_mut() = old.decor().clone();
    } else {
        value.decor_mut().set_prefix(" ");
    }
    *item = Item::Value(value);
}

/// A float as the form shows it: plain in the everyday range, exponent notation beyond
/// (`1e308`, not 309 digits), always the exact value (it is edited and written back).
fn float_text(f: f64) -> String {
    if qmarc_config::in_exponent_notation(f) { format!("{f:e}") } else { f.to_string() }
}

/// Whether `new` is the value `old` holds (numbers by value, whatever their spelling).
fn same_value(old: &Value, new: &Value) -> bool {
    match (old, new) {
        (Value::Float(a), Value::Float(b)) => a.value() == b.value(),
        (Value::Integer(a), Value::Integer(b)) => a.value() == b.value(),
        (Value::Boolean(a), Value::Boolean(b)) => a.value() == b.value(),
        (Value::String(a), Value::String(b)) => a.value() == b.value(),
        (Value::Array(a), Value::Array(b)) => {
            a.len() == b.len() && a.iter().zip(b.iter()).all(|(x, y)| same_value(x, y))
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests;
