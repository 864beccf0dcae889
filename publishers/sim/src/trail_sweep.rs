//! Paper 002's parameter study (`pheromone sweep trail-following`, issue 49 part 4): the
//! antenna robots' settings varied one at a time about the scenario's own — the turn gain, the
//! antenna spacing b, each antenna's field of view and splay, the forward speed K and the
//! normalisation of the readings — each value run on seeds 1..=T by the caller's runner (as
//! processes or in one process), with the mean path error and the turning share of every
//! `[[metrics.paths]]` per run ([`TrailRun`]) and mean ± sd per value ([`TrailPoint`]).
//! The scenario's own value of each parameter is always one of its points (run once, shared).

use std::collections::BTreeMap;

use pheromone_world::scenario::{Overrides, Scenario, ScenarioError};
use serde::Serialize;

use crate::metrics::scenario_metrics;
use crate::recording::Recording;
use crate::sweep_stats::MeanSd;

/// A setting of the antenna robots the study varies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum TrailParam {
    /// ω = k·(P_L − P_R): k (rad/s), `--omega-gain`.
    OmegaGain,
    /// b, the distance between the antennas (m), `--wheel-base`.
    WheelBase,
    /// Each antenna's field of view on the source channel (degrees), `--fov`.
    Fov,
    /// Each antenna turned outward from the heading (degrees), `--splay`.
    Splay,
    /// K of eq. 6, the forward speed (m/s), `--speed`.
    Speed,
    /// The readings' scale (`normalize_max`); 0 = by the larger reading, `--normalize`.
    Normalize,
}

impl TrailParam {
    /// In the order of the CSV and the chart's panels.
    pub const ALL: [TrailParam; 6] = [
        TrailParam::OmegaGain,
        TrailParam::WheelBase,
        TrailParam::Fov,
        TrailParam::Splay,
        TrailParam::Speed,
        TrailParam::Normalize,
    ];

