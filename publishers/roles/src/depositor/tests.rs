use super::*;
use approx::assert_relative_eq;
use pheromone_field::deposit::{gamma, prepare, DepositLimits, ErrorEllipse};
use pheromone_field::{ChannelSpec, Evaporation, FieldConfig, OwnedField};
use proptest::prelude::*;

/// A 10 m × 10 m, 0.05 m field with one channel that never evaporates.
fn still_field(channel: ChannelSpec) -> OwnedField {
    OwnedField::new(FieldConfig {
        width: 200,
        height: 200,
        cell_size_m: 0.05,
        channels: vec![channel],
        ..FieldConfig::default()
    })
    .unwrap()
}

/// A pose at a cell centre with the given position covariance and a small heading variance.
fn pose(x_m: f64, y_m: f64, xx: f64, xy: f64, yy: f64) -> PoseMsg {
    PoseMsg {
        x_m,
        y_m,
        cov: [xx, xy, 0.0, xy, yy, 0.0, 0.0, 0.0, 0.01],
        ..PoseMsg::default()
    }
}

fn every_pose(mode: DepositMode) -> Depositor {
    Depositor::new(DepositorConfig {
        mode,
        interval_m: 0.0,
        interval_s: 0.0,
        ..DepositorConfig::default()
    })
    .unwrap()
}

/// Deposits one pose into a fresh still field and returns the value at the pose.
fn peak_after_deposit(dep: &Depositor, p: &PoseMsg) -> f32 {
    let mut f = still_field(ChannelSpec::new("trail", Evaporation::None));
    f.offer(&dep.deposit_for(p).unwrap()).unwrap();
    f.tick();
    f.view().value(0, p.x_m as f32, p.y_m as f32)
}

#[test]
fn deposited_peak_scales_as_one_over_det_until_the_cap() {
    // Eqs. 12 and 14 as printed (`amount = "literal"`): the peak is γ.
    let dep = Depositor::new(DepositorConfig {
        amount: AmountForm::Literal,
        interval_m: 0.0,
        interval_s: 0.0,
        ..DepositorConfig::default()
    })
    .unwrap();
    let tau = dep.config().tau as f64;
    let gmax = dep.config().gamma_max;
    // (x, y) = (5.025, 5.025) is a cell centre, so the peak cell holds exactly γ.
    let mut uncapped = Vec::new();
    for (xx, xy, yy) in [
        (0.05, 0.0, 0.05),
        (0.1, 0.0, 0.1),
        (0.2, 0.05, 0.1),
        (0.2, 0.0, 0.2),
        (0.4, 0.1, 0.3),
    ] {
        let det = xx * yy - xy * xy;
        let peak = peak_after_deposit(&dep, &pose(5.025, 5.025, xx, xy, yy));
        assert!(tau / det < gmax as f64, "case must be below the cap");
        // γ·det = τ: the deposit scales as 1/det Σxy (seed 000 eq. 12).
        assert_relative_eq!(peak as f64 * det, tau, max_relative = 1e-4);
        let e = ErrorEllipse::from_cov(xx as f32, xy as f32, yy as f32);
        assert_relative_eq!(peak, gamma(tau as f32, e.det(), gmax), max_relative = 1e-4);
        uncapped.push((det, peak));
    }
    // Four times the determinant, a quarter of the peak.
    assert_relative_eq!(uncapped[1].1 / uncapped[3].1, 4.0, max_relative = 1e-4);
    // Confident enough to hit the cap: γ = γmax, and a zero covariance is no infinity.
    for (xx, yy) in [(0.01, 0.01), (1e-6, 1e-6), (0.0, 0.0)] {
        let peak = peak_after_deposit(&dep, &pose(5.025, 5.025, xx, 0.0, yy));
        assert_relative_eq!(peak, gmax, max_relative = 1e-5);
    }
}

