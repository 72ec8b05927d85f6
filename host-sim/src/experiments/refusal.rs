//! Why an experiment's settings were refused, before anything ran: the flag and what is
//! wrong with it (the command line prints it and exits 2).

use std::fmt;

/// Why settings were refused (before anything ran): the flag, and the whole message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SettingsError {
    /// The flag (as the command line spells it, `--rates`).
    pub flag: &'static str,
    /// What is wrong, the flag named first.
    pub message: String,
}

impl SettingsError {
    /// `flag` must be `expected`: "`flag`: `expected`".
    pub fn new(flag: &'static str, expected: impl fmt::Display) -> Self {
        Self {
            flag,
            message: format!("{flag}: {expected}"),
        }
    }

    /// `message` as it is, about `flag`.
    pub fn raw(flag: &'static str, message: String) -> Self {
        Self { flag, message }
    }
}

impl fmt::Display for SettingsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for SettingsError {}

/// `--duration` within (0, `max`] s.
pub fn duration_within(duration: f64, max: f64) -> Result<(), SettingsError> {
    if duration > 0.0 && duration <= max {
        Ok(())
    } else {
        Err(SettingsError::raw(
            "--duration",
            format!("--duration must be in (0, {max}], got {duration}"),
        ))
    }
}
