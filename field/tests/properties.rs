//! Property tests of the numeric kernels: evaporation, ambient mean, deposits, never a NaN.
//!
//! Property tests of the numeric kernels (DESIGN.md "Style": proptest + approx): evaporation never
//! increases a cell, each model matches its closed form, the running-sum ambient mean equals the
//! brute-force one, deposits add exactly what they claim, and no input ever puts a NaN in a frame.

use approx::assert_relative_eq;
use pheromone_field::deposit::{prepare, DepositLimits, REJECT_REASONS};
use pheromone_field::models::{ambient_mean_brute, ambient_mean_plane, CELL_LIMIT};
use pheromone_field::tune::time_to_threshold_s;
use pheromone_field::{
    ChannelSpec, DepositMsg, Evaporation, FieldConfig, GridGeometry, OwnedField, Stepper,
};
use pheromone_field::{Deposit, Kernel};
use proptest::collection::vec;
use proptest::prelude::*;

// ---------------------------------------------------------------------------------------------
// Helpers and strategies

fn channel(evaporation: Evaporation, diffusion_m2_per_s: f32, signed: bool) -> ChannelSpec {
    ChannelSpec {
        name: "c".to_string(),
        evaporation,
        diffusion_m2_per_s,
        signed,
        sources: None,
    }
}

fn config(
    width: usize,
    height: usize,
    cell_size_m: f32,
    tick_hz: f32,
    channels: Vec<ChannelSpec>,
) -> FieldConfig {
    FieldConfig {
        width: width as u32,
        height: height as u32,
        cell_size_m,
        tick_hz,
        channels,
        ..FieldConfig::default()
    }
}

/// One tick of a single-channel field from `prev`, starting at field time `t0_s`.
fn tick_once(cfg: FieldConfig, t0_s: f64, prev: &[f32]) -> Vec<f32> {
    let mut stepper = Stepper::new(cfg).expect("valid config");
    stepper.sim_time_s = t0_s;
    let mut next = vec![f32::NAN; prev.len()];
    stepper.step(prev, &mut next);
    next
}

/// Non-negative cell values over many magnitudes, with plenty of exact zeros.
fn cell_value() -> impl Strategy<Value = f32> + Clone {
    prop_oneof![
        3 => Just(0.0f32),
        3 => 0.0f32..1.0,
        2 => 0.0f32..1.0e3,
        1 => 1.0e3f32..1.0e7,
        1 => 1.0e-30f32..1.0e-6,
    ]
}

/// Non-negative cell values of a moderate range (closed-form comparisons).
fn moderate_value() -> impl Strategy<Value = f32> + Clone {
    prop_oneof![1 => Just(0.0f32), 4 => 0.0f32..100.0]
}

/// `(width, height, cells)` with `1..=max_w × 1..=max_h` cells.
fn plane_of<S>(
    max_w: usize,
    max_h: usize,
    value: S,
) -> impl Strategy<Value = (usize, usize, Vec<f32>)>
where
    S: Strategy<Value = f32> + Clone,
{
    (1..=max_w, 1..=max_h)
        .prop_flat_map(move |(w, h)| (Just(w), Just(h), vec(value.clone(), w * h)))
}

/// Applies random signs to the cells when `signed`.
fn signed_cells(cells: Vec<f32>, signs: &[bool], signed: bool) -> Vec<f32> {
    if !signed {
        return cells;
    }
    cells
        .into_iter()
        .zip(signs.iter().cycle())
        .map(|(v, &neg)| if neg { -v } else { v })
        .collect()
}

fn unit_interval() -> impl Strategy<Value = f32> + Clone {
    prop_oneof![Just(0.0f32), Just(1.0f32), 0.0f32..=1.0]
}

/// Every evaporation model, parameters anywhere in their valid range.
fn evaporation() -> impl Strategy<Value = Evaporation> {
    prop_oneof![
        Just(Evaporation::None),
        (0.0f32..20.0).prop_map(|k| Evaporation::Exponential { decay_per_s: k }),
        (0.0f32..20.0, unit_interval(), 0.0f32..3.0).prop_map(|(k, alpha, radius_m)| {
            Evaporation::Ambient {
                decay_per_s: k,
                alpha,
                radius_m,
            }
        }),
        unit_interval().prop_map(|rho| Evaporation::Saturating { rho_per_tick: rho }),
        (0.0f32..10.0, 0.001f32..2.0)
            .prop_map(|(quantum, tau_s)| Evaporation::Quantum { quantum, tau_s }),
    ]
}

fn sum_f64(cells: &[f32]) -> f64 {
    cells.iter().map(|&v| v as f64).sum()
}

fn sum_abs_f64(cells: &[f32]) -> f64 {
    cells.iter().map(|&v| (v as f64).abs()).sum()
}