#[test]
fn ellipse_is_oriented_along_the_major_eigenvector() {
    for kernel in [EllipseKernel::Ellipse, EllipseKernel::Paper] {
        let dep = Depositor::new(DepositorConfig {
            kernel,
            range_m: 2.0,
            ..DepositorConfig::default()
        })
        .unwrap();
        // Σxy = R(30°) diag(0.09, 0.01) R(30°)ᵀ: major axis at 30°.
        let a = 30f64.to_radians();
        let (c, s) = (a.cos(), a.sin());
        let (l1, l2) = (0.09, 0.01);
        let (xx, xy, yy) = (
            l1 * c * c + l2 * s * s,
            (l1 - l2) * c * s,
            l1 * s * s + l2 * c * c,
        );
        let mut f = still_field(ChannelSpec::new("trail", Evaporation::None));
        let p = pose(5.0, 5.0, xx, xy, yy);
        f.offer(&Depositor::deposit_for(&dep, &p).unwrap()).unwrap();
        f.tick();
        let v = f.view();
        for d in [0.1f64, 0.2, 0.3] {
            for sgn in [1.0, -1.0] {
                let major = v.value(0, (5.0 + sgn * d * c) as f32, (5.0 + sgn * d * s) as f32);
                let minor = v.value(0, (5.0 - sgn * d * s) as f32, (5.0 + sgn * d * c) as f32);
                assert!(
                    major > minor,
                    "{kernel:?} d = {d}: major {major} ≤ minor {minor}"
                );
            }
        }
        // The direction of the largest value on a ring of radius 0.2 m is the major axis.
        let best = (0..360)
            .map(|k| (k as f64).to_radians())
            .max_by(|p, q| {
                let val = |t: &f64| {
                    v.value(
                        0,
                        (5.0 + 0.2 * t.cos()) as f32,
                        (5.0 + 0.2 * t.sin()) as f32,
                    )
                };
                val(p).total_cmp(&val(q))
            })
            .unwrap();
        let off = (best - a).rem_euclid(std::f64::consts::PI);
        let off = off.min(std::f64::consts::PI - off);
        assert!(
            off < 5f64.to_radians(),
            "{kernel:?}: ring maximum at {best} rad"
        );
    }
}

fn stamped(x_m: f64, stamp_s: f64) -> PoseMsg {
    PoseMsg {
        stamp_ns: (stamp_s * 1e9) as u64,
        ..pose(x_m, 1.0, 0.1, 0.0, 0.1)
    }
}

fn run(dep: &mut Depositor, poses: &[(f64, f64)]) -> Vec<bool> {
    poses
        .iter()
        .map(|&(x, t)| dep.process(&stamped(x, t)).unwrap().is_some())
        .collect()
}

#[test]
fn deposits_by_distance_interval() {
    let mut dep = Depositor::new(DepositorConfig {
        interval_m: 0.5,
        interval_s: 0.0,
        ..DepositorConfig::default()
    })
    .unwrap();
    let got = run(
        &mut dep,
        &[
            (0.0, 0.0),
            (0.2, 1.0),
            (0.49, 50.0),
            (0.5, 51.0),
            (0.6, 52.0),
            (1.0, 53.0),
            (0.6, 54.0),
        ],
    );
    assert_eq!(got, [true, false, false, true, false, true, false]);
    assert_eq!(dep.counters().deposits, 3);
    assert_eq!(dep.counters().skipped_interval, 4);
    assert_eq!(dep.counters().poses, 7);
    dep.reset();
    assert!(
        dep.process(&stamped(1.0, 60.0)).unwrap().is_some(),
        "first pose after reset deposits"
    );
}

#[test]
fn deposits_by_time_interval_and_either_trigger() {
    let mut dep = Depositor::new(DepositorConfig {
        interval_m: 0.0,
        interval_s: 1.0,
        ..DepositorConfig::default()
    })
    .unwrap();
    let got = run(
        &mut dep,
        &[
            (0.0, 10.0),
            (5.0, 10.5),
            (5.0, 11.0),
            (5.0, 11.9),
            (5.0, 9.0),
            (5.0, 12.0),
        ],
    );
    assert_eq!(got, [true, false, true, false, false, true]);

    let mut both = Depositor::new(DepositorConfig {
        interval_m: 0.5,
        interval_s: 1.0,
        ..DepositorConfig::default()
    })
    .unwrap();
    let got = run(
        &mut both,
        &[(0.0, 0.0), (0.1, 0.5), (0.7, 0.6), (0.8, 1.6), (0.9, 1.7)],
    );
    assert_eq!(got, [true, false, true, true, false]);

    let mut every = every_pose(DepositMode::UncertaintyAware);
    assert_eq!(
        run(&mut every, &[(0.0, 0.0), (0.0, 0.0), (0.0, 0.0)]),
        [true, true, true]
    );
}

#[test]
fn constant_mode_ignores_the_covariance() {
    let dep = every_pose(DepositMode::Constant);
    let sharp = pose(5.025, 5.025, 1e-4, 0.0, 1e-4);
    let lost = pose(5.025, 5.025, 2.0, 0.5, 1.0);
    let (a, b) = (
        dep.deposit_for(&sharp).unwrap(),
        dep.deposit_for(&lost).unwrap(),
    );
    assert_eq!(a, b);
    let s2 = 0.1f32 * 0.1;
    assert_eq!((a.cov_xx, a.cov_xy, a.cov_yy), (s2, 0.0, s2));
    assert_eq!(
        peak_after_deposit(&dep, &sharp),
        peak_after_deposit(&dep, &lost)
    );
    // The uncertainty-aware depositor tells the two apart.
    let aware = every_pose(DepositMode::UncertaintyAware);
    assert!(peak_after_deposit(&aware, &sharp) > 10.0 * peak_after_deposit(&aware, &lost));
}

