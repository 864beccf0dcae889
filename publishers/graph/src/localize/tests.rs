//! Tests of graph robots' localization (`localize.rs`): ρ_t, settings, landmarks and sensors.

use super::*;

fn cov_xy(sxx: f64, sxy: f64, syy: f64) -> [[f64; 3]; 3] {
    [[sxx, sxy, 0.0], [sxy, syy, 0.0], [0.0, 0.0, 0.01]]
}

#[test]
fn rho_t_is_inverse_to_the_covariance_within_0_and_1() {
    let r = 0.05;
    assert_eq!(rho_t(&cov_xy(0.0, 0.0, 0.0), r, 1), Ok(1.0));
    // A 1-σ circle of radius ρ_ref or smaller: 1.
    assert_eq!(rho_t(&cov_xy(r * r, 0.0, r * r), r, 1), Ok(1.0));
    // Larger: ρ_ref² / √det, and Σ × k gives ρ_t / k.
    let base = rho_t(&cov_xy(0.01, 0.002, 0.02), r, 1).unwrap();
    let det: f64 = 0.01 * 0.02 - 0.002 * 0.002;
    assert!((base - r * r / det.sqrt()).abs() < 1e-12);
    let scaled = rho_t(&cov_xy(0.04, 0.008, 0.08), r, 1).unwrap();
    assert!((scaled - base / 4.0).abs() < 1e-12);
    assert!(base > 0.0 && base < 1.0);
    // Huge but finite: small, never 0 or NaN.
    let tiny = rho_t(&cov_xy(1e6, 0.0, 1e6), r, 1).unwrap();
    assert!(tiny > 0.0 && tiny.is_finite());
}

#[test]
fn a_bad_covariance_or_setting_is_refused_by_name() {
    for bad in [
        cov_xy(f64::NAN, 0.0, 1.0),
        cov_xy(1.0, 0.0, f64::INFINITY),
        cov_xy(-1.0, 0.0, 1.0),
        cov_xy(1.0, 2.0, 1.0),
    ] {
        let e = rho_t(&bad, 0.05, 7).unwrap_err();
        assert!(matches!(e, LocalizeError::Covariance { robot: 7, .. }));
        assert!(e.to_string().contains("R7"), "{e}");
    }
    for (key, c) in [
        (
            "landmark_spacing_m",
            LocalizeConfig {
                landmark_spacing_m: 0.0,
                ..LocalizeConfig::default()
            },
        ),
        (
            "rho_ref_m",
            LocalizeConfig {
                rho_ref_m: f64::NAN,
                ..LocalizeConfig::default()
            },
        ),
        (
            "alpha[2]",
            LocalizeConfig {
                alpha: [0.0, 0.0, -1.0, 0.0],
                ..LocalizeConfig::default()
            },
        ),
        (
            "unlit_rect_m[2]",
            LocalizeConfig {
                unlit_rect_m: [5.0, 0.0, 4.0, 1.0],
                ..LocalizeConfig::default()
            },
        ),
        (
            "unlit_rect_m[1]",
            LocalizeConfig {
                unlit_rect_m: [0.0, f64::INFINITY, 4.0, 1.0],
                ..LocalizeConfig::default()
            },
        ),
    ] {
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains(&format!("`{key}`")), "{e}");
    }
    assert!("sometimes".parse::<DepositWeight>().is_err());
    assert_eq!("rho".parse::<DepositWeight>(), Ok(DepositWeight::Rho));
    // The scenario key refuses unknown settings.
    assert!(toml::from_str::<LocalizeConfig>("spacing = 1.0").is_err());
    let c: LocalizeConfig = toml::from_str("landmark_spacing_m = 4.0").unwrap();
    assert_eq!(c.landmark_spacing_m, 4.0);
    assert_eq!(c.sensor_range_m, LocalizeConfig::default().sensor_range_m);
}

#[test]
fn landmarks_line_both_sides_of_every_link_and_the_sensors_are_seeded() {
    let sc = crate::agent::RegionsScenario::paper_corridor();
    let g = sc.graph().unwrap();
    let c = LocalizeConfig::default();
    let map = graph_landmarks(&g, &c);
    // 9 links of 2–5 m: one pair per metre (at least one per link).
    assert_eq!(map.len(), 50);
    assert!(map
        .iter()
        .all(|l| (1..=c.signatures).contains(&l.signature)));
    let truth = [11.0, 2.5, 0.0];
    let a = Sensing::new(c, 3, 1).observe(truth, &map);
    let b = Sensing::new(c, 3, 1).observe(truth, &map);
    assert_eq!(a, b);
    let in_range = map
        .iter()
        .filter(|l| (l.x_m - truth[0]).hypot(l.y_m - truth[1]) <= c.sensor_range_m)
        .count();
    assert_eq!(a.len(), in_range);
    assert_ne!(a, Sensing::new(c, 4, 1).observe(truth, &map));
}

#[test]
fn an_unlit_rectangle_has_no_landmarks_and_the_rest_of_the_map_keeps_them() {
    let sc = crate::agent::RegionsScenario::paper_corridor();
    let g = sc.graph().unwrap();
    let all = graph_landmarks(&g, &LocalizeConfig::default());
    let c = LocalizeConfig {
        unlit_rect_m: [10.0, 0.0, 16.0, 5.0],
        ..LocalizeConfig::default()
    };
    c.validate().unwrap();
    let lit = graph_landmarks(&g, &c);
    let inside = |l: &GraphLandmark| (10.0..=16.0).contains(&l.x_m) && (0.0..=5.0).contains(&l.y_m);
    assert!(all.iter().any(inside), "the corridor has landmarks there");
    assert!(!lit.iter().any(inside), "none is left inside");
    assert_eq!(lit.len(), all.iter().filter(|l| !inside(l)).count());
    assert!(lit.len() >= 30, "{} landmarks outside", lit.len());
}
