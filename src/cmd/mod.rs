//! One module per subcommand: argument parsing and a short loop over library types.

pub mod bench;
pub mod bridge;
pub mod check;
pub mod deposit;
pub mod export;
pub mod field;
pub mod flags;
pub mod gateway;
pub mod graph;
pub mod list;
pub mod probe;
pub mod roles;
pub mod ros2;
pub mod sim;
pub mod sim_args;
pub mod stop;
pub mod sweep;
pub mod tune;
pub mod view;

use std::error::Error;
use std::fmt;
use std::path::Path;

type Cause = Box<dyn Error + Send + Sync + 'static>;

/// Bad input or usage: the process exits with status 2 (clap's convention). It keeps the error
/// it stems from, so the printed chain shows every cause.
#[derive(Debug)]
pub struct BadInput {
    /// What the user reads first; `None`: the cause's own message (the marker is transparent).
    context: Option<String>,
    cause: Option<Cause>,
}

impl fmt::Display for BadInput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.context, &self.cause) {
            (Some(c), _) => f.write_str(c),
            (None, Some(e)) => e.fmt(f),
            (None, None) => Ok(()),
        }
    }
}

impl Error for BadInput {
    fn source(&self) -> Option<&(dyn Error + 'static)> {
        let cause = self.cause.as_deref()?;
        match self.context {
            Some(_) => Some(cause),
            // Transparent: the cause is this error's message; its causes follow.
            None => cause.source(),
        }
    }
}

/// A `BadInput` error with a message and no cause.
pub fn bad(msg: impl Into<String>) -> anyhow::Error {
    anyhow::Error::new(BadInput {
        context: Some(msg.into()),
        cause: None,
    })
}

/// The error `e` marked as bad input: its message, and its causes, unchanged.
pub fn bad_from(e: impl Into<Cause>) -> anyhow::Error {
    anyhow::Error::new(BadInput {
        context: None,
        cause: Some(e.into()),
    })
}

/// The error `e` marked as bad input, after `context` (printed `context: e`).
pub fn bad_in(context: impl Into<String>, e: impl Into<Cause>) -> anyhow::Error {
    anyhow::Error::new(BadInput {
        context: Some(context.into()),
        cause: Some(e.into()),
    })
}

/// The error and its causes on one line, `: `-separated as `{:#}` prints them, leaving out a
/// cause whose text is already on the line (the libraries' messages name their cause).
pub fn one_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if text.is_empty() || line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

/// Reads a TOML file into `T`; any problem is `BadInput` naming the file, line and key.
pub fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| bad_in(format!("{}: cannot read", path.display()), e))?;
    toml::from_str(&text).map_err(|e| bad_in(path.display().to_string(), e))
}

/// The longest time any flag may give, in seconds (about 31.7 years): longer is a mistake, and
/// `Duration` from 1e300 s would overflow.
pub const MAX_SECONDS: f64 = 1e9;