#[test]
fn saturating_mode_strength_falls_with_uncertainty() {
    let dep = every_pose(DepositMode::Saturating);
    let rho = |xx: f64, yy: f64| {
        dep.deposit_for(&pose(5.0, 5.0, xx, 0.0, yy))
            .unwrap()
            .amount
    };
    assert_relative_eq!(rho(0.0, 0.0), 1.0);
    assert_relative_eq!(rho(0.125, 0.125), (-1.0f32).exp(), max_relative = 1e-6);
    assert!(
        rho(0.01, 0.01) > rho(0.1, 0.1) && rho(0.1, 0.1) > rho(1.0, 1.0) && rho(1.0, 1.0) > 0.0
    );
    let m = dep.deposit_for(&pose(5.0, 5.0, 0.01, 0.0, 0.01)).unwrap();
    assert_eq!(m.kernel, KernelKind::Saturating as u32);
    assert_eq!((m.sigma_m, m.range_m), (0.05, 1.0));

    // Anti-pheromone on a signed saturating channel: negative, saturating at −1.
    let anti = Depositor::new(DepositorConfig {
        mode: DepositMode::Saturating,
        anti_pheromone: true,
        interval_m: 0.0,
        ..DepositorConfig::default()
    })
    .unwrap();
    let mut spec = ChannelSpec::new("anti", Evaporation::Saturating { rho_per_tick: 0.0 });
    spec.signed = true;
    let mut f = still_field(spec);
    let p = pose(5.025, 5.025, 0.0, 0.0, 0.0);
    for _ in 0..20 {
        f.offer(&anti.deposit_for(&p).unwrap()).unwrap();
        f.tick();
    }
    let v = f.view().value(0, 5.025, 5.025);
    assert!((-1.0..-0.99).contains(&v), "{v}");
}

/// Issue 48 part 2, eq. 11's intent (the default): what a robot leaves at its place falls as
/// its uncertainty grows, also where γ = τ/det Σxy is still capped at γmax (σ ≤ 0.21 m with
/// τ = 0.2), where the literal peak stays at γmax and a wider ellipse brightens the trail.
#[test]
fn the_intended_amount_falls_with_uncertainty_where_the_literal_one_is_capped() {
    let intent = every_pose(DepositMode::UncertaintyAware);
    assert_eq!(intent.config().amount, AmountForm::Intent);
    let literal = Depositor::new(DepositorConfig {
        amount: AmountForm::Literal,
        interval_m: 0.0,
        interval_s: 0.0,
        ..DepositorConfig::default()
    })
    .unwrap();
    let (mut last_i, mut last_l) = (f32::INFINITY, 0.0f32);
    for sigma in [0.1f64, 0.12, 0.15, 0.18, 0.2] {
        let v = sigma * sigma;
        let p = pose(5.025, 5.025, v, 0.0, v);
        let (i, l) = (
            peak_after_deposit(&intent, &p),
            peak_after_deposit(&literal, &p),
        );
        assert_relative_eq!(l, 100.0, max_relative = 1e-4); // capped
                                                            // γmax per reference ellipse of σ = 0.1 m: the peak is 100·(0.1/σ)².
        assert_relative_eq!(i as f64, 100.0 * 0.01 / v, max_relative = 1e-3);
        assert!(i <= last_i && l >= last_l, "σ {sigma}: {i} / {l}");
        (last_i, last_l) = (i, l);
    }
    assert!(last_i < 0.3 * last_l, "{last_i} vs {last_l}");
}

#[test]
fn anti_pheromone_negates_the_ellipse_amount() {
    let dep = Depositor::new(DepositorConfig {
        anti_pheromone: true,
        channel: 3,
        kernel: EllipseKernel::Paper,
        amount: AmountForm::Literal,
        ..DepositorConfig::default()
    })
    .unwrap();
    let m = dep.deposit_for(&pose(1.0, 2.0, 0.1, 0.0, 0.1)).unwrap();
    assert_eq!(
        (m.amount, m.channel, m.kernel),
        (-0.2, 3, KernelKind::Paper as u32)
    );
}

