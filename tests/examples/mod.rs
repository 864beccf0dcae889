//! The Rust examples as a new user runs them (issue 51): `pheromone field`, then the `deposit`
//! and `read` examples (`examples/rust`, package `pheromone-examples`) as processes of their own;
//! the reader must show the depositor's trail (its peak on the depositor's 3 m circle, a value at
//! the circle's start) soon after both start. `cargo test --workspace` builds the examples (or
//! `cargo build -p pheromone-examples --examples`), as `cargo run -p pheromone-examples --example
//! read` does for a user, into `target/<profile>/examples/`.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use super::harness::*;

/// An example's process, killed (SIGTERM, as Ctrl-C would stop it) and reaped on drop.
struct Example {
    child: Child,
    lines: mpsc::Receiver<String>,
}

impl Example {
    fn start(name: &str, field: &str) -> Self {
        let path = bin()
            .parent()
            .expect("target dir")
            .join("examples")
            .join(name);
        assert!(
            path.exists(),
            "{} is missing: `cargo test --workspace` builds the examples (or run \
             `cargo build -p pheromone-examples --examples`)",
            path.display()
        );
        let mut child = Command::new(&path)
            .arg(field)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| panic!("start {}: {e}", path.display()));
        let out = child.stdout.take().expect("stdout");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self { child, lines }
    }
}

impl Drop for Example {
    fn drop(&mut self) {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(self.child.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
        let _ = self.child.wait();
    }
}

/// (peak, x, y, start) from a line of the read example, if it is a peak line.
fn parse_read_line(line: &str) -> Option<(f32, f32, f32, f32)> {
    let rest = line.split("peak").nth(1)?;
    let (peak, rest) = rest.trim_start().split_once(" at (")?;
    let (xy, rest) = rest.split_once(")")?;
    let (x, y) = xy.split_once(',')?;
    let start = rest.split(")").nth(2)?.split_whitespace().next()?;
    Some((
        peak.trim().parse().ok()?,
        x.trim().parse().ok()?,
        y.trim().parse().ok()?,
        start.parse().ok()?,
    ))
}

#[test]
fn the_read_example_shows_where_the_deposit_example_deposits() {
    let name = unique("examples");
    // The default field's grid: 25.6 m square, centre (12.8, 12.8).
    let _field = Proc::spawn(&Cmd::field(&name).duration(120).argv());
    let reader = Example::start("read", &name);
    let _depositor = Example::start("deposit", &name);
    let mut seen = Vec::new();
    let (peak, x, y, start) = eventually(
        Duration::from_secs(60),
        "the trail in read's output",
        || {
            while let Ok(line) = reader.lines.try_recv() {
                seen.push(line);
            }
            seen.iter()
                .rev()
                .filter_map(|l| parse_read_line(l))
                .find(|&(_, x, y, start)| {
                    let r = ((x - 12.8).powi(2) + (y - 12.8).powi(2)).sqrt();
                    (2.5..=3.5).contains(&r) && start > 0.0
                })
        },
    );
    assert!(peak > 0.0, "peak {peak} at ({x}, {y}), start {start}");
}

#[test]
fn a_read_line_parses() {
    let line = "t =    1.50 s  peak   54.552 at (15.80, 12.80) m, ∇P = (  -1.00,    0.00)  \
                start (15.8, 12.8)   54.552  deposits applied 3";
    assert_eq!(parse_read_line(line), Some((54.552, 15.8, 12.8, 54.552)));
    assert_eq!(parse_read_line("t = 0.50 s  the field is empty"), None);
}

/// The README's Rust snippet is `examples/rust/readme.rs` below its `//!` comment, so that it
/// compiles (`cargo test --workspace` and clippy build the examples) and is a whole program
/// (issue 51).
#[test]
fn the_readmes_rust_snippet_is_the_readme_example() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).expect("README.md");
    let snippet = readme
        .split("```rust\n")
        .nth(1)
        .and_then(|s| s.split("```").next())
        .expect("a ```rust block in README.md");
    let example =
        std::fs::read_to_string(root.join("examples/rust/readme.rs")).expect("the example");
    let body: String = example
        .lines()
        .skip_while(|l| l.starts_with("//!") || l.is_empty())
        .map(|l| format!("{l}\n"))
        .collect();
    assert_eq!(
        snippet, body,
        "README.md's ```rust block is not examples/rust/readme.rs"
    );
}
