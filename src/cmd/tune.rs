//! `pheromone tune`: paper 000 eqs. 23 and 26.

use clap::{Args, Subcommand};

use super::{bad, bad_from};

#[derive(Args)]
pub struct TuneArgs {
    #[command(subcommand)]
    what: TuneWhat,
}

#[derive(Subcommand)]
enum TuneWhat {
    /// The evaporation rate K (1/s) that takes P0 down to P_tm in t_m seconds (eq. 23).
    K {
        /// Initial pheromone level P0.
        #[arg(long, value_parser = super::f64_any())]
        p0: f64,
        /// Level P_tm reached after t_m seconds.
        #[arg(long, value_parser = super::f64_any())]
        ptm: f64,
        /// Time t_m in seconds.
        #[arg(long, value_parser = super::secs())]
        tm: f64,
        /// Ambient pheromone level Pa.
        #[arg(long, value_parser = super::f64_any(), default_value_t = 0.0)]
        pa: f64,
        /// Print one JSON object `{"k_per_s": …}` on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Time (s) for P0 to fall to a threshold with rate K (eq. 26); give --level T or --delta δ
    /// (T = δ·P0).
    Threshold {
        /// Initial pheromone level P0.
        #[arg(long, value_parser = super::f64_any())]
        p0: f64,
        /// Evaporation rate K (1/s).
        #[arg(long, value_parser = super::f64_any())]
        k: f64,
        /// Threshold level T.
        #[arg(long, value_parser = super::f64_any(), conflicts_with = "delta", required_unless_present = "delta")]
        level: Option<f64>,
        /// Threshold as a fraction of P0 (T = δ·P0).
        #[arg(long, value_parser = super::f64_any())]
        delta: Option<f64>,
        /// Ambient pheromone level Pa.
        #[arg(long, value_parser = super::f64_any(), default_value_t = 0.0)]
        pa: f64,
        /// Print one JSON object `{"time_to_threshold_s": …}` on stdout.
        #[arg(long)]
        json: bool,
    },
}

pub fn run(args: TuneArgs) -> anyhow::Result<()> {
    match args.what {
        TuneWhat::K {
            p0,
            ptm,
            tm,
            pa,
            json,
        } => {
            let k = pheromone_field::tune::k_per_s(p0, ptm, tm, pa).map_err(bad_from)?;
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "k_per_s": k, "p0": p0, "ptm": ptm, "tm_s": tm, "pa": pa })
                );
            } else {
                println!("K = {k:.6} per second: P0 = {p0} falls to {ptm} in {tm} s with ambient Pa = {pa}.");
            }
        }
        TuneWhat::Threshold {
            p0,
            k,
            level,
            delta,
            pa,
            json,
        } => {
            let level = match (level, delta) {
                (Some(l), _) => l,
                (None, Some(d)) => d * p0,
                (None, None) => return Err(bad("give --level or --delta")),
            };
            let t =
                pheromone_field::tune::time_to_threshold_s(p0, k, level, pa).map_err(bad_from)?;
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "time_to_threshold_s": t, "p0": p0, "k_per_s": k, "level": level, "pa": pa })
                );
            } else {
                println!("P0 = {p0} falls to {level} in {t:.1} s with K = {k} per second and ambient Pa = {pa}.");
            }
        }
    }
    Ok(())
}
