//! The cross-checks of a scenario before anything starts: the clock, the robots' roles, the
//! scripted deposits (by the field's own checks), starts on the grid, probes, metrics.

use super::{DepositError, Scenario, ScenarioError};

/// The most robots a scenario may have (each is up to four processes in a run as processes).
pub const MAX_ROBOTS: usize = 256;
/// The most landmarks a scenario's world may have.
pub const MAX_LANDMARKS: usize = 100_000;
/// The most `[[deposit]]` entries a scenario may have.
pub const MAX_SCRIPTED_DEPOSITS: usize = 100_000;

impl Scenario {
    /// Cross-checks the parts: sizes, the field clock against the world step, robot ids.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        self.validate_clock()?;
        self.validate_sizes()?;
        self.validate_robot_roles()?;
        self.validate_scripted_deposits()?;
        crate::World::new(self.world.clone(), self.seed).map_err(ScenarioError::World)?;
        self.validate_starts_in_field()?;
        self.validate_active_robots()?;
        let channels = self.field.channels.len() as u32;
        self.validate_mark_walls(channels)?;
        self.validate_probes(channels)?;
        self.validate_snapshot_times()?;
        self.validate_metric_paths()?;
        if let Some(w) = &self.metrics.wrong_area {
            w.validate()?;
        }
        self.validate_follower_channels(channels)?;
        self.validate_mapping()?;
        self.validate_radio()?;
        self.validate_exploration()
    }

    /// The robots whose follower has the antenna strategy (those `sim --remote` runs through
    /// the gateway), by ID.
    pub fn antenna_robots(&self) -> Vec<u32> {
        self.robots
            .iter()
            .filter(|r| {
                self.follower_config(r.id)
                    .is_some_and(|f| f.strategy == pheromone_roles::follower::StrategyKind::Antenna)
            })
            .map(|r| r.id)
            .collect()
    }

    /// `[radio]` in range, with a client on the air for every antenna robot (client = its ID).
    fn validate_radio(&self) -> Result<(), ScenarioError> {
        let Some(r) = &self.radio else {
            return Ok(());
        };
        r.validate()
            .map_err(|e| ScenarioError::value(format!("radio.{}", e.key), e.value, e.expected))?;
        if let Some(top) = self.antenna_robots().into_iter().max() {
            if top >= r.clients {
                return Err(ScenarioError::value(
                    "radio.clients",
                    r.clients.to_string(),
                    "must be more than the highest antenna robot's ID (each is client ID on the air)",
                ));
            }
        }
        Ok(())
    }

    /// What a file can claim, bounded (issue 54): a name without control characters, at most
    /// [`MAX_ROBOTS`] robots (none only with scripted deposits), at most [`MAX_LANDMARKS`] landmarks and [`MAX_SCRIPTED_DEPOSITS`]
    /// scripted deposits, each at a time ≥ 0.
    fn validate_sizes(&self) -> Result<(), ScenarioError> {
        if self.name.is_empty() || self.name.chars().any(char::is_control) {
            return Err(ScenarioError::value(
                "name",
                format!("{:?}", self.name),
                "must be a non-empty name without control characters (NUL, newline…)",
            ));
        }
        let robots = self.world.robots.len();
        if robots > MAX_ROBOTS {
            return Err(ScenarioError::value(
                "world.robots",
                format!("{robots} robots"),
                "must be at most 256 robots",
            ));
        }
        if robots == 0 && self.deposits.is_empty() {
            return Err(ScenarioError::value(
                "world.robots",
                "0 robots and no [[deposit]]",
                "a run needs a robot or a scripted deposit",
            ));
        }
        let landmarks = self.world.landmarks.len();
        if landmarks > MAX_LANDMARKS {
            return Err(ScenarioError::value(
                "world.landmarks",
                format!("{landmarks} landmarks"),
                "must be at most 100000 landmarks",
            ));
        }
        if self.deposits.len() > MAX_SCRIPTED_DEPOSITS {
            return Err(ScenarioError::value(
                "deposit",
                format!("{} scripted deposits", self.deposits.len()),
                "must be at most 100000 [[deposit]] entries",
            ));
        }
        if let Some((i, d)) = self
            .deposits
            .iter()
            .enumerate()
            .find(|(_, d)| !(d.t_s.is_finite() && d.t_s >= 0.0))
        {
            return Err(ScenarioError::NegativeTime {
                key: format!("deposit {}: t_s", i + 1),
                value: d.t_s,
            });
        }
        Ok(())
    }

    /// The field, the duration, and the field's tick against the world's step.
    fn validate_clock(&self) -> Result<(), ScenarioError> {
        self.field.validate().map_err(ScenarioError::Field)?;
        if !(self.duration_s.is_finite() && self.duration_s > 0.0 && self.duration_s <= 1e9) {
            return Err(ScenarioError::value(
                "duration_s",
                self.duration_s,
                "must be > 0 s and at most 1e9 s",
            ));
        }
        let field_dt = 1.0 / self.field.tick_hz as f64;
        if (field_dt - self.world.dt_s).abs() > 1e-6 * self.world.dt_s.max(1e-9) + 1e-9 {
            return Err(ScenarioError::ClockMismatch {
                tick_hz: self.field.tick_hz,
                field_dt,
                world_dt: self.world.dt_s,
            });
        }
        Ok(())
    }

    /// Each robot's roles: a robot of the world, with a valid localizer, depositor, follower.
    fn validate_robot_roles(&self) -> Result<(), ScenarioError> {
        for (i, r) in self.robots.iter().enumerate() {
            if self.robots[..i].iter().any(|q| q.id == r.id) {
                return Err(ScenarioError::DuplicateRobot { robot: r.id });
            }
            if !self.world.robots.iter().any(|w| w.id == r.id) {
                return Err(ScenarioError::NoWorldRobot { robot: r.id });
            }
            let robot = r.id;
            r.localizer
                .validate()
                .map_err(|source| ScenarioError::Localizer { robot, source })?;
            self.validate_filter(r)?;
            if let Some(d) = &r.depositor {
                d.validate()
                    .map_err(|source| ScenarioError::Depositor { robot, source })?;
            }
            if let Some(f) = &r.follower {
                f.validate()
                    .map_err(|source| ScenarioError::Follower { robot, source })?;
            }
        }
        Ok(())
    }

    /// The robot's filter: its settings valid; the loss script only with the EKF; a particle
    /// filter only with the world's laser.
    fn validate_filter(&self, r: &super::RobotRoles) -> Result<(), ScenarioError> {
        use pheromone_roles::localizer::{FilterKind, LocalizerError};
        let robot = r.id;
        let err = |source| ScenarioError::Localizer { robot, source };
        r.ukf.validate().map_err(err)?;
        r.pf.validate().map_err(err)?;
        if let (Some(t), true) = (r.localizer.loss.after_s, r.filter != FilterKind::Ekf) {
            return Err(err(LocalizerError::InvalidConfig {
                field: format!("loss.after_s (filter = {})", r.filter.name()),
                value: t,
                expected: "unset: the loss script is EKF-only (--no-scripted-loss)",
            }));
        }
        if r.filter == FilterKind::Pf && self.world.laser.is_none() {
            return Err(ScenarioError::PfWithoutLaser { robot });
        }
        Ok(())
    }

    /// Each scripted deposit as the field will take it: every message passes the field's own
    /// checks (finite numbers, covariance, channel, grid), so none is refused mid-run.
    fn validate_scripted_deposits(&self) -> Result<(), ScenarioError> {
        let geometry = self.field.geometry();
        for (i, d) in self.deposits.iter().enumerate() {
            let err = |source| ScenarioError::Deposit {
                index: i + 1,
                source,
            };
            for msg in d.messages().map_err(err)? {
                pheromone_field::deposit::prepare(
                    &msg,
                    &geometry,
                    &self.field.channels,
                    &self.field.limits,
                )
                .map_err(|r| err(DepositError::Refused(r)))?;
            }
        }
        Ok(())
    }

    /// Every world robot starts on the field's grid (its deposits and readings would be lost).
    fn validate_starts_in_field(&self) -> Result<(), ScenarioError> {
        let f = &self.field;
        let (x0_m, y0_m) = (f.origin_x_m as f64, f.origin_y_m as f64);
        let x1_m = x0_m + f.width as f64 * f.cell_size_m as f64;
        let y1_m = y0_m + f.height as f64 * f.cell_size_m as f64;
        for r in &self.world.robots {
            let (x_m, y_m) = (r.start.x_m, r.start.y_m);
            if !((x0_m..=x1_m).contains(&x_m) && (y0_m..=y1_m).contains(&y_m)) {
                return Err(ScenarioError::StartOutsideField {
                    robot: r.id,
                    x_m,
                    y_m,
                    x0_m,
                    x1_m,
                    y0_m,
                    y1_m,
                });
            }
        }
        Ok(())
    }

    /// `active_robots`, if given, between 1 and the world's robots.
    fn validate_active_robots(&self) -> Result<(), ScenarioError> {
        if let Some(n) = self.active_robots {
            if n == 0 || n > self.world.robots.len() {
                return Err(ScenarioError::ActiveRobots {
                    n,
                    robots: self.world.robots.len(),
                });
            }
        }
        Ok(())
    }

    /// `mark_walls`, if given: a channel of the field's `channels` and a spacing > 0.
    fn validate_mark_walls(&self, channels: u32) -> Result<(), ScenarioError> {
        if let Some(m) = &self.mark_walls {
            if m.channel >= channels {
                return Err(ScenarioError::Channel {
                    key: "mark_walls.channel".into(),
                    channel: m.channel,
                    channels,
                });
            }
            if !(m.spacing_m.is_finite() && m.spacing_m > 0.0) {
                return Err(ScenarioError::value(
                    "mark_walls.spacing_m",
                    m.spacing_m,
                    "must be > 0",
                ));
            }
        }
        Ok(())
    }

    /// Each probe: a channel of the field's `channels`, and finite times ≥ 0.
    fn validate_probes(&self, channels: u32) -> Result<(), ScenarioError> {
        for (i, p) in self.probes.iter().enumerate() {
            if p.channel >= channels {
                return Err(ScenarioError::Channel {
                    key: format!("probe {}: channel", i + 1),
                    channel: p.channel,
                    channels,
                });
            }
            if let Some(t) = p.times_s.iter().find(|t| !(t.is_finite() && **t >= 0.0)) {
                return Err(ScenarioError::NegativeTime {
                    key: format!("probe {}: times_s", i + 1),
                    value: *t,
                });
            }
        }
        Ok(())
    }

    /// `snapshots_s`: finite times ≥ 0.
    fn validate_snapshot_times(&self) -> Result<(), ScenarioError> {
        if let Some(t) = self
            .snapshots_s
            .iter()
            .find(|t| !(t.is_finite() && **t >= 0.0))
        {
            return Err(ScenarioError::NegativeTime {
                key: "snapshots_s".into(),
                value: *t,
            });
        }
        Ok(())
    }

    /// `metrics.paths`: at least 2 points each, and positive `every_s` and `over_s`.
    fn validate_metric_paths(&self) -> Result<(), ScenarioError> {
        for p in &self.metrics.paths {
            if p.points.len() < 2 {
                return Err(ScenarioError::Metric {
                    metric: format!("metrics.paths '{}'", p.name),
                    reason: "needs at least 2 points".into(),
                });
            }
            if !(p.every_s > 0.0 && p.over_s > 0.0) {
                return Err(ScenarioError::Metric {
                    metric: format!("metrics.paths '{}'", p.name),
                    reason: format!(
                        "every_s = {} and over_s = {} must be > 0",
                        p.every_s, p.over_s
                    ),
                });
            }
        }
        Ok(())
    }

    /// Each depositor's channel, follower's channel and explorer (`after_loss`) channel: one of
    /// the field's `channels`.
    fn validate_follower_channels(&self, channels: u32) -> Result<(), ScenarioError> {
        for r in &self.robots {
            match &r.depositor {
                Some(d) if d.channel >= channels => {
                    return Err(ScenarioError::Channel {
                        key: format!("robot {}: depositor channel", r.id),
                        channel: d.channel,
                        channels,
                    })
                }
                _ => {}
            }
            let Some(f) = &r.follower else { continue };
            let explorer = f.after_loss.as_ref().and_then(|a| a.channel);
            for (key, ch) in [
                ("channel", Some(f.channel)),
                ("after_loss.channel", explorer),
            ] {
                match ch {
                    Some(c) if c >= channels => {
                        return Err(ScenarioError::Channel {
                            key: format!("robot {}: follower {key}", r.id),
                            channel: c,
                            channels,
                        })
                    }
                    _ => {}
                }
            }
        }
        Ok(())
    }

    /// `metrics.exploration`, if given: a non-empty grid of sectors.
    fn validate_exploration(&self) -> Result<(), ScenarioError> {
        if let Some(e) = &self.metrics.exploration {
            if e.cols == 0 || e.rows == 0 || e.max_m[0] <= e.min_m[0] || e.max_m[1] <= e.min_m[1] {
                return Err(ScenarioError::Metric {
                    metric: "metrics.exploration".into(),
                    reason: format!("{e:?} is an empty grid of sectors"),
                });
            }
        }
        Ok(())
    }
}
