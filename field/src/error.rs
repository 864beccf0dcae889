//! Error types of the field crate (thiserror; one enum per operation family).

use std::fmt::Display;

/// A configuration value that cannot be used. Names the setting and the value.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum ConfigError {
    /// The setting `name` has a value that is out of range, not finite, or inconsistent with
    /// another setting; `reason` says which rule it breaks.
    #[error("{name} = {value}: {reason}")]
    Invalid {
        /// The setting, as the user spells it (e.g. `channel 'food' decay_per_s`).
        name: String,
        /// The offending value, formatted.
        value: String,
        /// The rule the value breaks (e.g. `must be finite and ≥ 0`).
        reason: String,
    },
}

impl ConfigError {
    /// A [`ConfigError::Invalid`] from anything that displays (the setting, its value, the rule).
    pub fn invalid(name: impl Display, value: impl Display, reason: impl Display) -> Self {
        Self::Invalid {
            name: name.to_string(),
            value: value.to_string(),
            reason: reason.to_string(),
        }
    }
}
