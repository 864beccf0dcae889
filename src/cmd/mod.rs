//! One module per subcommand: argument parsing and a short loop over library types.

pub mod bench;
pub mod field;
pub mod gateway;
pub mod graph;
pub mod probe;
pub mod roles;
pub mod sim;
pub mod sim_args;
pub mod tune;

use std::fmt;
use std::path::Path;

/// Bad input or usage: the process exits with status 2 (clap's convention).
#[derive(Debug)]
pub struct BadInput(pub String);

impl fmt::Display for BadInput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadInput {}

/// Shorthand for a `BadInput` error.
pub fn bad(msg: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(BadInput(msg.into()))
}

/// Reads a TOML file into `T`; any problem is `BadInput` naming the file, line and key.
pub fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| bad(format!("{}: cannot read: {e}", path.display())))?;
    toml::from_str(&text).map_err(|e| bad(format!("{}: {e}", path.display())))
}

/// A positive number of seconds from a flag, or a `BadInput` naming the flag and the value.
pub fn seconds(flag: &str, v: f64) -> anyhow::Result<std::time::Duration> {
    if v.is_finite() && v > 0.0 {
        Ok(std::time::Duration::from_secs_f64(v))
    } else {
        Err(bad(format!(
            "--{flag} {v}: must be a positive number of seconds"
        )))
    }
}
