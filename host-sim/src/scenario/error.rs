//! Why a scenario file did not load: which file, which line, and what is wrong.

use std::fmt;
use std::ops::Range;
use std::path::PathBuf;

/// A scenario that failed to load: where, and what is wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioError {
    /// The file.
    pub file: PathBuf,
    /// 1-based line, when the problem has one.
    pub line: Option<usize>,
    /// What is wrong.
    pub problem: String,
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "{}:{}: {}", self.file.display(), l, self.problem),
            None => write!(f, "{}: {}", self.file.display(), self.problem),
        }
    }
}

impl std::error::Error for ScenarioError {}

/// The 1-based line of the start of `span` in `text`.
pub fn line_of(text: &str, span: Range<usize>) -> usize {
    let end = span.start.min(text.len());
    text.get(..end).map_or(1, |s| s.matches('\n').count() + 1)
}

/// Makes errors for one file: `err(span, problem)`.
pub struct Errors<'a> {
    text: &'a str,
    file: &'a std::path::Path,
}

impl<'a> Errors<'a> {
    /// Errors in `text`, read from `file`.
    pub fn new(text: &'a str, file: &'a std::path::Path) -> Self {
        Self { text, file }
    }

    /// The error `problem` at `span` (or at no line).
    pub fn at(&self, span: Option<Range<usize>>, problem: impl Into<String>) -> ScenarioError {
        ScenarioError {
            file: self.file.to_path_buf(),
            line: span.map(|s| line_of(self.text, s)),
            problem: problem.into(),
        }
    }

    /// The error of a TOML parse failure, naming the key it is about (serde's message
    /// names only the type it wanted).
    pub fn toml(&self, e: &toml::de::Error) -> ScenarioError {
        let message = e.message().to_string();
        let key = e.span().and_then(|s| key_at(self.text, s.start));
        match key {
            Some(key) if !message.contains(&key) => self.at(e.span(), format!("{key}: {message}")),
            _ => self.at(e.span(), message),
        }
    }

    /// The error `problem` about `field` of the table at `table`: on the field's own line
    /// when the table writes it (else the table's), the message naming the field.
    pub fn field(&self, table: Option<Range<usize>>, what: &str, f: &FieldError) -> ScenarioError {
        let line = table.clone().and_then(|t| field_in(self.text, t, f.field));
        ScenarioError {
            file: self.file.to_path_buf(),
            line: line.or(table.map(|s| line_of(self.text, s))),
            problem: format!("{what}: {f}"),
        }
    }

    /// The error `problem` about the key `key` of the table `[table]` (dotted, e.g.
    /// `faults.liar`), found by its text: on the key's line, else the table's header's,
    /// else the first line.
    pub fn key(&self, table: &str, key: &str, problem: impl Into<String>) -> ScenarioError {
        let header = self.text.find(&format!("[{table}]"));
        let line = header
            .and_then(|h| field_in(self.text, h..self.text.len(), key))
            .or(header.map(|h| line_of(self.text, h..h)))
            .unwrap_or(1);
        ScenarioError {
            file: self.file.to_path_buf(),
            line: Some(line),
            problem: problem.into(),
        }
    }
}

/// A problem with one field of a table: which field, and what is wrong with it.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldError {
    /// The field's key.
    pub field: &'static str,
    /// What is wrong.
    pub problem: String,
}

impl FieldError {
    /// `problem` with `field`.
    pub fn new(field: &'static str, problem: impl Into<String>) -> Self {
        Self {
            field,
            problem: problem.into(),
        }
    }
}

impl fmt::Display for FieldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.field, self.problem)
    }
}

/// The 1-based line of `key = …` within `span` of `text`, before any later table header.
fn field_in(text: &str, span: Range<usize>, key: &str) -> Option<usize> {
    let body = text.get(span.clone())?;
    let mut at = span.start;
    for (i, line) in body.split_inclusive('\n').enumerate() {
        let t = line.trim_start();
        if i > 0 && t.starts_with('[') {
            return None;
        }
        let named = t
            .strip_prefix(key)
            .is_some_and(|rest| rest.trim_start().starts_with('='));
        if named {
            return Some(line_of(text, at..at));
        }
        at += line.len();
    }
    None
}

/// The dotted name of the key written on the line holding byte `at` of `text` (its
/// table's header before it), if that line is `key = …`.
fn key_at(text: &str, at: usize) -> Option<String> {
    let start = text.get(..at)?.rfind('\n').map_or(0, |i| i + 1);
    let line = text.get(start..)?.lines().next()?;
    let (key, _) = line.split_once('=')?;
    let key = key.trim();
    let plain = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.';
    if key.is_empty() || !key.chars().all(plain) {
        return None;
    }
    let table = text
        .get(..start)?
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('['))
        .map(|h| h.trim_matches(|c| c == '[' || c == ']').to_string());
    Some(match table {
        Some(t) => format!("{t}.{key}"),
        None => key.to_string(),
    })
}
