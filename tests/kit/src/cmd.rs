//! [`Cmd`]: the argv of one `pheromone` command, built by subcommand and option instead of
//! spelled out as a vector of strings in every test.

use std::fmt::Display;

/// The arguments of one `pheromone` command line (without the program).
///
/// ```
/// use pheromone_testkit::Cmd;
/// let field = Cmd::field("f1").grid(64, 64).tick_hz(50).json();
/// assert_eq!(
///     field.argv(),
///     ["field", "--name", "f1", "--width", "64", "--height", "64", "--tick-hz", "50", "--json"]
/// );
/// let deposit = Cmd::deposit("f1").at(6.4, 6.4).amount(0.5).opt("--cov", "0.01,0,0.01");
/// assert_eq!(deposit.argv()[3..7], ["--x", "6.4", "--y", "6.4"]);
/// ```
///
/// Values are written with `Display`, so `0.02`, `"0.02"` and `50` give the strings a test would
/// have typed. Pass [`Cmd::argv`] wherever a `&[&str]` is taken.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Cmd {
    args: Vec<String>,
}

impl Cmd {
    /// `pheromone SUBCOMMAND`.
    pub fn new(subcommand: &str) -> Self {
        Self {
            args: vec![subcommand.to_string()],
        }
    }

    /// `pheromone field --name NAME`.
    pub fn field(name: &str) -> Self {
        Self::new("field").opt("--name", name)
    }

    /// `pheromone deposit --field FIELD`.
    pub fn deposit(field: &str) -> Self {
        Self::new("deposit").opt("--field", field)
    }

    /// `pheromone probe --field FIELD`.
    pub fn probe(field: &str) -> Self {
        Self::new("probe").opt("--field", field)
    }

    /// A bare argument: a flag without a value, or a positional argument.
    pub fn arg(mut self, arg: impl Display) -> Self {
        self.args.push(arg.to_string());
        self
    }

    /// Bare arguments, in order.
    pub fn args<I: IntoIterator<Item = S>, S: Display>(mut self, args: I) -> Self {
        self.args.extend(args.into_iter().map(|a| a.to_string()));
        self
    }

    /// An option and its value: `FLAG VALUE`.
    pub fn opt(self, flag: &str, value: impl Display) -> Self {
        self.arg(flag).arg(value)
    }

    /// `--width W --height H` (cells).
    pub fn grid(self, width: impl Display, height: impl Display) -> Self {
        self.opt("--width", width).opt("--height", height)
    }

    /// `--cell-size M` (metres).
    pub fn cell_size(self, m: impl Display) -> Self {
        self.opt("--cell-size", m)
    }

    /// `--model NAME` (evaporation model).
    pub fn model(self, name: &str) -> Self {
        self.opt("--model", name)
    }

    /// `--tick-hz HZ`.
    pub fn tick_hz(self, hz: impl Display) -> Self {
        self.opt("--tick-hz", hz)
    }

    /// `--duration S` (seconds).
    pub fn duration(self, s: impl Display) -> Self {
        self.opt("--duration", s)
    }

    /// `--ticks N`.
    pub fn ticks(self, n: impl Display) -> Self {
        self.opt("--ticks", n)
    }

    /// `--x X --y Y` (metres): where a deposit or a probe goes.
    pub fn at(self, x: impl Display, y: impl Display) -> Self {
        self.opt("--x", x).opt("--y", y)
    }

    /// `--tau A` (a deposit's τ; the tests that spell it `--amount` check its alias).
    pub fn amount(self, a: impl Display) -> Self {
        self.opt("--tau", a)
    }

    /// `--timeout S` (seconds).
    pub fn timeout(self, s: impl Display) -> Self {
        self.opt("--timeout", s)
    }

    /// `--json`: one JSON object on stdout.
    pub fn json(self) -> Self {
        self.arg("--json")
    }

    /// The arguments, borrowed (for functions that take `&[&str]`).
    pub fn argv(&self) -> Vec<&str> {
        self.args.iter().map(String::as_str).collect()
    }

    /// The arguments, owned.
    pub fn into_args(self) -> Vec<String> {
        self.args
    }
}
