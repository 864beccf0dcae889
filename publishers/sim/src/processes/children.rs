//! A run's children: their command lines, spawning the field, world, roles and gateway in order, waiting for the observer to join, and their reports.

use super::*;
use pheromone_field::shm::AttachError;

/// `v` as owned arguments.
pub(super) fn args(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

/// The names a run's children are started with, and their command lines.
pub(super) struct ChildArgs {
    pub(super) field: String,
    pub(super) world: String,
    /// The scenario file's path.
    pub(super) scenario: String,
    /// Robot id → the file of its part of the scenario (its localizer, depositor, follower).
    pub(super) parts: std::collections::BTreeMap<u32, String>,
    pub(super) realtime: bool,
    /// Real-time scheduling arguments of the control-loop children.
    pub(super) rt: Vec<String>,
}

impl ChildArgs {
    /// A role's arguments: the scenario (a robot's own part, but for a mapper, which needs its
    /// peers), world and field, the robot, `--realtime`.
    pub(super) fn role(&self, name: &str, robot: Option<u32>) -> Vec<String> {
        let scenario = robot
            .filter(|_| name != "mapper")
            .and_then(|r| self.parts.get(&r))
            .unwrap_or(&self.scenario);
        let mut v = args(&[
            name,
            "--scenario",
            scenario,
            "--world",
            &self.world,
            "--field",
            &self.field,
            "--json",
        ]);
        if let Some(r) = robot {
            v.extend(args(&["--robot", &r.to_string()]));
        }
        if self.realtime {
            v.push("--realtime".to_string());
        }
        v.extend(self.rt.iter().cloned());
        v
    }

    /// The field's arguments: clocked by the world.
    pub(super) fn field(&self) -> Vec<String> {
        let mut v = args(&[
            "field",
            "--name",
            &self.field,
            "--scenario",
            &self.scenario,
            "--clock",
            &self.world,
            "--json",
        ]);
        v.extend(self.rt.iter().cloned());
        v
    }

    /// The view's arguments, listening on `listen`.
    pub(super) fn view(&self, listen: &str) -> Vec<String> {
        args(&[
            "view",
            "--field",
            &self.field,
            "--world",
            &self.world,
            "--listen",
            listen,
            "--scenario",
            &self.scenario,
        ])
    }

    /// The ROS 2 bridge's arguments: the field and the robots `robots`, connecting to `connect`.
    pub(super) fn ros2(&self, connect: &str, robots: &[u32]) -> Vec<String> {
        let ids: Vec<String> = robots.iter().map(u32::to_string).collect();
        let mut v = args(&[
            "ros2",
            "--field",
            &self.field,
            "--world",
            &self.world,
            "--connect",
            connect,
            "--json",
        ]);
        if !ids.is_empty() {
            v.extend(args(&["--robots", &ids.join(",")]));
        }
        v
    }

    /// The gateway's arguments: UDP loopback on any port, printing its address.
    pub(super) fn gateway(&self, attach_timeout: Duration) -> Vec<String> {
        let mut v = args(&[
            "gateway",
            "--field",
            &self.field,
            "--udp",
            "127.0.0.1:0",
            "--rate-hz",
            "0",
            "--attach-timeout",
            &attach_timeout.as_secs_f64().to_string(),
            "--print-address",
            "--json",
        ]);
        v.extend(self.rt.iter().cloned());
        v
    }

    /// The world's arguments: in lockstep it waits for the observer and the mappers.
    pub(super) fn world(&self, attach_timeout: Duration, stall_timeout: Duration) -> Vec<String> {
        let mut world_args = self.role("world", None);
        if !self.realtime {
            world_args.extend(args(&[
                "--observed",
                "--mapped",
                "--attach-timeout",
                &attach_timeout.as_secs_f64().to_string(),
                "--stall-timeout",
                &stall_timeout.as_secs_f64().to_string(),
            ]));
        }
        world_args
    }
}

/// What the waits of a run's start share: the observer's node, when the first process started,
/// and how long every process may take to join.
pub(super) struct RunStart<'a> {
    pub(super) node: &'a iceoryx2::node::Node<pheromone_field::shm::Svc>,
    pub(super) started: Instant,
    pub(super) attach_timeout: Duration,
}

/// The children of a run, by role.
pub(super) struct Children {
    pub(super) field: ChildId,
    /// `--remote`: the gateway and the address it serves.
    pub(super) gateway: Option<(ChildId, String)>,
    /// Localizers, depositors and followers, robot by robot.
    pub(super) roles: Vec<ChildId>,
    /// The followers that read the field through the gateway.
    pub(super) remote_ids: Vec<ChildId>,
    pub(super) mappers: Vec<ChildId>,
    pub(super) world: ChildId,
}

