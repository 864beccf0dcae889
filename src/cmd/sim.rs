//! `pheromone sim`: starts a whole scenario as separate processes (field, world, and each
//! robot's localizer, depositor and follower), waits for the end, collects their summaries and
//! stops every process it started — also on Ctrl-C or when one of them fails.

use std::io::Read;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::Args;
use serde_json::{json, Value};

use super::roles::load_scenario;

/// Run a scenario as real processes on this host and report what happened.
///
/// Starts `pheromone field --clock`, then for every robot of the scenario a localizer, and a
/// depositor and a follower where the scenario gives them, then the world (lockstep clock: as
/// fast as the processes answer). At the end it prints a summary on stderr, and with --json one
/// metrics object on stdout.
#[derive(Args, Debug)]
pub struct SimArgs {
    /// Scenario: a built-in name (trail) or a TOML file.
    #[arg(default_value = "trail")]
    pub scenario: String,
    /// Print one JSON metrics object on stdout.
    #[arg(long)]
    pub json: bool,
    /// Seconds the whole run may take before it is stopped as failed.
    #[arg(long, default_value_t = 600.0, value_name = "SECS")]
    pub timeout: f64,
}

/// A started role; killed and reaped if still running when dropped.
struct Role {
    name: String,
    child: Child,
}

impl Role {
    fn spawn(name: String, args: &[String]) -> anyhow::Result<Self> {
        let exe = std::env::current_exe()?;
        let child = Command::new(exe)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| anyhow::anyhow!("cannot start {name}: {e}"))?;
        Ok(Self { name, child })
    }

    /// Output of a finished role: (success, stdout JSON, stderr text).
    fn collect(&mut self) -> (bool, Option<Value>, String) {
        let status = self.child.wait().ok();
        let mut out = String::new();
        let mut err = String::new();
        if let Some(mut o) = self.child.stdout.take() {
            let _ = o.read_to_string(&mut out);
        }
        if let Some(mut e) = self.child.stderr.take() {
            let _ = e.read_to_string(&mut err);
        }
        (
            status.is_some_and(|s| s.success()),
            serde_json::from_str(out.trim()).ok(),
            err,
        )
    }
}

