//! One module per subcommand: argument parsing and a short loop over library types.

#[cfg(feature = "bench")]
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
pub mod out;
pub mod probe;
pub mod roles;
pub mod ros2;
pub mod rt;
pub mod sim;
pub mod sim_args;
pub mod sim_filters;
pub mod sim_run;
pub mod stop;
pub mod sweep;
pub mod sweep_trail;
pub mod tune;
pub mod view;
pub mod zenoh_args;

/// `pheromone bench` in a build without the feature `bench` (its crate and the C ABI it measures
/// were compiled last before the binary in a cold release build; docs/building.md): the
/// subcommand says how to get it.
#[cfg(not(feature = "bench"))]
pub mod bench {
    /// Takes any arguments: the real ones are in a build with `--features bench`.
    #[derive(clap::Args)]
    pub struct BenchArgs {
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, hide = true)]
        args: Vec<std::ffi::OsString>,
    }

    pub fn run(_: BenchArgs) -> anyhow::Result<()> {
        Err(super::bad(
            "`pheromone bench` is not in this build: build with `--features bench` (or `zenoh`), \
             e.g. `cargo run --release --features bench -- bench`",
        ))
    }
}

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

/// Whether `e` is bad input (exit status 2): a [`BadInput`], or a field, robot or domain name
/// that breaks the naming rules, wherever it was found (an attach, a start).
pub fn is_bad_input(e: &anyhow::Error) -> bool {
    use pheromone_field::shm::{AttachError, NameError, StartError};
    e.chain().any(|c| {
        c.is::<BadInput>()
            || matches!(c.downcast_ref(), Some(NameError::Invalid { .. }))
            || matches!(
                c.downcast_ref(),
                Some(AttachError::Name(NameError::Invalid { .. }))
            )
            || matches!(
                c.downcast_ref(),
                Some(StartError::Name(NameError::Invalid { .. }))
            )
            || matches!(
                c.downcast_ref(),
                Some(pheromone_sim::processes::ProcessRunError::HostLimit { .. })
            )
    })
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
    let text =
        pheromone_field::infile::read_text_bounded(path, pheromone_field::infile::MAX_TEXT_BYTES)
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
/// or infinite. As a clap value parser it refuses anything else with `--flag VALUE: must be …`
/// (clap exits with status 2).
#[derive(Clone, Copy, Debug)]
pub struct Bounds {
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
}

/// The clap error of flag `arg` given `value`: `--flag VALUE: reason` (exit status 2).
fn flag_error(
    cmd: &clap::Command,
    arg: Option<&clap::Arg>,
    value: &str,
    reason: &str,
) -> clap::Error {
    let flag = arg
        .and_then(clap::Arg::get_long)
        .map_or_else(|| "value".to_string(), |l| format!("--{l}"));
    clap::Error::raw(
        clap::error::ErrorKind::ValueValidation,
        format!("{flag} {value}: {reason}\n"),
    )
    .with_cmd(cmd)
}

/// A bounded real flag, parsed as `f64` or `f32` (`T`).
#[derive(Clone, Copy, Debug)]
pub struct Real<T>(Bounds, std::marker::PhantomData<T>);

/// A number a flag may parse into.
pub trait FlagNumber: Copy + Send + Sync + 'static {
    /// `v` as `Self`, if it keeps its sign (an `f32` rounding 1e-50 to 0 does not).
    fn from_f64(v: f64) -> Self;
    fn is_zero(self) -> bool;
}

impl FlagNumber for f64 {
    fn from_f64(v: f64) -> Self {
        v
    }
    fn is_zero(self) -> bool {
        self == 0.0
    }
}

impl FlagNumber for f32 {
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn is_zero(self) -> bool {
        self == 0.0
    }
}

impl<T: FlagNumber + Clone> clap::builder::TypedValueParser for Real<T> {
    type Value = T;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<T, clap::Error> {
        let text = value.to_string_lossy();
        let v = self
            .0
            .check(&text)
            .map_err(|reason| flag_error(cmd, arg, &text, &reason))?;
        let t = T::from_f64(v);
        if self.0.lo_open && self.0.lo == 0.0 && t.is_zero() {
            return Err(flag_error(cmd, arg, &text, &self.0.expected()));
        }
        Ok(t)
    }
}

/// A bounded whole-number flag, parsed as `T`.
#[derive(Clone, Copy, Debug)]
pub struct Int<T> {
    lo: i128,
    hi: i128,
    ty: std::marker::PhantomData<T>,
}

