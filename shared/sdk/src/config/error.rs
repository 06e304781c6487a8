//! The one error of a launch file: where the bad value came from, the key, and what is allowed.
//! At the bottom of the configuration layer, so that every part of it can report one.

use std::fmt;

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LaunchError {
    /// The file (or `--set KEY=VALUE`) the bad value came from.
    pub origin: String,
    /// The dotted key, when one is to blame.
    pub key: Option<String>,
    pub message: String,
}

impl LaunchError {
    pub fn new(origin: impl Into<String>, key: Option<&str>, message: impl Into<String>) -> Self {
        Self { origin: origin.into(), key: key.map(str::to_owned), message: message.into() }
    }
}

impl fmt::Display for LaunchError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.key {
            Some(key) => write!(f, "{}: key `{}`: {}", self.origin, key, self.message),
            None => write!(f, "{}: {}", self.origin, self.message),
        }
    }
}

impl std::error::Error for LaunchError {}