impl Drop for Role {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

pub fn run(a: SimArgs) -> anyhow::Result<()> {
    let scenario = load_scenario(&a.scenario)?;
    let tag = format!("sim{}", std::process::id());
    let (field_name, world_name) = (tag.clone(), tag.clone());
    let interrupted = Arc::new(AtomicBool::new(false));
    {
        let flag = interrupted.clone();
        let _ = ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst));
    }
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let common = |role: &str, robot: Option<u32>| {
        let mut v = s(&[
            role,
            "--scenario",
            &a.scenario,
            "--world",
            &world_name,
            "--field",
            &field_name,
            "--json",
        ]);
        if let Some(r) = robot {
            v.extend(s(&["--robot", &r.to_string()]));
        }
        v
    };
    eprintln!(
        "sim '{}': {} robot(s), {:.1} s simulated, field {}×{} cells; processes:",
        scenario.name,
        scenario.robots.len(),
        scenario.duration_s,
        scenario.field.width,
        scenario.field.height
    );
    let mut roles = vec![Role::spawn(
        "field".into(),
        &s(&[
            "field",
            "--name",
            &field_name,
            "--scenario",
            &a.scenario,
            "--clock",
            &world_name,
            "--json",
        ]),
    )?];
    for r in &scenario.robots {
        roles.push(Role::spawn(
            format!("localizer r{}", r.id),
            &common("localizer", Some(r.id)),
        )?);
        if r.depositor.is_some() {
            roles.push(Role::spawn(
                format!("depositor r{}", r.id),
                &common("depositor", Some(r.id)),
            )?);
        }
        if r.follower.is_some() {
            roles.push(Role::spawn(
                format!("follower r{}", r.id),
                &common("follower", Some(r.id)),
            )?);
        }
    }
    roles.push(Role::spawn("world".into(), &common("world", None))?);
    for r in &roles {
        eprintln!("  {:<14} pid {}", r.name, r.child.id());
    }
    // Wait until the world ends (or a role fails, or Ctrl-C, or the timeout).
    let started = Instant::now();
    let deadline = started + Duration::from_secs_f64(a.timeout);
    let world_index = roles.len() - 1;
    loop {
        if interrupted.load(Ordering::SeqCst) {
            anyhow::bail!("interrupted: stopped every process of the run");
        }
        if let Ok(Some(_)) = roles[world_index].child.try_wait() {
            break;
        }
        for r in roles.iter_mut().take(world_index) {
            if let Ok(Some(status)) = r.child.try_wait() {
                if !status.success() {
                    let (_, _, err) = r.collect();
                    anyhow::bail!("{} failed ({status}): {}", r.name, err.trim());
                }
            }
        }
        if Instant::now() > deadline {
            anyhow::bail!(
                "the run took longer than {} s: stopped every process",
                a.timeout
            );
        }
        // Child exits have no iceoryx2 event; check them every 20 ms.
        std::thread::park_timeout(Duration::from_millis(20));
    }
    let (ok, world, err) = roles[world_index].collect();
    if !ok {
        anyhow::bail!("world failed: {}", err.trim());
    }
    let world = world.unwrap_or(Value::Null);
    // The other roles stop by themselves when the world announces the end.
    let mut summaries = Vec::new();
    let end_deadline = Instant::now() + Duration::from_secs(15);
    for r in roles.iter_mut().take(world_index) {
        while r.child.try_wait().ok().flatten().is_none() {
            if Instant::now() > end_deadline {
                anyhow::bail!(
                    "{} did not stop within 15 s of the end of the run: stopped every process",
                    r.name
                );
            }
            std::thread::park_timeout(Duration::from_millis(20));
        }
        let (ok, out, err) = r.collect();
        if !ok {
            anyhow::bail!("{} failed: {}", r.name, err.trim());
        }
        summaries.push((r.name.clone(), out.unwrap_or(Value::Null)));
    }
    let field = &summaries[0].1;
    let wall_s = started.elapsed().as_secs_f64();
    let robots: Vec<Value> = world["robots"]
        .as_array()
        .cloned()
        .unwrap_or_default()
        .into_iter()
        .map(|r| {
            let id = r["id"].as_u64().unwrap_or(0);
            let role = match scenario.roles(id as u32) {
                Some(x) if x.follower.is_some() && x.depositor.is_some() => "follower+depositor",
                Some(x) if x.follower.is_some() => "follower",
                Some(x) if x.depositor.is_some() => "depositor",
                _ => "idle",
            };
            json!({
                "id": id,
                "role": role,
                "true_pose": r["true_pose"],
                "distance_travelled_m": r["distance_travelled_m"],
                "collisions": r["collisions"],
            })
        })
        .collect();
    let metrics = json!({
        "scenario": scenario.name,
        "seed": scenario.seed,
        "sim_time_s": world["sim_time_s"],
        "ticks": field["ticks"],
        "wall_time_s": wall_s,
        "field": {
            "width": scenario.field.width,
            "height": scenario.field.height,
            "cell_size_m": scenario.field.cell_size_m,
            "channels": scenario.field.channels.iter().map(|c| c.name.clone()).collect::<Vec<_>>(),
            "total_mass": field["total_mass"],
            "max": field["max"],
            "deposits_applied": field["deposits_applied"],
            "deposits_rejected": field["deposits_rejected"],
        },
        "robots": robots,
        "processes": summaries.iter().map(|(n, v)| json!({"role": n, "summary": v})).collect::<Vec<_>>(),
    });
    eprintln!(
        "sim '{}' done: {} steps ({} s simulated) in {:.2} s wall time; field: {} deposits applied",
        scenario.name, world["steps"], world["sim_time_s"], wall_s, field["deposits_applied"]
    );
    for r in metrics["robots"].as_array().into_iter().flatten() {
        eprintln!(
            "  robot {} ({}): ended at {}, travelled {:.2} m",
            r["id"],
            r["role"].as_str().unwrap_or(""),
            r["true_pose"],
            r["distance_travelled_m"].as_f64().unwrap_or(0.0)
        );
    }
    if a.json {
        println!("{metrics}");
    }
    Ok(())
}
