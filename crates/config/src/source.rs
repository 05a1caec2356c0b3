//! Where a value came from: byte offsets of the settings file turned into `file:line:column`
//! and the dotted field name, and the small checks every section uses.

use crate::ConfigLoadError;
use std::ops::Range;
use std::path::Path;
use toml::Spanned;

/// An optional value of the file with its position.
pub(crate) type S<T> = Option<Spanned<T>>;

/// The error of toml's own parse of the file `path` holding `text` (a settings file, or
/// another TOML file of the project's: a camera's calibration): its line, column and field.
pub fn toml_file_error(path: &Path, text: &str, e: &toml::de::Error) -> ConfigLoadError {
    Source { path, text }.toml_error(e)
}

/// The text of the settings file, for turning byte offsets into lines and fields.
pub(crate) struct Source<'a> {
    pub path: &'a Path,
    pub text: &'a str,
}

impl Source<'_> {
    fn line_col(&self, offset: usize) -> (usize, usize) {
        let before = &self.text[..offset.min(self.text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        (line, column)
    }

    /// The error for the value at `span`.
    pub fn invalid(
        &self,
        span: Range<usize>,
        field: &str,
        message: impl Into<String>,
    ) -> ConfigLoadError {
        let (line, column) = self.line_col(span.start);
        ConfigLoadError::Invalid {
            file: self.path.to_path_buf(),
            line,
            column,
            field: field.to_string(),
            message: message.into(),
        }
    }

    /// The dotted field path at `offset`: the enclosing table header (with the 1-based index
    /// of an array of tables) and the key whose value holds the offset — found on the
    /// nearest line at or before it that starts with `key =`, so that a value spanning lines
    /// (a multi-line array) is named by its key, not by the line the error is on.
    pub fn field_at(&self, offset: usize) -> String {
        let mut table = String::new();
        let mut key = String::new();
        let mut counts: Vec<(String, usize)> = Vec::new();
        let mut line_start = 0;
        for line in self.text.split_inclusive('\n') {
            if line_start > offset {
                break;
            }
            line_start += line.len();
            let t = line.trim();
            let is_array = t.starts_with("[[");
            let header = t
                .strip_prefix("[[")
                .and_then(|r| r.split("]]").next())
                .or_else(|| t.strip_prefix('[').and_then(|r| r.split(']').next()));
            if let Some(name) = header.map(str::trim).filter(|n| !n.is_empty() && !n.contains(','))
            {
                let name = name.to_string();
                key.clear();
                table = if is_array {
                    let n = match counts.iter_mut().find(|(k, _)| *k == name) {
                        Some((_, n)) => {
                            *n += 1;
                            *n
                        }
                        None => {
                            counts.push((name.clone(), 1));
                            1
                        }
                    };
                    format!("{name}[{n}]")
                } else {
                    name
                };
            } else if let Some((k, _)) = t.split_once('=') {
                let k = k.trim();
                if !k.is_empty() && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                    key = k.to_string();
                }
            }
        }
        match (table.is_empty(), key.is_empty()) {
            (true, _) => key,
            (false, true) => table,
            (false, false) => format!("{table}.{key}"),
        }
    }

    /// The error of toml's own parse, at its position.
    pub fn toml_error(&self, e: &toml::de::Error) -> ConfigLoadError {
        let span = e.span().unwrap_or(0..0);
        let field = self.field_at(span.start);
        let message = e.message().trim().to_string();
        self.invalid(span, if field.is_empty() { "(file)" } else { &field }, message)
    }

    /// `v` or, when the file does not set it, `default`; checked with `ok`.
    pub fn take<T: Clone>(
        &self,
        v: &S<T>,
        field: &str,
        default: T,
        ok: impl FnOnce(&T) -> Result<(), String>,
    ) -> Result<T, ConfigLoadError> {
        match v {
            None => Ok(default),
            Some(s) => {
                ok(s.get_ref()).map_err(|m| self.invalid(s.span(), field, m))?;
                Ok(s.get_ref().clone())
            }
        }
    }

    /// `v` read into a value by `read` (a name of a closed set, a list of them) or, when the
    /// file does not set it, `default`: read once, an error of `read` at `v`'s position.
    pub fn read<R, T>(
        &self,
        v: &S<R>,
        field: &str,
        default: T,
        read: impl FnOnce(&R) -> Result<T, String>,
    ) -> Result<T, ConfigLoadError> {
        match v {
            None => Ok(default),
            Some(s) => read(s.get_ref()).map_err(|m| self.invalid(s.span(), field, m)),
        }
    }

    /// An integer setting within `lo‥=hi`, or `default` (callers narrow it: it is in range).
    pub fn int(
        &self,
        v: &S<i64>,
        field: &str,
        default: i64,
        lo: i64,
        hi: i64,
    ) -> Result<i64, ConfigLoadError> {
        self.take(v, field, default, in_range(lo, hi))
    }
}

/// The position of an optional value, or the file's start.
pub(crate) fn span_of<T>(v: &S<T>) -> Range<usize> {
    v.as_ref().map_or(0..0, Spanned::span)
}