impl Children {
    /// Starts the field, the view, the gateway, each robot's roles, the mappers and the world.
    pub(super) fn spawn(
        scenario: &Scenario,
        o: &ProcessRunOptions<'_>,
        a: &ChildArgs,
        start: &RunStart<'_>,
        sup: &mut Supervisor,
    ) -> Result<Self, ProcessRunError> {
        let field = sup.spawn(ChildSpec::new("field", None, a.field()))?;
        // The view is no lockstep participant: it reads frames and poses, and is stopped with the
        // run (a view that cannot listen fails the run, as any child does).
        if let Some(listen) = &o.view {
            sup.spawn(ChildSpec::new("view", None, a.view(listen)))?;
        }
        // --ros2: no lockstep participant either; it finds the robots as their roles start.
        if let Some(connect) = &o.ros2 {
            let ids: Vec<u32> = scenario.world.robots.iter().map(|r| r.id).collect();
            let mut args = a.ros2(connect, &ids);
            args.extend(o.ros2_args.iter().cloned());
            sup.spawn(ChildSpec::new("ros2", None, args))?;
        }
        // --remote: the gateway serves the field to the antenna robots; they start once it serves.
        let remote = if o.remote {
            scenario.antenna_robots()
        } else {
            Vec::new()
        };
        if o.remote && remote.is_empty() {
            return Err(ProcessRunError::NoRemoteRobot {
                scenario: scenario.name.clone(),
            });
        }
        let gateway = if o.remote {
            Some(spawn_gateway(a, start, sup)?)
        } else {
            None
        };
        let (roles, remote_ids) =
            spawn_robot_roles(scenario, o, a, gateway.as_ref(), &remote, start, sup)?;
        // Seed 004: one mapper per robot when the scenario maps, each publishing its map as field
        // `<run>-map-r<ID>` and merging its peers' maps from their frames.
        let mut mappers: Vec<ChildId> = Vec::new();
        for id in mapper_robots(scenario, true) {
            not_stopping(start)?;
            mappers.push(sup.spawn(ChildSpec::new(
                "mapper",
                Some(id),
                a.role("mapper", Some(id)),
            ))?);
        }
        not_stopping(start)?;
        let world_args = a.world(start.attach_timeout, o.stall_timeout);
        let world = sup.spawn(ChildSpec::new("world", None, world_args))?;
        Ok(Self {
            field,
            gateway,
            roles,
            remote_ids,
            mappers,
            world,
        })
    }

    /// Waits (`end_timeout` for all) until the field, the roles and the mappers have stopped.
    pub(super) fn wait_roles_stopped(
        &self,
        sup: &mut Supervisor,
        end_timeout: Duration,
    ) -> Result<(), ProcessRunError> {
        let end_deadline = Instant::now() + end_timeout;
        for id in std::iter::once(self.field)
            .chain(self.roles.iter().copied())
            .chain(self.mappers.iter().copied())
        {
            if !sup.wait_exit(id, end_deadline.saturating_duration_since(Instant::now())) {
                return Err(ProcessRunError::NotStopped {
                    who: sup.spec(id).who(),
                    timeout_s: end_timeout.as_secs_f64(),
                });
            }
            sup.check()?;
        }
        Ok(())
    }

    /// The field's summary, and the reports of the field, the roles and the mappers.
    pub(super) fn reports(
        &self,
        sup: &mut Supervisor,
    ) -> Result<(FieldRunSummary, Vec<ProcessReport>), ProcessRunError> {
        let mut reports = Vec::new();
        let field_summary: FieldRunSummary = sup.summary(self.field)?;
        reports.push(report("field", &field_summary));
        for &id in &self.roles {
            if self.remote_ids.contains(&id) {
                let s: AntennaRobotSummary = sup.summary(id)?;
                reports.push(report(&sup.spec(id).who(), &s));
            } else {
                let s: RoleSummary = sup.summary(id)?;
                reports.push(report(&sup.spec(id).who(), &s));
            }
        }
        for &id in &self.mappers {
            let s: MapperSummary = sup.summary(id)?;
            reports.push(report(&sup.spec(id).who(), &s));
        }
        Ok((field_summary, reports))
    }
}

