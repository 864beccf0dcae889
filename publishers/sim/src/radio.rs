//! `metrics.radio` of a `sim --remote` run with `[radio]` (or `--clients N`): what seed 002's
//! shared air ([`pheromone_roles::radio`]) did to the thin clients' requests over the run's
//! steps. The air is a pure function of its configuration, the control period (the world's
//! step) and the scenario's seed, so these are the outcomes each remote robot saw (its
//! `processes[…].summary.radio` counts the same).

use std::collections::BTreeMap;

use pheromone_roles::radio::{RadioConfig, SharedAir};
use pheromone_world::scenario::Scenario;
use serde::Serialize;

/// One client's share.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ClientRadio {
    pub sent: u64,
    pub delivered: u64,
    /// Delivered / sent.
    pub delivery_rate: f64,
    /// Mean latency of the delivered requests (s): from the request's ready time to the end
    /// of its reply.
    pub mean_latency_s: Option<f64>,
}

/// The air over a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RadioMetrics {
    pub config: RadioConfig,
    /// Control periods (the run's steps).
    pub periods: u64,
    /// Over every client: requests sent, delivered, their rate and mean latency.
    pub all: ClientRadio,
    /// The robots' clients (client = robot ID), by robot ID.
    pub robots: BTreeMap<u32, ClientRadio>,
    /// Frames (requests and replies) that overlapped another, and all frames, until the last
    /// period's requests were resolved.
    pub collided_frames: u64,
    pub frames: u64,
    /// Frames lost to `loss_probability`.
    pub lost_frames: u64,
    /// Times a client heard the channel busy and backed off.
    pub deferrals: u64,
}

#[derive(Default)]
struct Tally {
    sent: u64,
    delivered: u64,
    latency_sum_ns: u64,
}

impl Tally {
    fn result(&self) -> ClientRadio {
        ClientRadio {
            sent: self.sent,
            delivered: self.delivered,
            delivery_rate: if self.sent == 0 {
                1.0
            } else {
                self.delivered as f64 / self.sent as f64
            },
            mean_latency_s: (self.delivered > 0)
                .then(|| self.latency_sum_ns as f64 / self.delivered as f64 / 1e9),
        }
    }
}

/// The air of the scenario's `[radio]` over `steps` control periods; `None` without `[radio]`
/// (or with a configuration the scenario's validation would refuse).
pub fn radio_metrics(scenario: &Scenario, robots: &[u32], steps: u64) -> Option<RadioMetrics> {
    let config = scenario.radio.as_ref()?;
    let mut air = SharedAir::new(config, scenario.world.dt_s, scenario.seed).ok()?;
    let mut all = Tally::default();
    let mut per: BTreeMap<u32, Tally> = robots.iter().map(|&r| (r, Tally::default())).collect();
    for _ in 0..steps {
        for (client, e) in air.next_period().iter().enumerate() {
            let add = |t: &mut Tally| {
                t.sent += 1;
                if e.delivered {
                    t.delivered += 1;
                    t.latency_sum_ns += e.latency_ns;
                }
            };
            add(&mut all);
            if let Some(t) = per.get_mut(&(client as u32)) {
                add(t);
            }
        }
    }
    let s = air.stats();
    Some(RadioMetrics {
        config: config.clone(),
        periods: steps,
        all: all.result(),
        robots: per.iter().map(|(&r, t)| (r, t.result())).collect(),
        collided_frames: s.collided_frames,
        frames: s.frames,
        lost_frames: s.lost_frames,
        deferrals: s.deferrals,
    })
}