    /// Its flag of `pheromone sweep`.
    pub fn flag(self) -> &'static str {
        match self {
            TrailParam::OmegaGain => "--omega-gain",
            TrailParam::WheelBase => "--wheel-base",
            TrailParam::Fov => "--fov",
            TrailParam::Splay => "--splay",
            TrailParam::Speed => "--speed",
            TrailParam::Normalize => "--normalize",
        }
    }

    /// Its name in the CSV's `param` column (with its unit).
    pub fn name(self) -> &'static str {
        match self {
            TrailParam::OmegaGain => "omega_gain_rad_per_s",
            TrailParam::WheelBase => "wheel_base_m",
            TrailParam::Fov => "fov_deg",
            TrailParam::Splay => "splay_deg",
            TrailParam::Speed => "k_v_m_per_s",
            TrailParam::Normalize => "normalize_max",
        }
    }

    /// The values it may take: (lowest, highest, lowest included).
    fn range(self) -> (f64, f64, bool) {
        match self {
            TrailParam::OmegaGain => (0.0, 100.0, false),
            TrailParam::WheelBase => (0.0, 2.0, false),
            TrailParam::Fov => (0.0, 360.0, false),
            TrailParam::Splay => (0.0, 90.0, true),
            TrailParam::Speed => (0.0, 5.0, false),
            TrailParam::Normalize => (0.0, 1e6, true),
        }
    }

    /// The scenario's own value (its first antenna robot's; `Missing` without one, or for
    /// `--fov`/`--splay` when its channel has no sources).
    pub fn shipped(self, s: &Scenario) -> Result<f64, TrailSweepError> {
        let f = s
            .robots
            .iter()
            .filter_map(|r| r.follower.as_ref())
            .find(|f| f.strategy == pheromone_roles::follower::StrategyKind::Antenna)
            .ok_or(TrailSweepError::Missing(self.flag(), "an antenna robot"))?;
        let a = &f.antenna;
        let sources = || {
            s.field
                .channels
                .get(f.channel as usize)
                .and_then(|c| c.sources)
                .ok_or(TrailSweepError::Missing(self.flag(), "a source channel"))
        };
        Ok(match self {
            TrailParam::OmegaGain => a.omega_gain_rad_per_s,
            TrailParam::WheelBase => decimal(a.wheel_base_m),
            TrailParam::Fov => decimal(sources()?.fov_deg),
            TrailParam::Splay => decimal(sources()?.splay_deg),
            TrailParam::Speed => a.k_v_m_per_s,
            TrailParam::Normalize => a.normalize_max.map_or(0.0, decimal),
        })
    }

    /// `s` with this setting `v` on every antenna robot (and every source channel).
    pub fn apply(self, s: &mut Scenario, v: f64) {
        let v32 = v as f32;
        for f in s.robots.iter_mut().filter_map(|r| r.follower.as_mut()) {
            let a = &mut f.antenna;
            match self {
                TrailParam::OmegaGain => a.omega_gain_rad_per_s = v,
                TrailParam::WheelBase => a.wheel_base_m = v32,
                TrailParam::Speed => a.k_v_m_per_s = v,
                TrailParam::Normalize => a.normalize_max = (v > 0.0).then_some(v32),
                TrailParam::Fov | TrailParam::Splay => {}
            }
        }
        for src in s
            .field
            .channels
            .iter_mut()
            .filter_map(|c| c.sources.as_mut())
        {
            match self {
                TrailParam::Fov => src.fov_deg = v32,
                TrailParam::Splay => src.splay_deg = v32,
                _ => {}
            }
        }
    }

    /// The comma-separated values of its flag (`max` for `--normalize`: by the larger reading,
    /// 0), each in range; sorted, each once.
    pub fn parse(self, text: &str) -> Result<Vec<f64>, TrailSweepError> {
        let err = |reason: String| TrailSweepError::List {
            option: self.flag(),
            value: text.to_string(),
            reason,
        };
        let (lo, hi, lo_ok) = self.range();
        let mut out = Vec::new();
        for item in text.split(',').map(str::trim) {
            let v = if self == TrailParam::Normalize && item == "max" {
                0.0
            } else {
                item.parse::<f64>()
                    .map_err(|_| err(format!("'{item}' is not a number")))?
            };
            let above_lo = if lo_ok { v >= lo } else { v > lo };
            if !(v.is_finite() && above_lo && v <= hi) {
                let open = if lo_ok { "[" } else { "(" };
                return Err(err(format!("{item} is outside {open}{lo}, {hi}]")));
            }
            out.push(v);
        }
        out.sort_by(f64::total_cmp);
        out.dedup();
        Ok(out)
    }
}

/// `x` as the shortest decimal that reads back as it (0.3, not 0.30000001192092896), so a
/// list's `0.3` is the scenario's `0.3`.
fn decimal(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(f64::from(x))
}

/// Paper 002's study as issue 49 ran it by hand (docs/gateway.md), each list with the
/// scenario's value added: what `sweep trail-following` runs when no list is given.
pub fn default_study() -> Vec<(TrailParam, Vec<f64>)> {
    vec![
        (TrailParam::OmegaGain, vec![1.0, 1.5, 6.0, 10.0]),
        (TrailParam::WheelBase, vec![0.1, 0.2, 0.4, 0.5]),
        (TrailParam::Fov, vec![90.0, 120.0, 240.0, 360.0]),
        (TrailParam::Splay, vec![15.0, 30.0, 60.0]),
        (TrailParam::Speed, vec![0.2, 0.6, 0.8]),
        (TrailParam::Normalize, vec![20.0, 40.0, 80.0, 200.0]),
    ]
}

