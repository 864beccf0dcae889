//! `pheromone __flags` (hidden): every value-taking argument of every subcommand, for the test
//! that feeds each numeric flag bad values (tests/cli.rs), so that no flag added later escapes it.
//!
//! One line per argument: `<subcommand path>\t<--long or NAME>\t<value type>`, the type being
//! the Rust type clap parses into (`f64`, `u32`, …) or `text` for anything else (strings, paths,
//! enumerations).

use std::any::TypeId;

/// The numeric types a flag may parse into, by name.
fn numeric_type(parser: &clap::builder::ValueParser) -> Option<&'static str> {
    let id = parser.type_id();
    let types: [(TypeId, &str); 12] = [
        (TypeId::of::<f64>(), "f64"),
        (TypeId::of::<f32>(), "f32"),
        (TypeId::of::<u8>(), "u8"),
        (TypeId::of::<u16>(), "u16"),
        (TypeId::of::<u32>(), "u32"),
        (TypeId::of::<u64>(), "u64"),
        (TypeId::of::<usize>(), "usize"),
        (TypeId::of::<i8>(), "i8"),
        (TypeId::of::<i16>(), "i16"),
        (TypeId::of::<i32>(), "i32"),
        (TypeId::of::<i64>(), "i64"),
        (TypeId::of::<isize>(), "isize"),
    ];
    types.iter().find(|(t, _)| id == *t).map(|(_, n)| *n)
}

/// The lines of `command` and of its subcommands, depth first.
fn walk(command: &clap::Command, path: &str, out: &mut Vec<String>) {
    for arg in command.get_arguments() {
        if !arg.get_action().takes_values() {
            continue;
        }
        let name = match arg.get_long() {
            Some(long) => format!("--{long}"),
            None => arg.get_id().to_string().to_uppercase(),
        };
        let ty = numeric_type(arg.get_value_parser()).unwrap_or("text");
        out.push(format!("{path}\t{name}\t{ty}"));
    }
    for sub in command.get_subcommands() {
        let sub_path = if path.is_empty() {
            sub.get_name().to_string()
        } else {
            format!("{path} {}", sub.get_name())
        };
        walk(sub, &sub_path, out);
    }
}

/// Prints the lines of `command` (the whole command line interface).
pub fn print(mut command: clap::Command) -> anyhow::Result<()> {
    // Propagates the global arguments to every subcommand.
    command.build();
    let mut lines = Vec::new();
    for sub in command.get_subcommands() {
        walk(sub, sub.get_name(), &mut lines);
    }
    println!("{}", lines.join("\n"));
    Ok(())
}