#[test]
fn bad_poses_are_rejected_and_counted() {
    let mut dep = every_pose(DepositMode::UncertaintyAware);
    let good = pose(1.0, 1.0, 0.1, 0.02, 0.1);
    let mut nan_x = good;
    nan_x.x_m = f64::NAN;
    let mut inf_cov = good;
    inf_cov.cov[8] = f64::INFINITY;
    let mut asym = good;
    asym.cov[3] = 0.05; // cov_yx ≠ cov_xy
    let neg_var = pose(1.0, 1.0, -0.1, 0.0, 0.1);
    let not_psd = pose(1.0, 1.0, 0.1, 0.2, 0.1); // |xy| > √(xx·yy)
    let mut huge = good;
    huge.y_m = 1e300;
    let cases = [
        (nan_x, PoseRejectReason::NonFinite, "x_m"),
        (inf_cov, PoseRejectReason::NonFinite, "cov_thetatheta"),
        (asym, PoseRejectReason::NotSymmetric, "cov[0][1]"),
        (neg_var, PoseRejectReason::NotPsd, "eigenvalue"),
        (not_psd, PoseRejectReason::NotPsd, "eigenvalue"),
        (huge, PoseRejectReason::OutOfRange, "y_m"),
    ];
    for (p, reason, mention) in cases {
        let e = dep.process(&p).unwrap_err();
        assert_eq!(e.reason(), reason, "{e}");
        assert!(
            e.to_string().contains(mention) && e.to_string().contains(reason.name()),
            "{e}"
        );
    }
    let c = dep.counters();
    assert_eq!(c.rejected, [2, 1, 2, 1]);
    assert_eq!((c.rejected_total(), c.deposits, c.poses), (6, 0, 6));
    assert_eq!(c.rejected_for(PoseRejectReason::NotPsd), 2);
    // A rejected pose does not count as the first deposit.
    assert!(dep.process(&good).unwrap().is_some());
    // Round-off asymmetry and a rank-deficient (but PSD) covariance are accepted.
    let mut nearly = good;
    nearly.cov[3] += 1e-12;
    assert!(dep.process(&nearly).is_ok());
    assert!(dep.process(&pose(1.0, 1.0, 0.1, 0.1, 0.1)).is_ok());
}

#[test]
fn bad_settings_are_refused_with_their_name() {
    for (cfg, name) in [
        (
            DepositorConfig {
                tau: f32::NAN,
                ..Default::default()
            },
            "tau",
        ),
        (
            DepositorConfig {
                gamma_max: 0.0,
                ..Default::default()
            },
            "gamma_max",
        ),
        (
            DepositorConfig {
                rho_max: 1.5,
                ..Default::default()
            },
            "rho_max",
        ),
        (
            DepositorConfig {
                interval_m: -1.0,
                ..Default::default()
            },
            "interval_m",
        ),
        (
            DepositorConfig {
                constant_sigma_m: 1e-30,
                ..Default::default()
            },
            "constant_sigma_m",
        ),
    ] {
        let e = Depositor::new(cfg).unwrap_err();
        assert_eq!(e.name, name);
        assert!(e.to_string().contains(name), "{e}");
    }
}

#[test]
fn config_defaults_and_unknown_keys() {
    use serde::de::value::{Error as DeError, MapDeserializer};
    let partial: Result<DepositorConfig, DeError> = DepositorConfig::deserialize(
        MapDeserializer::new([("tau", 0.5f64), ("interval_s", 2.0)].into_iter()),
    );
    let partial = partial.unwrap();
    assert_eq!((partial.tau, partial.interval_s), (0.5, 2.0));
    assert_eq!(partial.gamma_max, DepositorConfig::default().gamma_max);
    let unknown: Result<DepositorConfig, DeError> =
        DepositorConfig::deserialize(MapDeserializer::new([("taw", 0.5f64)].into_iter()));
    assert!(unknown.unwrap_err().to_string().contains("taw"));
}

proptest! {
    /// Whatever the pose, a produced deposit is finite and the field accepts it (or the pose
    /// was rejected); nothing non-finite ever leaves the depositor.
    #[test]
    fn never_emits_non_finite(
        x in prop::num::f64::ANY, y in prop::num::f64::ANY,
        xx in prop::num::f64::ANY, xy in prop::num::f64::ANY, yy in prop::num::f64::ANY,
        sx in 0.0f64..10.0, sxy in -1.0f64..1.0, sy in 0.0f64..10.0,
        mode in prop::sample::select(vec![DepositMode::UncertaintyAware, DepositMode::Saturating, DepositMode::Constant]),
        wild in any::<bool>(),
    ) {
        let dep = every_pose(mode);
        // Either arbitrary bit patterns or a plausible pose with a PSD covariance.
        let p = if wild {
            pose(x, y, xx, xy, yy)
        } else {
            let c = sxy * (sx * sy).sqrt();
            pose(5.0, 5.0, sx, c, sy)
        };
        if let Ok(m) = dep.deposit_for(&p) {
            prop_assert!(msg_is_finite(&m));
            if !wild {
                let cfg = FieldConfig {
                    width: 200,
                    height: 200,
                    cell_size_m: 0.05,
                    ..FieldConfig::default()
                };
                prop_assert!(prepare(&m, &cfg.geometry(), &cfg.channels, &DepositLimits::default()).is_ok());
            }
        }
    }
}
