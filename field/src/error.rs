//! Error types of the field crate (thiserror; one enum per operation family).

use std::fmt::Display;

/// A configuration value that cannot be used. Names the setting and the value.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum ConfigError {
    #[error("{name} = {value}: {reason}")]
    Invalid {
        name: String,
        value: String,
        reason: String,
    },
}

impl ConfigError {
    pub fn invalid(name: impl Display, value: impl Display, reason: impl Display) -> Self {
        Self::Invalid {
            name: name.to_string(),
            value: value.to_string(),
            reason: reason.to_string(),
        }
    }
}