/// A study cannot be planned or one of its runs failed.
#[derive(Debug, thiserror::Error)]
pub enum TrailSweepError<E = std::convert::Infallible> {
    #[error("{option} {value:?}: {reason}")]
    List {
        option: &'static str,
        value: String,
        reason: String,
    },
    #[error("{0}: the scenario has no {1}")]
    Missing(&'static str, &'static str),
    #[error("scenario has no [[metrics.paths]] to measure (try trail-following)")]
    NoPaths,
    #[error("{point}: {source}")]
    Scenario {
        point: String,
        #[source]
        source: Box<ScenarioError>,
    },
    #[error("{point}, seed {seed}: {source}")]
    Run { point: String, seed: u64, source: E },
}

/// One run's figures for one path.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrailRun {
    pub param: TrailParam,
    pub value: f64,
    /// The scenario's own value.
    pub shipped: bool,
    pub seed: u64,
    pub path: String,
    pub mean_path_error_m: Option<f64>,
    pub turning_share: Option<f64>,
}

/// One value of one parameter on one path, over the seeds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrailPoint {
    pub param: TrailParam,
    pub value: f64,
    pub shipped: bool,
    pub path: String,
    pub mean_path_error_m: Option<MeanSd>,
    pub turning_share: Option<MeanSd>,
}

/// The study: every run, every point, the scenario's value of each parameter.
#[derive(Debug, Clone, Serialize)]
pub struct TrailSweep {
    pub scenario: String,
    pub trials: u32,
    /// Each parameter studied and the scenario's value of it.
    pub shipped: BTreeMap<TrailParam, f64>,
    pub runs: Vec<TrailRun>,
    pub points: Vec<TrailPoint>,
    /// Simulations run (the scenario's own point once for all parameters).
    pub simulations: usize,
}

/// The lists of `study` with each parameter's shipped value added (sorted, once), checked
/// against the scenario.
pub fn plan(
    base: &Scenario,
    study: &[(TrailParam, Vec<f64>)],
) -> Result<Vec<(TrailParam, f64, Vec<f64>)>, TrailSweepError> {
    if base.metrics.paths.is_empty() {
        return Err(TrailSweepError::NoPaths);
    }
    study
        .iter()
        .map(|(p, values)| {
            let shipped = p.shipped(base)?;
            let mut v = values.clone();
            v.push(shipped);
            v.sort_by(f64::total_cmp);
            v.dedup();
            Ok((*p, shipped, v))
        })
        .collect()
}

/// Runs the study: for each planned parameter and value, seeds 1..=`trials` by `run` (the
/// caller's mode; its error ends the study), `done` after each simulation.
pub fn run_trail_sweep<E>(
    base: &Scenario,
    planned: &[(TrailParam, f64, Vec<f64>)],
    trials: u32,
    mut run: impl FnMut(&Scenario) -> Result<Recording, E>,
    mut done: impl FnMut(),
) -> Result<TrailSweep, TrailSweepError<E>> {
    let mut cache: Option<Vec<PathFigures>> = None;
    let (mut runs, mut simulations) = (Vec::new(), 0);
    for &(param, shipped, ref values) in planned {
        for &value in values {
            let is_shipped = value == shipped;
            let per_seed = match (&cache, is_shipped) {
                (Some(c), true) => c.clone(),
                _ => {
                    let mut s = base.clone();
                    param.apply(&mut s, value);
                    let point = format!("{} {value}", param.flag());
                    let r = run_seeds(&s, trials, &point, &mut run, &mut done)?;
                    simulations += r.len();
                    if is_shipped {
                        cache = Some(r.clone());
                    }
                    r
                }
            };
            for (i, paths) in per_seed.into_iter().enumerate() {
                for (path, err, turn) in paths {
                    runs.push(TrailRun {
                        param,
                        value,
                        shipped: is_shipped,
                        seed: i as u64 + 1,
                        path,
                        mean_path_error_m: err,
                        turning_share: turn,
                    });
                }
            }
        }
    }
    Ok(TrailSweep {
        scenario: base.name.clone(),
        trials,
        shipped: planned.iter().map(|&(p, v, _)| (p, v)).collect(),
        points: points(&runs),
        runs,
        simulations,
    })
}

type PathFigures = Vec<(String, Option<f64>, Option<f64>)>;