/// `lo‥=hi`.
pub(crate) fn in_range(lo: i64, hi: i64) -> impl FnOnce(&i64) -> Result<(), String> {
    move |v| {
        if (lo..=hi).contains(v) { Ok(()) } else { Err(format!("must be {lo}‥{hi}, found {v}")) }
    }
}

/// A finite number.
pub(crate) fn finite(v: &f64) -> Result<(), String> {
    if v.is_finite() { Ok(()) } else { Err(format!("must be a finite number, found {}", num(*v))) }
}

/// Whether `x` is written in exponent notation where QMARC shows a number (messages, the
/// console's form): outside 10⁻⁴‥10⁷, zero and non-finite values excepted.
pub fn in_exponent_notation(x: f64) -> bool {
    x != 0.0 && x.is_finite() && !(1e-4..1e7).contains(&x.abs())
}

/// `x` as a person reads it: plain between 10⁻⁴ and 10⁷, in exponent notation beyond
/// (`1e20`, `1e-300`).
pub fn num(x: f64) -> String {
    if in_exponent_notation(x) {
        // Six significant digits at most, trailing zeros dropped: 1e308, 1.5e-6.
        let short = format!("{x:.5e}");
        match short.split_once('e') {
            Some((mantissa, exp)) if mantissa.contains('.') => {
                format!("{}e{exp}", mantissa.trim_end_matches('0').trim_end_matches('.'))
            }
            _ => short,
        }
    } else {
        format!("{x}")
    }
}

/// A finite number > 0.
pub(crate) fn positive(v: &f64) -> Result<(), String> {
    if v.is_finite() && *v > 0.0 {
        Ok(())
    } else {
        Err(format!("must be a finite number > 0, found {}", num(*v)))
    }
}

/// A finite number ≥ 0.
pub(crate) fn non_negative(v: &f64) -> Result<(), String> {
    if v.is_finite() && *v >= 0.0 {
        Ok(())
    } else {
        Err(format!("must be a finite number ≥ 0, found {}", num(*v)))
    }
}

/// A finite number > 0 and ≤ `hi` of `unit`: a value that becomes a duration or a count.
pub(crate) fn positive_at_most(
    hi: f64,
    unit: &'static str,
) -> impl FnOnce(&f64) -> Result<(), String> {
    move |v| {
        if v.is_finite() && *v > 0.0 && *v <= hi {
            Ok(())
        } else {
            Err(format!("must be > 0 and ≤ {hi} {unit}, found {}", num(*v)))
        }
    }
}

/// A finite number within `lo‥=hi` of `unit`.
pub(crate) fn within(
    lo: f64,
    hi: f64,
    unit: &'static str,
) -> impl FnOnce(&f64) -> Result<(), String> {
    move |v| {
        if v.is_finite() && (lo..=hi).contains(v) {
            Ok(())
        } else {
            Err(format!("must be {lo}‥{hi} {unit}, found {}", num(*v)))
        }
    }
}

/// A non-empty text.
pub(crate) fn not_empty<T: AsRef<str>>(v: &T) -> Result<(), String> {
    if v.as_ref().trim().is_empty() { Err("must not be empty".into()) } else { Ok(()) }
}

/// One of `names` (`what`: e.g. "servo law"); any name that is not empty when `names` is
/// empty (a process that does not know them: [`crate::Names::any_plugin`]).
pub(crate) fn one_of<'a>(
    names: &'a [&'static str],
    what: &'static str,
) -> impl FnOnce(&String) -> Result<(), String> + 'a {
    move |v| {
        if names.contains(&v.as_str()) || (names.is_empty() && !v.trim().is_empty()) {
            Ok(())
        } else {
            Err(format!("unknown {what} `{v}`; registered: {}", names.join(", ")))
        }
    }
}

/// Largest settings file, bytes.
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// Reads at most `limit` bytes of the file `path`: `Ok(None)` when it holds more (a device
/// such as `/dev/zero` included, whatever its size says). Every file a user names is read
/// through this, so no input can grow memory without bound.
pub fn read_bounded(path: &Path, limit: u64) -> std::io::Result<Option<Vec<u8>>> {
    use std::io::Read;
    let mut raw = Vec::new();
    std::fs::File::open(path)?.take(limit.saturating_add(1)).read_to_end(&mut raw)?;
    Ok((raw.len() as u64 <= limit).then_some(raw))
}

/// Reads the settings file `path`, refusing more than [`MAX_CONFIG_BYTES`] (`/dev/zero`
/// included) and text that is not UTF-8.
pub fn read_config(path: &Path) -> Result<String, ConfigLoadError> {
    let file = || path.to_path_buf();
    let raw = read_bounded(path, MAX_CONFIG_BYTES)
        .map_err(|reason| ConfigLoadError::Read { file: file(), reason })?
        .ok_or_else(|| ConfigLoadError::TooLarge { file: file(), limit: MAX_CONFIG_BYTES })?;
    String::from_utf8(raw).map_err(|e| ConfigLoadError::Read {
        file: file(),
        reason: std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()),
    })
}