impl<T> clap::builder::TypedValueParser for Int<T>
where
    T: TryFrom<i128> + Clone + Send + Sync + 'static,
{
    type Value = T;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<T, clap::Error> {
        let text = value.to_string_lossy();
        let reason = format!(
            "must be between {} and {} (a whole number)",
            self.lo, self.hi
        );
        text.trim()
            .parse::<i128>()
            .ok()
            .filter(|v| (self.lo..=self.hi).contains(v))
            .and_then(|v| T::try_from(v).ok())
            .ok_or_else(|| flag_error(cmd, arg, &text, &reason))
    }
}

/// A clap value parser: a whole number from `lo` to `hi`, as `T`.
pub fn int<T>(lo: i128, hi: i128) -> Int<T> {
    Int {
        lo,
        hi,
        ty: std::marker::PhantomData,
    }
}

const fn real<T>(lo: f64, hi: f64, lo_open: bool) -> Real<T> {
    Real(Bounds { lo, hi, lo_open }, std::marker::PhantomData)
}

/// A clap value parser: a finite `f64` from `lo` to `hi`.
pub fn f64_in(lo: f64, hi: f64) -> Real<f64> {
    real(lo, hi, false)
}

/// A clap value parser: a finite `f64` above 0, at most `hi`.
pub fn f64_pos(hi: f64) -> Real<f64> {
    real(0.0, hi, true)
}

/// A clap value parser: a finite `f32` from `lo` to `hi`.
pub fn f32_in(lo: f64, hi: f64) -> Real<f32> {
    real(lo, hi, false)
}

/// A clap value parser: a finite `f32` above 0, at most `hi` (a value that rounds to 0 is
/// refused).
pub fn f32_pos(hi: f64) -> Real<f32> {
    real(0.0, hi, true)
}

/// A clap value parser: a positive number of seconds, at most `MAX_SECONDS`.
pub fn secs() -> Real<f64> {
    f64_pos(MAX_SECONDS)
}

/// A clap value parser: a number of seconds from 0 to `MAX_SECONDS`.
pub fn secs0() -> Real<f64> {
    f64_in(0.0, MAX_SECONDS)
}

/// A clap value parser: a finite `f32` of magnitude at most `MAX_MAGNITUDE` (a coordinate, an
/// amount, a level).
pub fn f32_any() -> Real<f32> {
    f32_in(-MAX_MAGNITUDE, MAX_MAGNITUDE)
}

/// A clap value parser: a finite `f64` of magnitude at most `MAX_MAGNITUDE`.
pub fn f64_any() -> Real<f64> {
    f64_in(-MAX_MAGNITUDE, MAX_MAGNITUDE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn number_flags_name_the_flag_and_the_value_and_keep_their_bounds() {
        let parse = |parser: clap::builder::ValueParser, value: &str| {
            clap::Command::new("t")
                .arg(clap::Arg::new("x").long("x").value_parser(parser))
                .try_get_matches_from(["t", &format!("--x={value}")])
                .map(|_| ())
                .map_err(|e| (e.kind(), e.to_string()))
        };
        // 1e-50 is above 0 as f64 but 0 as f32: refused where 0 is.
        let e = parse(f32_pos(1.0).into(), "1e-50").unwrap_err();
        assert_eq!(e.0, clap::error::ErrorKind::ValueValidation);
        assert!(
            e.1.contains("--x 1e-50: must be a number above 0, at most 1"),
            "{}",
            e.1
        );
        assert!(parse(f32_pos(1.0).into(), "1").is_ok());
        assert!(parse(secs0().into(), "0").is_ok());
        for bad in ["nan", "inf", "-1", "1e300", "", "junk"] {
            let e = parse(secs0().into(), bad).unwrap_err();
            assert!(e.1.contains(&format!("--x {bad}:")), "{}", e.1);
        }
        let e = parse(int::<u32>(1, 99).into(), "100").unwrap_err();
        assert!(e.1.contains("--x 100: must be between 1 and 99"), "{}", e.1);
        // Beyond the type, though within the bounds given: refused, not wrapped.
        assert!(parse(int::<u8>(0, 1000).into(), "256").is_err());
        assert!(parse(int::<u8>(0, 1000).into(), "255").is_ok());
        assert!(parse(int::<usize>(0, 9).into(), "1.5").is_err());
    }

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
        let s =
            ::pheromone_world::scenario::Scenario::parse("name = 'x'\nduration_s = -1\n", "y.toml")
                .unwrap_err();
        let text = s.to_string();
        let e = bad_from(s);
        assert!(e.downcast_ref::<BadInput>().is_some());
        assert_eq!(e.to_string(), text);
        assert_eq!(one_line(&e), text);
        assert_eq!(e.chain().count(), 2, "{e:?}");
    }
}