/// `s` on seeds 1..=trials: each path's mean error and turning share per seed.
fn run_seeds<E>(
    s: &Scenario,
    trials: u32,
    point: &str,
    run: &mut impl FnMut(&Scenario) -> Result<Recording, E>,
    done: &mut impl FnMut(),
) -> Result<Vec<PathFigures>, TrailSweepError<E>> {
    let mut out = Vec::new();
    for seed in 1..=u64::from(trials) {
        let mut s = s.clone();
        s.apply(&Overrides {
            seed: Some(seed),
            ..Overrides::default()
        })
        .and_then(|()| s.validate())
        .map_err(|e| TrailSweepError::Scenario {
            point: point.to_string(),
            source: Box::new(e),
        })?;
        let rec = run(&s).map_err(|source| TrailSweepError::Run {
            point: point.to_string(),
            seed,
            source,
        })?;
        let m = scenario_metrics(&s, &rec);
        let (err, turn) = (
            m.mean_path_error_m.unwrap_or_default(),
            m.turning_share.unwrap_or_default(),
        );
        out.push(
            s.metrics
                .paths
                .iter()
                .map(|p| {
                    let e = err.get(&p.name).copied().flatten();
                    let t = turn.get(&p.name).copied().flatten();
                    (p.name.clone(), e, t)
                })
                .collect(),
        );
        done();
    }
    Ok(out)
}

/// Mean ± sd over the seeds of each (parameter, value, path), in the runs' order.
fn points(runs: &[TrailRun]) -> Vec<TrailPoint> {
    let mut out: Vec<TrailPoint> = Vec::new();
    for r in runs {
        if out
            .iter()
            .any(|p| p.param == r.param && p.value == r.value && p.path == r.path)
        {
            continue;
        }
        let same: Vec<&TrailRun> = runs
            .iter()
            .filter(|x| x.param == r.param && x.value == r.value && x.path == r.path)
            .collect();
        let of = |f: fn(&TrailRun) -> Option<f64>| {
            MeanSd::of(&same.iter().filter_map(|x| f(x)).collect::<Vec<_>>())
        };
        out.push(TrailPoint {
            param: r.param,
            value: r.value,
            shipped: r.shipped,
            path: r.path.clone(),
            mean_path_error_m: of(|x| x.mean_path_error_m),
            turning_share: of(|x| x.turning_share),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_are_checked_sorted_and_name_their_flag() {
        assert_eq!(
            TrailParam::Fov.parse("360,90,90").unwrap(),
            vec![90.0, 360.0]
        );
        assert_eq!(
            TrailParam::Normalize.parse("max,20").unwrap(),
            vec![0.0, 20.0]
        );
        let e = TrailParam::Fov.parse("0").unwrap_err().to_string();
        assert!(e.contains("--fov") && e.contains("outside"), "{e}");
        let e = TrailParam::Speed.parse("fast").unwrap_err().to_string();
        assert!(e.contains("--speed") && e.contains("fast"), "{e}");
        assert!(TrailParam::OmegaGain.parse("nan").is_err());
        assert!(TrailParam::Splay.parse("0").is_ok());
    }

    #[test]
    fn the_plan_adds_the_shipped_value_and_apply_sets_it() {
        let base = Scenario::load("trail-following").unwrap();
        let planned = plan(&base, &[(TrailParam::OmegaGain, vec![1.0])]).unwrap();
        let shipped = TrailParam::OmegaGain.shipped(&base).unwrap();
        assert_eq!(planned[0].2, {
            let mut v = vec![1.0, shipped];
            v.sort_by(f64::total_cmp);
            v
        });
        for p in TrailParam::ALL {
            let mut s = base.clone();
            p.apply(&mut s, 7.3);
            assert_eq!(p.shipped(&s).unwrap(), 7.3, "{p:?}");
        }
        let none = Scenario::load("ias-ss").unwrap();
        assert!(plan(&none, &default_study()).is_err());
    }
}
