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

    /// The error of a TOML parse failure.
    pub fn toml(&self, e: &toml::de::Error) -> ScenarioError {
        self.at(e.span(), e.message().to_string())
    }
}