/// Starts each robot's localizer, depositor and follower; all of them, and those via `gateway`.
pub(super) fn spawn_robot_roles(
    scenario: &Scenario,
    o: &ProcessRunOptions<'_>,
    a: &ChildArgs,
    gateway: Option<&(ChildId, String)>,
    remote: &[u32],
    start: &RunStart<'_>,
    sup: &mut Supervisor,
) -> Result<(Vec<ChildId>, Vec<ChildId>), ProcessRunError> {
    let mut roles: Vec<ChildId> = Vec::new();
    let mut remote_ids: Vec<ChildId> = Vec::new();
    for r in &scenario.robots {
        not_stopping(start)?;
        let mut loc = a.role("localizer", Some(r.id));
        if o.slam {
            loc.push("--slam".into());
        }
        roles.push(sup.spawn(ChildSpec::new("localizer", Some(r.id), loc))?);
        if r.depositor.is_some() {
            roles.push(sup.spawn(ChildSpec::new(
                "depositor",
                Some(r.id),
                a.role("depositor", Some(r.id)),
            ))?);
        }
        if r.follower.is_some() {
            let mut follower = a.role("follower", Some(r.id));
            let through = gateway.filter(|_| remote.contains(&r.id));
            if let Some((_, address)) = through {
                follower.extend(args(&["--gateway", address]));
            } else if let Some(w) = o.follower_wait {
                follower.extend(["--wait".to_string(), w.to_string()]);
            }
            let id = sup.spawn(ChildSpec::new("follower", Some(r.id), follower))?;
            if through.is_some() {
                remote_ids.push(id);
            }
            roles.push(id);
        }
    }
    Ok((roles, remote_ids))
}

/// `Interrupted` once SIGINT/SIGTERM reached the run's node: a start-up stops spawning
/// children at once (the caller stops those already started).
fn not_stopping(start: &RunStart<'_>) -> Result<(), ProcessRunError> {
    if pheromone_field::shm::should_stop(start.node) {
        return Err(ProcessRunError::Interrupted);
    }
    Ok(())
}

/// Starts the gateway and waits until it serves; its id and address.
pub(super) fn spawn_gateway(
    a: &ChildArgs,
    start: &RunStart<'_>,
    sup: &mut Supervisor,
) -> Result<(ChildId, String), ProcessRunError> {
    let id = sup.spawn(ChildSpec::new(
        "gateway",
        None,
        a.gateway(start.attach_timeout),
    ))?;
    let address = gateway_address(
        start.node,
        sup,
        id,
        start.started + start.attach_timeout,
        start.attach_timeout.as_secs_f64(),
    )?;
    Ok((id, address))
}

/// Every robot has gone: stops the gateway `id` as Ctrl-C would, and reports its counters.
pub(super) fn stop_gateway(
    sup: &mut Supervisor,
    id: ChildId,
    end_timeout: Duration,
) -> Result<ProcessReport, ProcessRunError> {
    sup.signal(id, nix::sys::signal::Signal::SIGTERM);
    if !sup.wait_exit(id, end_timeout) {
        return Err(ProcessRunError::NotStopped {
            who: sup.spec(id).who(),
            timeout_s: end_timeout.as_secs_f64(),
        });
    }
    let counters: serde_json::Value = sup.summary(id)?;
    Ok(report("gateway", &counters))
}

/// The observer, joined once the field is up; a child that fails meanwhile ends the run.
pub(super) fn join_observer(
    scenario: &Scenario,
    a: &ChildArgs,
    start: &RunStart<'_>,
    sup: &mut Supervisor,
) -> Result<Observer, ProcessRunError> {
    let field_deadline = start.started + start.attach_timeout;
    loop {
        sup.check()?;
        match Observer::new(
            start.node,
            scenario,
            &a.world,
            &a.field,
            Duration::from_millis(100),
        ) {
            Ok(obs) => return Ok(obs),
            Err(AttachError::NoField { .. }) | Err(AttachError::Service(_))
                if Instant::now() < field_deadline =>
            {
                continue
            }
            Err(AttachError::NoField { .. }) => {
                return Err(ProcessRunError::NoField {
                    timeout_s: start.attach_timeout.as_secs_f64(),
                })
            }
            Err(e) => return Err(e.into()),
        }
    }
}

/// The address a gateway child prints on its first stdout line once it serves
/// (`--print-address`), waited for until `deadline` (woken by the line, or by Ctrl-C and a
/// failed child within 100 ms).
pub(super) fn gateway_address(
    node: &iceoryx2::node::Node<pheromone_field::shm::Svc>,
    sup: &mut Supervisor,
    id: ChildId,
    deadline: Instant,
    timeout_s: f64,
) -> Result<String, ProcessRunError> {
    loop {
        sup.check()?;
        if pheromone_field::shm::should_stop(node) {
            return Err(ProcessRunError::Interrupted);
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(ProcessRunError::NoGateway {
                timeout_s,
                stderr_tail: sup.stderr_tail(id),
            });
        }
        if let Some(line) = sup.next_line(id, left.min(Duration::from_millis(100)))? {
            let line = line.trim().to_string();
            return match line.strip_prefix("udp://") {
                Some(a) if !a.is_empty() => Ok(line),
                _ => Err(ProcessRunError::GatewayAddress { line }),
            };
        }
    }
}