// ---------------------------------------------------------------------------------------------
// Evaporation

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// |P'| ≤ |P| and the sign never flips, for every model (no diffusion), whatever the cells.
    #[test]
    fn evaporation_never_increases_a_cell(
        (w, h, cells) in plane_of(24, 24, cell_value()),
        signs in vec(any::<bool>(), 1..64),
        evaporation in evaporation(),
        signed in any::<bool>(),
        tick_hz in 0.5f32..500.0,
        cell_size_m in 0.02f32..1.0,
        t0_s in 0.0f64..100.0,
        ticks in 1usize..4,
    ) {
        // The ambient model is defined for non-negative pheromone only (validate refuses it).
        let signed = signed && !matches!(evaporation, Evaporation::Ambient { .. });
        let mut prev = signed_cells(cells, &signs, signed);
        let mut stepper = Stepper::new(config(w, h, cell_size_m, tick_hz, vec![channel(evaporation, 0.0, signed)]))
            .expect("valid config");
        stepper.sim_time_s = t0_s;
        let mut next = vec![f32::NAN; prev.len()];
        for _ in 0..ticks {
            stepper.step(&prev, &mut next);
            for (i, (&p, &n)) in prev.iter().zip(&next).enumerate() {
                prop_assert!(n.abs() <= p.abs(), "cell {i}: {p} -> {n} under {evaporation:?}");
                prop_assert!(n == 0.0 || n.signum() == p.signum(), "cell {i} changed sign: {p} -> {n}");
            }
            std::mem::swap(&mut prev, &mut next);
        }
    }

    /// Diffusion on its own conserves mass on the closed (zero-flux) grid; with exponential decay
    /// the total falls by exactly e^(−K·dt) per tick.
    #[test]
    fn diffusion_conserves_mass(
        (w, h, cells) in plane_of(20, 20, cell_value()),
        signs in vec(any::<bool>(), 1..64),
        signed in any::<bool>(),
        kappa in 0.0f32..0.249,
        decay_per_s in prop_oneof![Just(0.0f32), 0.0f32..2.0],
        tick_hz in 1.0f32..100.0,
        cell_size_m in 0.02f32..1.0,
        ticks in 1usize..6,
    ) {
        let dt = 1.0 / tick_hz;
        let d = kappa * cell_size_m * cell_size_m / dt;
        let evaporation = if decay_per_s == 0.0 {
            Evaporation::None
        } else {
            Evaporation::Exponential { decay_per_s }
        };
        let mut prev = signed_cells(cells, &signs, signed);
        let mut stepper =
            Stepper::new(config(w, h, cell_size_m, tick_hz, vec![channel(evaporation, d, signed)])).expect("valid config");
        let factor = (-(decay_per_s as f64) * dt as f64).exp();
        let mut next = vec![f32::NAN; prev.len()];
        for _ in 0..ticks {
            let (before, scale) = (sum_f64(&prev), sum_abs_f64(&prev));
            stepper.step(&prev, &mut next);
            let after = sum_f64(&next);
            prop_assert!(
                (after - before * factor).abs() <= 1e-5 * scale + 1e-30,
                "mass {before} -> {after}, expected {} (κ = {kappa}, {w}×{h})",
                before * factor
            );
            std::mem::swap(&mut prev, &mut next);
        }
    }

    /// Exponential: P' = P·e^(−K·dt).
    #[test]
    fn exponential_matches_its_closed_form(
        (w, h, cells) in plane_of(16, 16, cell_value()),
        decay_per_s in 0.0f32..20.0,
        tick_hz in 0.5f32..500.0,
    ) {
        let next = tick_once(
            config(w, h, 0.05, tick_hz, vec![channel(Evaporation::Exponential { decay_per_s }, 0.0, false)]),
            0.0,
            &cells,
        );
        let e = (-(decay_per_s as f64) / tick_hz as f64).exp();
        for (&p, &n) in cells.iter().zip(&next) {
            assert_relative_eq!(n as f64, p as f64 * e, max_relative = 1e-5, epsilon = 1e-37);
        }
    }

    /// Ambient (seed 000 eq. 22 with the M1 decision): P' = P·e + (1 − e)·min(P, α·Pa), Pa the
    /// brute-force window mean.
    #[test]
    fn ambient_matches_its_closed_form(
        (w, h, cells) in plane_of(20, 20, moderate_value()),
        decay_per_s in 0.0f32..20.0,
        alpha in unit_interval(),
        radius_m in 0.0f32..2.0,
        cell_size_m in 0.05f32..0.5,
        tick_hz in 0.5f32..500.0,
    ) {
        let evaporation = Evaporation::Ambient { decay_per_s, alpha, radius_m };
        let next = tick_once(config(w, h, cell_size_m, tick_hz, vec![channel(evaporation, 0.0, false)]), 0.0, &cells);
        let r = (radius_m / cell_size_m).round() as usize;
        let e = (-(decay_per_s as f64) / tick_hz as f64).exp();
        for y in 0..h {
            for x in 0..w {
                let p = cells[y * w + x] as f64;
                let pa = ambient_mean_brute(&cells, w, x, y, r) as f64;
                let expected = p * e + (1.0 - e) * p.min(alpha as f64 * pa);
                assert_relative_eq!(next[y * w + x] as f64, expected, max_relative = 1e-5, epsilon = 1e-4);
            }
        }
    }

    /// Saturating (seeds 001/004): ξ' = ξ·(1 − ρ).
    #[test]
    fn saturating_matches_its_closed_form(
        (w, h, cells) in plane_of(16, 16, -1.0f32..=1.0),
        rho in unit_interval(),
    ) {
        let next = tick_once(
            config(w, h, 0.05, 10.0, vec![channel(Evaporation::Saturating { rho_per_tick: rho }, 0.0, true)]),
            0.0,
            &cells,
        );
        for (&p, &n) in cells.iter().zip(&next) {
            assert_relative_eq!(n as f64, p as f64 * (1.0 - rho as f64), max_relative = 1e-6, epsilon = 1e-37);
        }
    }

    /// Quantum counter (seed 002, M3): after n·τ seconds of ticks a cell has lost n·Q, never
    /// crossing 0; one tick earlier it had lost (n − 1)·Q.
    #[test]
    fn quantum_loses_one_quantum_per_tau(
        (w, h, cells) in plane_of(6, 6, 0.0f32..100.0),
        signs in vec(any::<bool>(), 1..16),
        tick_hz in prop::sample::select(vec![1.0f32, 3.0, 7.0, 10.0, 13.0, 20.0, 30.0, 49.0, 50.0, 60.0, 100.0, 1000.0]),
        ticks_per_tau in 1u32..12,
        n in 1u32..6,
        quantum in 0.01f32..20.0,
    ) {
        let tau_s = (ticks_per_tau as f64 / tick_hz as f64) as f32;
        let cells = signed_cells(cells, &signs, true);
        let cfg = config(w, h, 0.05, tick_hz, vec![channel(Evaporation::Quantum { quantum, tau_s }, 0.0, true)]);
        let mut f = OwnedField::with_cells(cfg, cells.clone()).expect("valid field");
        let expect = |lost: u32, p: f32| {
            let m = (p.abs() as f64 - lost as f64 * quantum as f64).max(0.0);
            m.copysign(p as f64)
        };
        let total = n * ticks_per_tau;
        for _ in 0..total - 1 {
            f.tick();
        }
        for (&p, &v) in cells.iter().zip(f.cells()) {
            let e = expect(n - 1, p);
            prop_assert!((v as f64 - e).abs() <= 1e-4 * (p.abs() as f64 + 1.0),
                "after {} ticks of {tick_hz} Hz (τ = {tau_s} s): {p} -> {v}, expected {e}", total - 1);
        }
        f.tick();
        for (&p, &v) in cells.iter().zip(f.cells()) {
            let e = expect(n, p);
            prop_assert!((v as f64 - e).abs() <= 1e-4 * (p.abs() as f64 + 1.0),
                "after {total} ticks of {tick_hz} Hz (τ = {tau_s} s): {p} -> {v}, expected {e}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// The running-sum ambient mean equals the brute-force window mean, for any grid shape and any
    /// radius (including 0 and larger than the grid), and is never negative for non-negative cells.
    #[test]
    fn fast_ambient_mean_equals_brute_force(
        w in prop_oneof![1usize..=7, 8usize..=32],
        h in 1usize..=24,
        r in prop_oneof![0usize..=3, 0usize..=40],
        seed_cells in vec(cell_value(), 32 * 24),
    ) {
        let cells = &seed_cells[..w * h];
        let fast = ambient_mean_plane(cells, w, r);
        prop_assert_eq!(fast.len(), cells.len());
        let max = cells.iter().copied().fold(0.0f32, f32::max) as f64;
        for y in 0..h {
            for x in 0..w {
                let brute = ambient_mean_brute(cells, w, x, y, r) as f64;
                let got = fast[y * w + x] as f64;
                prop_assert!(got >= 0.0, "({x}, {y}) r = {r}: negative mean {got}");
                prop_assert!(
                    (got - brute).abs() <= 1e-6 * brute + 1e-12 * max,
                    "({x}, {y}) of {w}×{h}, r = {r}: fast {got} vs brute {brute}"
                );
            }
        }
    }
}

/// Round-off of the running column sums must not make a mean negative: [1, 1e-17, 0] in a
/// column; with r = 0 the sums go 1 → 1 + 1e-17 − 1 = 0 → 0 + 0 − 1e-17 < 0 in f64.
#[test]
fn running_sum_round_off_never_makes_mass_negative() {
    let cells = [1.0f32, 1.0e-17, 0.0];
    let fast = ambient_mean_plane(&cells, 1, 0);
    assert!(fast.iter().all(|&m| m >= 0.0), "{fast:?}");
    let evaporation = Evaporation::Ambient {
        decay_per_s: 1.0,
        alpha: 1.0,
        radius_m: 0.0,
    };
    let next = tick_once(
        config(1, 3, 0.1, 10.0, vec![channel(evaporation, 0.0, false)]),
        0.0,
        &cells,
    );
    assert!(
        next.iter().zip(&cells).all(|(n, p)| *n >= 0.0 && n <= p),
        "{cells:?} -> {next:?}"
    );
}

/// Seed 000's own check: K = 0.0057 s⁻¹, P0 = 35, Pa = 0 falls to 18 in about 116 s — run tick by
/// tick at dt = 0.1 s with plain exponential decay and with the ambient model at α = 0.
#[test]
fn papers_check_35_to_18_in_about_116_s_tick_by_tick() {
    let k = 0.0057f32;
    let formula = time_to_threshold_s(35.0, k as f64, 18.0, 0.0).unwrap();
    for evaporation in [
        Evaporation::Exponential { decay_per_s: k },
        Evaporation::Ambient {
            decay_per_s: k,
            alpha: 0.0,
            radius_m: 0.2,
        },
    ] {
        let cfg = config(4, 4, 0.1, 10.0, vec![channel(evaporation, 0.0, false)]);
        let mut f = OwnedField::with_cells(cfg, vec![35.0; 16]).unwrap();
        let mut ticks = 0u32;
        while f.cells()[5] > 18.0 {
            f.tick();
            ticks += 1;
            assert!(ticks < 10_000, "never reached 18");
        }
        let t = ticks as f64 * 0.1;
        assert!(
            (t - 116.0).abs() <= 1.0,
            "{evaporation:?}: reached 18 at {t} s"
        );
        assert!(
            (t - formula).abs() <= 0.1 + 1e-9,
            "{evaporation:?}: {t} s vs eq. 26 {formula} s"
        );
        assert!(
            f.cells().iter().all(|&v| v == f.cells()[0]),
            "a uniform field stays uniform"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Deposits

fn rotated_cov(s1_m: f64, s2_m: f64, angle: f64) -> [f32; 3] {
    let (s, c) = angle.sin_cos();
    let (v1, v2) = (s1_m * s1_m, s2_m * s2_m);
    [
        (v1 * c * c + v2 * s * s) as f32,
        ((v1 - v2) * c * s) as f32,
        (v1 * s * s + v2 * c * c) as f32,
    ]
}

fn one_channel(signed: bool, evaporation: Evaporation) -> Vec<ChannelSpec> {
    vec![channel(evaporation, 0.0, signed)]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Ellipse kernel γ·exp(−½ dᵀΣ⁻¹d): well inside the grid with z_rng ≫ σ ≫ h, the grid gains
    /// γ·2π·√det Σ (cell sum × h²) within 2 %.
    #[test]
    fn ellipse_deposit_adds_its_gaussian_mass(
        s1_cells in 1.5f64..8.0,
        s2_cells in 1.5f64..8.0,
        angle in 0.0f64..std::f64::consts::PI,
        gamma in 0.1f64..100.0,
        jitter in (-1.0f32..1.0, -1.0f32..1.0),
    ) {
        let h = 0.05f32;
        let range_cells = 6.0 * s1_cells.max(s2_cells);
        let side = (2.0 * range_cells).ceil() as usize + 8;
        let g = GridGeometry::new(side as u32, side as u32, h).unwrap();
        let cov = rotated_cov(s1_cells * h as f64, s2_cells * h as f64, angle);
        let det = cov[0] as f64 * cov[2] as f64 - cov[1] as f64 * cov[1] as f64;
        let tau = (gamma * det) as f32;
        let centre = 0.5 * side as f32 * h;
        let msg = DepositMsg::from(Deposit { channel: 0, x_m: centre + jitter.0 * h, y_m: centre + jitter.1 * h, kernel: Kernel::Ellipse { tau, cov_m2: cov, range_m: range_cells as f32 * h, gamma_max: 1.0e6 } });
        let d = prepare(&msg, &g, &one_channel(false, Evaporation::None), &DepositLimits::default()).unwrap();
        let prev = vec![0.0f32; g.cells()];
        let mut plane = prev.clone();
        let added = d.apply(&g, &prev, &mut plane, 0.0, CELL_LIMIT);
        let mass = sum_f64(&plane) * (h as f64).powi(2);
        let expected = gamma * 2.0 * std::f64::consts::PI * det.sqrt();
        prop_assert!((mass / expected - 1.0).abs() < 0.02, "mass {mass} vs γ·2π·√det = {expected}");
        assert_relative_eq!(added, sum_f64(&plane), max_relative = 1e-9);
    }

    /// Z-shape (seed 002 eq. 1) on a fine grid: the cells sum to amount·π(c² + cσ + σ²/3)/h².
    #[test]
    fn z_shape_deposit_adds_its_cone_mass(
        plateau_m in 0.0f32..0.6,
        slope_m in 0.06f32..0.6,
        amount in 0.1f32..50.0,
        jitter in (-1.0f32..1.0, -1.0f32..1.0),
    ) {
        let h = 0.02f32;
        let side = (2.0 * (plateau_m + slope_m) / h).ceil() as usize + 8;
        let g = GridGeometry::new(side as u32, side as u32, h).unwrap();
        let centre = 0.5 * side as f32 * h;
        let msg = DepositMsg::from(Deposit { channel: 0, x_m: centre + jitter.0 * h, y_m: centre + jitter.1 * h, kernel: Kernel::ZShape { amount, plateau_m, slope_m } });
        let d = prepare(&msg, &g, &one_channel(false, Evaporation::None), &DepositLimits::default()).unwrap();
        let prev = vec![0.0f32; g.cells()];
        let mut plane = prev.clone();
        d.apply(&g, &prev, &mut plane, 0.0, CELL_LIMIT);
        let (c, s) = (plateau_m as f64, slope_m as f64);
        let expected = amount as f64 * std::f64::consts::PI * (c * c + c * s + s * s / 3.0) / (h as f64).powi(2);
        let got = sum_f64(&plane);
        prop_assert!((got / expected - 1.0).abs() < 0.02, "sum {got} vs {expected} (c = {c}, σ = {s})");
    }

    /// `apply` returns exactly the increase of the plane's sum (each cell's f64 increment, summed),
    /// whatever the background, kernel, sign and clamping.
    #[test]
    fn apply_returns_the_actual_sum_increase(
        (w, h, cells) in plane_of(40, 40, cell_value()),
        signs in vec(any::<bool>(), 1..64),
        signed in any::<bool>(),
        kernel in 0u32..4,
        pos in (0.0f32..1.0, 0.0f32..1.0),
        amount in prop_oneof![0.0f32..1.0, 0.0f32..1.0e4],
        negative in any::<bool>(),
        cov in (0.0001f32..0.5, -1.0f32..1.0, 0.0001f32..0.5),
        range_m in 0.05f32..2.0,
        gamma_max in 1.0f32..1.0e6,
        sigma_m in 0.01f32..1.0,
        shape in (0.0f32..1.0, 0.0f32..1.0),
    ) {
        let cell = 0.05f32;
        let g = GridGeometry::new(w as u32, h as u32, cell).unwrap();
        let evaporation = if kernel == 2 { Evaporation::Saturating { rho_per_tick: 0.1 } } else { Evaporation::None };
        let channels = one_channel(signed, evaporation);
        let (lo, hi) = channels[0].value_range();
        let before: Vec<f32> = signed_cells(cells, &signs, signed).into_iter().map(|v| v.clamp(lo, hi)).collect();
        let mut amount = if kernel == 2 { amount.min(1.0) } else { amount };
        if signed && negative {
            amount = -amount;
        }
        let xy = cov.1 * (cov.0 * cov.2).sqrt();
        let msg = DepositMsg {
            kernel,
            x_m: pos.0 * g.width_m(),
            y_m: pos.1 * g.height_m(),
            amount,
            cov_xx: cov.0,
            cov_xy: xy,
            cov_yy: cov.2,
            range_m,
            gamma_max,
            sigma_m,
            plateau_m: shape.0,
            slope_m: shape.1,
            ..DepositMsg::default()
        };
        let d = prepare(&msg, &g, &channels, &DepositLimits::default());
        // Rounding can make a borderline covariance non-PSD; that is not this property.
        prop_assume!(d.is_ok(), "rejected: {:?}", d);
        let d = d.unwrap();
        let mut after = before.clone();
        let added = d.apply(&g, &before, &mut after, lo, hi);
        let (actual, scale) = before.iter().zip(&after).fold((0.0f64, 0.0f64), |(s, a), (&b, &n)| {
            let inc = n as f64 - b as f64;
            (s + inc, a + inc.abs())
        });
        prop_assert!(
            (added - actual).abs() <= 1e-12 * scale,
            "apply says {added}, the plane gained {actual} (Σ|Δ| = {scale})"
        );
        prop_assert!(after.iter().all(|v| v.is_finite() && *v >= lo && *v <= hi));
    }

    /// Saturating deposits (seed 001 eq. 3) never push a cell beyond ±1 (or below 0 when unsigned),
    /// however many pile up on the same cells in one tick.
    #[test]
    fn saturating_deposits_stay_within_one(
        (w, h, cells) in plane_of(24, 24, 0.0f32..=1.0),
        signs in vec(any::<bool>(), 1..64),
        signed in any::<bool>(),
        rho_per_tick in unit_interval(),
        deposits in vec(((0.0f32..1.0, 0.0f32..1.0), -1.0f32..=1.0, 0.02f32..0.5, 0.05f32..1.0), 1..12),
        ticks in 1usize..4,
    ) {
        let cells = signed_cells(cells, &signs, signed);
        let cfg = config(w, h, 0.05, 20.0, one_channel(signed, Evaporation::Saturating { rho_per_tick }));
        let g = cfg.geometry();
        let mut f = OwnedField::with_cells(cfg, cells).unwrap();
        let lo = if signed { -1.0 } else { 0.0 };
        for _ in 0..ticks {
            for &((px, py), rho, sigma_m, range_m) in &deposits {
                let rho = if signed { rho } else { rho.abs() };
                // Land several on the same spot: positions snap to a coarse lattice.
                let x = (px * 4.0).floor() / 4.0 * g.width_m();
                let y = (py * 4.0).floor() / 4.0 * g.height_m();
                f.offer(&DepositMsg::from(Deposit { channel: 0, x_m: x, y_m: y, kernel: Kernel::Saturating { rho, sigma_m, range_m } })).unwrap();
            }
            f.tick();
            prop_assert!(f.cells().iter().all(|&v| (lo..=1.0).contains(&v)), "{:?}", f.cells());
        }
    }
}

// ---------------------------------------------------------------------------------------------
// No input makes a NaN

/// Any f32: arbitrary bit patterns, the special values, and plausible numbers.
fn wild_f32() -> impl Strategy<Value = f32> + Clone {
    prop_oneof![
        3 => any::<u32>().prop_map(f32::from_bits),
        2 => prop::sample::select(vec![
            f32::NAN,
            -f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            f32::EPSILON,
            1.0e-45,
            1.0e-30,
            1.0e-20,
            1.0e30,
            -1.0,
            -0.0,
            0.0,
            0.05,
            0.1,
            1.0,
        ]),
        4 => -1.0f32..4.0,
        2 => 0.0f32..0.2,
    ]
}

fn wild_msg(cell_size_m: f32) -> impl Strategy<Value = DepositMsg> {
    (
        prop_oneof![8 => 0u32..3, 1 => any::<u32>()],
        prop_oneof![8 => 0u32..4, 1 => any::<u32>()],
        prop::array::uniform11(wild_f32()),
        any::<bool>(),
        any::<bool>(),
    )
        .prop_map(move |(channel, kernel, mut v, centred, scaled)| {
            if scaled {
                // Lengths in cells rather than metres, so that tiny and huge cells get kernels
                // that fit their grid.
                for (i, x) in v.iter_mut().enumerate().skip(3) {
                    *x *= if i < 6 {
                        cell_size_m * cell_size_m
                    } else if i == 7 {
                        1.0
                    } else {
                        cell_size_m
                    };
                }
            }
            // Sometimes land exactly on a cell centre (d = 0 makes 0·∞ possible in a kernel).
            let (x_m, y_m) = if centred {
                (2.5 * cell_size_m, 3.5 * cell_size_m)
            } else {
                (v[0] * cell_size_m * 10.0, v[1] * cell_size_m * 10.0)
            };
            DepositMsg {
                channel,
                kernel,
                x_m,
                y_m,
                amount: v[2],
                cov_xx: v[3],
                cov_xy: v[4],
                cov_yy: v[5],
                range_m: v[6],
                gamma_max: v[7],
                sigma_m: v[8],
                plateau_m: v[9],
                slope_m: v[10],
                ..DepositMsg::default()
            }
        })
}

fn wild_field(cell_size_m: f32) -> FieldConfig {
    let mut anti = channel(Evaporation::Saturating { rho_per_tick: 0.05 }, 0.0, true);
    anti.name = "anti".into();
    let mut counter = channel(
        Evaporation::Quantum {
            quantum: 1.0,
            tau_s: 0.3,
        },
        // κ = D·dt/h² = 0.1 whatever the cell size (none where h² overflows).
        Some(0.1 * cell_size_m * cell_size_m * 10.0)
            .filter(|d| d.is_finite())
            .unwrap_or(0.0),
        true,
    );
    counter.name = "counter".into();
    let trail = ChannelSpec::new(
        "trail",
        Evaporation::Ambient {
            decay_per_s: 0.5,
            alpha: 0.5,
            radius_m: 0.3,
        },
    );
    config(32, 24, cell_size_m, 10.0, vec![trail, anti, counter])
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// Whatever is offered, every cell of every frame stays finite and within its channel's range,
    /// and every rejection is counted once, under its reason.
    #[test]
    fn no_input_makes_a_nan(
        (cell_size_m, batches) in prop::sample::select(vec![1.0e-20f32, 1.0e-9, 1.0e-3, 0.1, 0.1, 0.1, 5.0, 1.0e30])
            .prop_flat_map(|h| (Just(h), vec(vec(wild_msg(h), 0..24), 1..5)))
    ) {
        let cfg = wild_field(cell_size_m);
        let ranges: Vec<(f32, f32)> = cfg.channels.iter().map(|c| c.value_range()).collect();
        let n = cfg.geometry().cells();
        let mut f = OwnedField::new(cfg).unwrap();
        let (mut accepted, mut rejected) = (0u64, 0u64);
        for batch in &batches {
            for msg in batch {
                let before = f.stepper.counters;
                match f.offer(msg) {
                    Ok(()) => {
                        accepted += 1;
                        prop_assert_eq!(before.rejected, f.stepper.counters.rejected);
                    }
                    Err(r) => {
                        rejected += 1;
                        let i = r.reason as usize;
                        prop_assert!(i < REJECT_REASONS);
                        prop_assert_eq!(f.stepper.counters.rejected[i], before.rejected[i] + 1, "{}", r);
                        prop_assert_eq!(f.stepper.counters.rejected_total(), before.rejected_total() + 1);
                    }
                }
            }
            let report = f.tick();
            prop_assert!(report.mass_added.is_finite());
            for (c, &(lo, hi)) in ranges.iter().enumerate() {
                let plane = &f.cells()[c * n..(c + 1) * n];
                if let Some(i) = plane.iter().position(|v| !(v.is_finite() && *v >= lo && *v <= hi)) {
                    prop_assert!(false, "channel {c} cell {i} = {} after {batch:?}", plane[i]);
                }
            }
        }
        prop_assert_eq!(f.stepper.counters.rejected_total(), rejected);
        prop_assert_eq!(f.stepper.counters.applied, accepted);
    }
}

/// A saturating deposit with a vanishing λ centred exactly on a cell: 1/λ² overflows to ∞ and the
/// centre cell has d² = 0, so the kernel must not evaluate 0·∞.
#[test]
fn vanishing_sigma_on_a_cell_centre_stays_finite() {
    let mut f = OwnedField::new(config(
        8,
        8,
        0.1,
        10.0,
        one_channel(true, Evaporation::Saturating { rho_per_tick: 0.1 }),
    ))
    .unwrap();
    for sigma_m in [1.0e-30f32, 1.0e-45, f32::MIN_POSITIVE] {
        // (0.45, 0.45) m is the centre of cell (4, 4).
        if f.offer(&DepositMsg::from(Deposit {
            channel: 0,
            x_m: 0.45,
            y_m: 0.45,
            kernel: Kernel::Saturating {
                rho: 0.5,
                sigma_m,
                range_m: 0.2,
            },
        }))
        .is_ok()
        {
            f.tick();
        }
        assert_eq!(
            f.view().non_finite_cells(),
            0,
            "σ = {sigma_m}: {:?}",
            f.cells()
        );
    }
}

/// With sub-nanometre cells, 1/λ² of the `paper` kernel overflows f32; the kernel constants are
/// saturated instead of turning into ∞·0 = NaN.
#[test]
fn paper_kernel_on_tiny_cells_stays_finite() {
    for h in [1.0e-20f32, 1.0e-10] {
        for kernel in [0u32, 1] {
            let cfg = config(8, 8, h, 10.0, one_channel(false, Evaporation::None));
            let mut f = OwnedField::new(cfg).unwrap();
            let msg = DepositMsg {
                kernel,
                x_m: 4.5 * h,
                y_m: 4.5 * h,
                amount: 1.0,
                range_m: 3.0 * h,
                gamma_max: 10.0,
                ..DepositMsg::default()
            };
            f.offer(&msg).unwrap();
            let report = f.tick();
            assert_eq!(f.view().non_finite_cells(), 0, "h = {h}, kernel {kernel}");
            assert!(report.mass_added >= 10.0, "the centre cell gets γ = γmax");
        }
    }
}

/// The default 50 Hz tick (dt = 0.02f32, a hair under 0.02 s) with τ = 1 s: the first quantum
/// goes after exactly 50 ticks, not 51.
#[test]
fn quantum_counts_whole_seconds_at_50_hz() {
    let evaporation = Evaporation::Quantum {
        quantum: 1.0,
        tau_s: 1.0,
    };
    let cfg = config(1, 1, 0.05, 50.0, vec![channel(evaporation, 0.0, false)]);
    let mut f = OwnedField::with_cells(cfg, vec![10.0]).unwrap();
    for tick in 1..=500 {
        f.tick();
        assert_eq!(
            f.cells()[0],
            10.0 - (tick / 50) as f32,
            "after {tick} ticks"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// The banded, dispatched ambient pass (pheromone_field::ambient, pheromone_field::simd) and threads.

use pheromone_field::models::{
    ambient_mean_plane_with, step_plane_with, Dispatch, PlanePlan, Scratch,
};
use pheromone_field::models::{band_rows, BAND_ROWS_MIN};

/// Planes taller than one band, so band restarts are exercised.
fn tall_plane() -> impl Strategy<Value = (usize, usize, Vec<f32>)> {
    (1usize..=12, BAND_ROWS_MIN + 1..=2 * BAND_ROWS_MIN + 40)
        .prop_flat_map(|(w, h)| (Just(w), Just(h), vec(cell_value(), w * h)))
}

/// The dispatches to compare: portable, and AVX2 where the CPU has it.
fn dispatches() -> Vec<Dispatch> {
    let mut d = vec![Dispatch::portable()];
    d.extend(Dispatch::avx2());
    d
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Over several bands, the fast mean equals brute force within the bound of `pheromone_field::ambient`
    /// (far below 1e-6 relative here, plus a floor for cancellation against the largest cell),
    /// never NaN nor negative, and the AVX2 kernels and any thread count give the same bits as
    /// the portable kernels on one thread.
    #[test]
    fn banded_ambient_mean_equals_brute_force_and_is_dispatch_and_thread_independent(
        (w, h, cells) in tall_plane(),
        r in prop_oneof![0usize..=2, 0usize..=6],
        threads in 2usize..=4,
    ) {
        prop_assert!(band_rows(h, r) < h, "the plane spans several bands");
        let base = ambient_mean_plane_with(&cells, w, r, Dispatch::portable(), 1);
        let max = cells.iter().copied().fold(0.0f32, f32::max) as f64;
        for y in 0..h {
            for x in 0..w {
                let brute = ambient_mean_brute(&cells, w, x, y, r) as f64;
                let got = base[y * w + x] as f64;
                prop_assert!(got.is_finite() && got >= 0.0, "({x}, {y}): {got}");
                prop_assert!(
                    (got - brute).abs() <= 1e-6 * brute + 1e-12 * max,
                    "({x}, {y}) of {w}×{h}, r = {r}: fast {got} vs brute {brute}"
                );
            }
        }
        for d in dispatches() {
            for t in [1, threads] {
                let other = ambient_mean_plane_with(&cells, w, r, d, t);
                prop_assert!(
                    other.iter().zip(&base).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{} on {t} threads differs from portable on 1", d.name()
                );
            }
        }
    }

    /// The fused ambient step never raises a cell, never writes NaN or a negative value, and
    /// gives the same bits for the AVX2 and portable kernels and for any thread count — with and
    /// without diffusion.
    #[test]
    fn banded_ambient_step_never_increases_and_is_dispatch_and_thread_independent(
        (w, _h, cells) in tall_plane(),
        r in 0u32..=6,
        factor in 0.0f32..=1.0,
        alpha in prop_oneof![Just(0.0f32), 0.0f32..=1.0, Just(1.0f32)],
        kappa in prop_oneof![Just(0.0f32), 0.0f32..=0.2],
        threads in 2usize..=4,
    ) {
        let plan = PlanePlan::Ambient { factor, alpha, radius_cells: r };
        let step = |d: Dispatch, t: usize| {
            let mut next = vec![f32::NAN; cells.len()];
            step_plane_with(plan, kappa, w, &cells, &mut next, &mut Scratch::default(), t, d);
            next
        };
        let base = step(Dispatch::portable(), 1);
        if kappa == 0.0 {
            for (i, (&n, &p)) in base.iter().zip(&cells).enumerate() {
                prop_assert!(n.is_finite() && (0.0..=p).contains(&n), "cell {i}: {p} -> {n}");
            }
        } else {
            prop_assert!(base.iter().all(|n| n.is_finite()), "NaN or ∞ in the frame");
        }
        for d in dispatches() {
            for t in [1, threads] {
                let other = step(d, t);
                prop_assert!(
                    other.iter().zip(&base).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{} on {t} threads differs from portable on 1", d.name()
                );
            }
        }
    }

    /// A Stepper on N threads produces frames bit-identical to one on 1 thread, for every model,
    /// with diffusion, over several ticks with deposits.
    #[test]
    fn stepper_threads_give_bit_identical_frames(
        evaporation in evaporation(),
        diffusion in prop_oneof![Just(0.0f32), 0.0f32..=0.03],
        (w, h) in (1usize..=24, 1usize..=2 * BAND_ROWS_MIN + 40),
        threads in 2usize..=5,
        seed in vec(cell_value(), 24),
    ) {
        let signed = matches!(
            evaporation,
            Evaporation::Saturating { .. } | Evaporation::Quantum { .. }
        );
        let cfg = config(w, h, 0.05, 50.0, vec![channel(evaporation, diffusion, signed)]);
        let cells: Vec<f32> = (0..w * h).map(|i| seed[i % seed.len()].min(1.0)).collect();
        let mut one = Stepper::new(cfg.clone()).unwrap();
        let mut many = Stepper::new(cfg).unwrap();
        many.set_threads(threads).unwrap();
        let (mut a, mut b) = (cells.clone(), cells);
        let (mut na, mut nb) = (vec![0.0f32; a.len()], vec![0.0f32; b.len()]);
        for tick in 0..3 {
            let msg = DepositMsg::from(Deposit { channel: 0, x_m: (tick as f32 + 0.5) * 0.05, y_m: h as f32 * 0.5 * 0.05, kernel: Kernel::Ellipse { tau: 0.5, cov_m2: [0.01, 0.0, 0.01], range_m: 0.15, gamma_max: 1.0 } });
            let _ = one.offer(&msg);
            let _ = many.offer(&msg);
            one.step(&a, &mut na);
            many.step(&b, &mut nb);
            std::mem::swap(&mut a, &mut na);
            std::mem::swap(&mut b, &mut nb);
            prop_assert!(
                a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "tick {tick}: {threads} threads differ from 1"
            );
        }
    }
}

#[test]
fn set_threads_refuses_zero_and_absurd_counts() {
    let mut s = Stepper::new(FieldConfig::default()).unwrap();
    for bad in [0usize, pheromone_field::engine::MAX_THREADS + 1, usize::MAX] {
        let e = s.set_threads(bad).unwrap_err().to_string();
        assert!(e.contains("threads") && e.contains(&bad.to_string()), "{e}");
    }
    assert_eq!(s.threads(), 1);
    s.set_threads(2).unwrap();
    assert_eq!(s.threads(), 2);
}
