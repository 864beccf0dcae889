use super::*;

#[test]
fn every_builtin_scenario_loads() {
    for (name, _) in BUILTIN {
        let s = Scenario::load(name).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(&s.name, name);
    }
}

#[test]
fn unknown_keys_and_bad_values_are_refused_with_the_origin() {
    let e = Scenario::parse("name = 'x'\nduration_s = 1\nspeed = 3\n", "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("x.toml") && e.contains("speed"), "{e}");
    let e = Scenario::parse("name = 'x'\nduration_s = -1\n", "y.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("y.toml") && e.contains("duration_s = -1"), "{e}");
    let e = Scenario::load("no-such-scenario").unwrap_err().to_string();
    assert!(e.contains("no-such-scenario") && e.contains("trail"), "{e}");
}

#[test]
fn duplicates_robots_off_the_field_nan_deposits_and_endless_runs_are_refused() {
    let refused = |edit: &dyn Fn(&mut Scenario)| {
        let mut s = Scenario::load("trail").unwrap();
        edit(&mut s);
        s.validate().unwrap_err().to_string()
    };
    let e = refused(&|s| s.robots.push(s.robots[0].clone()));
    assert!(e.contains("more than one [[robots]] entry"), "{e}");
    let e = refused(&|s| s.world.robots[0].start.x_m = -1e4);
    assert!(
        e.contains("lies outside the field") && e.contains("-10000"),
        "{e}"
    );
    let e = refused(&|s| s.deposits[0].amount = f32::NAN);
    assert!(
        e.contains("deposit 1: the field would refuse it") && e.contains("non_finite"),
        "{e}"
    );
    let e = refused(&|s| s.deposits[0].channel = 7);
    assert!(e.contains("deposit 1: the field would refuse it"), "{e}");
    let e = refused(&|s| s.duration_s = 1e300);
    assert!(
        e.contains("duration_s") && e.contains("at most 1e9 s"),
        "{e}"
    );
    let e = refused(&|s| {
        s.robots[0]
            .depositor
            .as_mut()
            .expect("trail's robot deposits")
            .channel = 5
    });
    assert!(
        e.contains("depositor channel = 5") && e.contains("the field has 2 channel(s)"),
        "{e}"
    );
}

#[test]
fn nan_infinite_and_absurd_numbers_anywhere_in_a_file_are_refused_naming_the_key() {
    // Every float key of a file, at any depth, in tables and arrays of tables.
    let cases = [
        (
            "duration_s = ",
            "nan",
            "duration_s = NaN: must be a finite number",
        ),
        (
            "duration_s = ",
            "inf",
            "duration_s = inf: must be a finite number",
        ),
        (
            "duration_s = ",
            "-1e300",
            "duration_s = -1e300: must be at most 1e9 in size",
        ),
    ];
    for (key, value, says) in cases {
        let text = format!("name = 'x'\n{key}{value}\n");
        let e = Scenario::parse(&text, "n.toml").unwrap_err().to_string();
        assert!(e.contains("n.toml") && e.contains(says), "{value}: {e}");
    }
    let nested = "name = 'x'\nduration_s = 5.0\n[[robots]]\nid = 0\n[[robots]]\nid = 1\n\
                  [robots.depositor]\ntau = nan\n";
    let e = check_numbers(&toml::from_str(nested).unwrap(), "")
        .unwrap_err()
        .to_string();
    assert_eq!(e, "robots[1].depositor.tau = NaN: must be a finite number");
}

#[test]
fn a_refused_scenario_keeps_what_was_refused_as_its_source() {
    use std::error::Error;
    let e = Scenario::parse("name = 'x'\nduration_s = -1\n", "y.toml").unwrap_err();
    let inner = e
        .source()
        .and_then(|s| s.downcast_ref::<Box<ScenarioError>>());
    assert!(
        matches!(inner.map(|b| &**b), Some(ScenarioError::Value { key, .. }) if key == "duration_s"),
        "{e:?}"
    );
    let mut s = Scenario::load("trail").unwrap();
    s.deposits[0].kernel = "blob".into();
    let e = s.validate().unwrap_err();
    assert!(
        matches!(
            &e,
            ScenarioError::Deposit {
                index: 1,
                source: DepositError::Kernel(_)
            }
        ),
        "{e:?}"
    );
    let kernel = e.source().and_then(|d| d.source()).map(|k| k.to_string());
    assert!(kernel.is_some_and(|k| k.contains("'blob'")), "{e}");
}

#[test]
fn a_line_deposit_expands_every_spacing() {
    let s = Scenario::load("trail").unwrap();
    let msgs = s.deposits[0].messages().unwrap();
    assert_eq!(msgs.len(), 106);
    assert!((msgs[105].x_m - 11.0).abs() < 1e-3);
}

#[test]
fn a_bad_landmark_region_fails_validation_naming_the_robot_and_the_key() {
    // A scenario with a bad region fails validation naming the robot and the key.
    let mut scenario = Scenario::load("trail").unwrap();
    scenario.robots[0].localizer.landmark_region_m = Some([1.0, 1.0, 0.0, 2.0]);
    let e = scenario.validate().unwrap_err().to_string();
    assert!(
        e.contains("localizer") && e.contains("`landmark_region_m`"),
        "{e}"
    );
}
