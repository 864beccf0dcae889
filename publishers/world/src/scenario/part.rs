//! A robot's part of a scenario (issue 52): what its localizer, depositor and follower read. A
//! run as processes writes one such file per robot beside the whole scenario, so each of its 3N
//! role processes parses and validates a scenario of one robot, not of N (N² over a start-up).

use super::{MetricsConfig, Scenario};

impl Scenario {
    /// Robot `id`'s part: the scenario with only that robot in the world and among the roles
    /// (its start as drawn: no `[start_area]` to draw again), without what only the world and
    /// the observer read (scripted deposits, wall marks, probes, snapshots, metrics, the
    /// active-robot count, the loss script the sim already applied). What robot `id`'s
    /// localizer, depositor and follower are built from (`roles`, `localizer_setup`,
    /// `follower_config`, `own_map_start`, the world's step) is the whole scenario's; a
    /// mapper's peers are not in it. `None` when `id` is not a robot of the world.
    pub fn robot_part(&self, id: u32) -> Option<Scenario> {
        let world_robot = self.world.robots.iter().find(|r| r.id == id)?.clone();
        let mut world = self.world.clone();
        world.robots = vec![world_robot];
        Some(Scenario {
            name: self.name.clone(),
            seed: self.seed,
            duration_s: self.duration_s,
            field: self.field.clone(),
            world,
            robots: self.robots.iter().filter(|r| r.id == id).cloned().collect(),
            deposits: Vec::new(),
            active_robots: None,
            mark_walls: None,
            probes: Vec::new(),
            snapshots_s: Vec::new(),
            metrics: MetricsConfig::default(),
            mapping: self.mapping.clone(),
            start_area: None,
            scripted_loss: None,
            radio: self.radio.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Overrides, BUILTIN};
    use super::*;

    /// Everything robot `id`'s localizer, depositor and follower processes take from `s`.
    fn role_inputs(s: &Scenario, id: u32) -> String {
        let setups: Vec<String> = [false, true]
            .iter()
            .map(|&slam| format!("{:?}", s.localizer_setup(id, slam)))
            .collect();
        format!(
            "{:?}\n{setups:?}\n{:?}\n{:?}\n{}",
            s.roles(id),
            s.follower_config(id),
            s.own_map_start(id),
            s.world.dt_s
        )
    }

    /// Every built-in scenario, as the sim runs it (with `--robots` at its largest), and the
    /// scale bench's kind of swarm: each robot's part, written and read back as a child reads
    /// it, gives its roles exactly what the whole scenario gives them.
    #[test]
    fn a_robot_part_read_back_gives_its_roles_what_the_whole_scenario_gives() {
        let mut checked = 0;
        for (name, _) in BUILTIN {
            let mut s = Scenario::load(name).unwrap();
            s.apply(&Overrides::default()).unwrap();
            for r in s.world.robots.clone() {
                let part = s.robot_part(r.id).expect("a robot of the world");
                let text = part.to_toml().unwrap();
                let read = Scenario::parse(&text, "part").unwrap_or_else(|e| panic!("{name}: {e}"));
                assert_eq!(read.world.robots.len(), 1, "{name}");
                assert!(read.robots.len() <= 1, "{name}");
                assert_eq!(
                    role_inputs(&read, r.id),
                    role_inputs(&s, r.id),
                    "{name} r{}",
                    r.id
                );
                checked += 1;
            }
        }
        assert!(checked > BUILTIN.len(), "{checked} robots checked");
        assert!(Scenario::load("trail").unwrap().robot_part(9999).is_none());
    }

    /// A scenario of 8 robots whose starts are drawn from `[start_area]`: the part keeps the
    /// drawn start (drawing again for one robot would give robot i the first pose).
    #[test]
    fn a_drawn_start_is_kept_in_the_part() {
        let mut s = Scenario::load("ias-ss").unwrap();
        s.active_robots = None;
        s.start_area = Some(super::super::StartArea {
            min_x_m: 1.0,
            min_y_m: 1.0,
            max_x_m: 6.0,
            max_y_m: 6.0,
        });
        s.place_random_starts().unwrap();
        s.validate().unwrap();
        let whole = Scenario::parse(&s.to_toml().unwrap(), "whole").unwrap();
        assert_eq!(whole.world.robots.len(), 8);
        for w in &whole.world.robots {
            let part = whole.robot_part(w.id).unwrap();
            let read = Scenario::parse(&part.to_toml().unwrap(), "part").unwrap();
            assert_eq!(read.world.robots[0].start, w.start, "r{}", w.id);
            assert_eq!(
                role_inputs(&read, w.id),
                role_inputs(&whole, w.id),
                "r{}",
                w.id
            );
        }
    }
}