/// A number as a user would write it: `1e300`, not its 301 digits.
pub fn num(v: f64) -> String {
    if v.is_finite() && v.abs() >= 1e6 {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// A positive number of seconds from a flag, or a `BadInput` naming the flag and the value.
pub fn seconds(flag: &str, v: f64) -> anyhow::Result<std::time::Duration> {
    if v > 0.0 {
        seconds_or_zero(flag, v)
    } else {
        Err(bad(format!(
            "--{flag} {}: must be a positive number of seconds (at most {MAX_SECONDS:e})",
            num(v)
        )))
    }
}

/// A number of seconds ≥ 0 from a flag, or a `BadInput` naming the flag and the value.
pub fn seconds_or_zero(flag: &str, v: f64) -> anyhow::Result<std::time::Duration> {
    if v.is_finite() && (0.0..=MAX_SECONDS).contains(&v) {
        Ok(std::time::Duration::from_secs_f64(v))
    } else {
        Err(bad(format!(
            "--{flag} {}: must be a number of seconds from 0 to {MAX_SECONDS:e}",
            num(v)
        )))
    }
}

/// The largest magnitude a numeric flag may give where nothing smaller bounds it (a coordinate
/// in metres, an amount): beyond it the value is a typo, and `f32` would lose every decimal.
pub const MAX_MAGNITUDE: f64 = 1e9;

/// A numeric flag's accepted values: `lo ≤ v ≤ hi`, or `lo < v ≤ hi` when `lo_open`; never NaN
/// or infinite. Its parsers give clap the message (clap prints `invalid value 'V' for
/// '--flag <V>': must be …` and exits with status 2).
#[derive(Clone, Copy, Debug)]
struct Bounds {
    lo: f64,
    hi: f64,
    lo_open: bool,
}

impl Bounds {
    fn check(self, s: &str) -> Result<f64, String> {
        let v: f64 = s
            .trim()
            .parse()
            .map_err(|_| format!("not a number; {}", self.expected()))?;
        let above_lo = if self.lo_open {
            v > self.lo
        } else {
            v >= self.lo
        };
        if v.is_finite() && above_lo && v <= self.hi {
            Ok(v)
        } else {
            Err(self.expected())
        }
    }

    fn expected(self) -> String {
        if self.lo_open {
            format!(
                "must be a number above {}, at most {}",
                num(self.lo),
                num(self.hi)
            )
        } else {
            format!("must be a number from {} to {}", num(self.lo), num(self.hi))
        }
    }

    /// As `f32`: a value that rounds to 0 is refused where 0 is.
    fn check_f32(self, s: &str) -> Result<f32, String> {
        let v = self.check(s)? as f32;
        if self.lo_open && v <= self.lo as f32 {
            return Err(self.expected());
        }
        Ok(v)
    }
}

/// A clap value parser: a finite `f64` from `lo` to `hi`.
pub fn f64_in(lo: f64, hi: f64) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    let b = Bounds {
        lo,
        hi,
        lo_open: false,
    };
    move |s| b.check(s)
}

/// A clap value parser: a finite `f64` above 0, at most `hi`.
pub fn f64_pos(hi: f64) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    let b = Bounds {
        lo: 0.0,
        hi,
        lo_open: true,
    };
    move |s| b.check(s)
}

/// A clap value parser: a finite `f32` from `lo` to `hi`.
pub fn f32_in(lo: f64, hi: f64) -> impl Fn(&str) -> Result<f32, String> + Clone + Send + Sync {
    let b = Bounds {
        lo,
        hi,
        lo_open: false,
    };
    move |s| b.check_f32(s)
}

/// A clap value parser: a finite `f32` above 0, at most `hi`.
pub fn f32_pos(hi: f64) -> impl Fn(&str) -> Result<f32, String> + Clone + Send + Sync {
    let b = Bounds {
        lo: 0.0,
        hi,
        lo_open: true,
    };
    move |s| b.check_f32(s)
}

/// A clap value parser: a positive number of seconds, at most `MAX_SECONDS`.
pub fn secs() -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    f64_pos(MAX_SECONDS)
}

/// A clap value parser: a number of seconds from 0 to `MAX_SECONDS`.
pub fn secs0() -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    f64_in(0.0, MAX_SECONDS)
}

/// A clap value parser: a finite `f32` of magnitude at most `MAX_MAGNITUDE` (a coordinate, an
/// amount, a level).
pub fn f32_any() -> impl Fn(&str) -> Result<f32, String> + Clone + Send + Sync {
    f32_in(-MAX_MAGNITUDE, MAX_MAGNITUDE)
}

/// A clap value parser: a finite `f64` of magnitude at most `MAX_MAGNITUDE`.
pub fn f64_any() -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync {
    f64_in(-MAX_MAGNITUDE, MAX_MAGNITUDE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_input_keeps_its_cause_and_prints_each_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e = bad_in("x.toml: cannot read", io);
        assert!(e.downcast_ref::<BadInput>().is_some());
        assert_eq!(one_line(&e), "x.toml: cannot read: no such file");
        assert!(e
            .chain()
            .nth(1)
            .is_some_and(|c| c.downcast_ref::<std::io::Error>().is_some()));
        // Transparent: the scenario's message (which names what was refused) once, and the
        // refused part behind it in the chain.
        let s = ::roles::scenario::Scenario::parse("name = 'x'\nduration_s = -1\n", "y.toml")
            .unwrap_err();
        let text = s.to_string();
        let e = bad_from(s);
        assert!(e.downcast_ref::<BadInput>().is_some());
        assert_eq!(e.to_string(), text);
        assert_eq!(one_line(&e), text);
        assert_eq!(e.chain().count(), 2, "{e:?}");
    }
}
