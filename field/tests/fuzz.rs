//! Fuzzing the field's inputs: arbitrary deposits and configs never panic nor corrupt a frame.
//!
//! Fuzzing what the field accepts (issue 7, part 5): about a million deposits with arbitrary bit
//! patterns — NaN, ±inf, subnormals, 1e38, covariances that are not positive semi-definite,
//! unknown channels and kernels — offered to the tick engine on fields of every model and of
//! absurd cell sizes. Whatever comes in: no panic, no cell ever non-finite or outside its
//! channel's range, and every deposit is either applied or rejected under exactly one reason, so
//! `applied + Σ rejected[reason] == offered`, in the engine and in every frame header.
//!
//! The amount of work is configurable: `PHEROMONE_FUZZ_CASES` (default 256) cases of
//! `DEPOSITS_PER_CASE` deposits each. Also the configuration loader (`FieldConfig::from_toml` +
//! `validate`) with mutated and truncated TOML, and the shared-memory path (deposits through a
//! `DepositPublisher` into a `FieldServer`) with wild deposits.

use std::cell::RefCell;

use pheromone_field::deposit::{RejectReason, REJECT_REASONS};
use pheromone_field::{ChannelSpec, DepositMsg, Evaporation, FieldConfig, OwnedField};
use pheromone_testkit::toml_fuzz;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};

/// Deposits offered per case: 16 ticks of 256.
const DEPOSITS_PER_CASE: usize = 4096;
const PER_TICK: usize = 256;

/// Cases to run: `PHEROMONE_FUZZ_CASES`, or `default`.
fn cases(default: u32) -> u32 {
    match std::env::var("PHEROMONE_FUZZ_CASES") {
        Ok(v) => v
            .parse()
            .unwrap_or_else(|_| panic!("PHEROMONE_FUZZ_CASES = '{v}': expected a whole number")),
        Err(_) => default,
    }
}

fn runner(cases: u32) -> TestRunner {
    TestRunner::new(Config {
        cases,
        failure_persistence: None,
        ..Config::default()
    })
}

/// Cell sizes from absurdly small to absurdly large (kernel arithmetic over- and underflows).
const CELL_SIZES_M: [f32; 8] = [1.0e-20, 1.0e-6, 1.0e-3, 0.05, 0.1, 0.5, 7.0, 1.0e30];

/// A small field with one channel of each kind: ambient (unsigned), saturating (signed),
/// quantum counters (signed, diffusing), exponential (unsigned, diffusing), none (signed).
fn fuzz_field(cell_size_m: f32, origin_m: (f32, f32)) -> FieldConfig {
    let tick_hz = 20.0;
    // κ = D·dt/h² = 0.2 whatever the cell size (none where h² over- or underflows).
    let stable_diffusion = {
        let d = 0.2 * cell_size_m * cell_size_m * tick_hz;
        if d.is_finite() && d > 0.0 && (d / tick_hz / (cell_size_m * cell_size_m)) <= 0.25 {
            d
        } else {
            0.0
        }
    };
    let ch = |name: &str, evaporation, diffusion, signed| {
        let mut c = ChannelSpec::new(name, evaporation);
        c.diffusion_m2_per_s = diffusion;
        c.signed = signed;
        c
    };
    FieldConfig {
        width: 16,
        height: 12,
        cell_size_m,
        origin_x_m: origin_m.0,
        origin_y_m: origin_m.1,
        tick_hz,
        channels: vec![
            ch(
                "ambient",
                Evaporation::Ambient {
                    decay_per_s: 0.5,
                    alpha: 0.5,
                    radius_m: 3.0 * cell_size_m,
                },
                0.0,
                false,
            ),
            ch(
                "anti",
                Evaporation::Saturating { rho_per_tick: 0.05 },
                0.0,
                true,
            ),
            ch(
                "counter",
                Evaporation::Quantum {
                    quantum: 1.0,
                    tau_s: 0.2,
                },
                stable_diffusion,
                true,
            ),
            ch(
                "exp",
                Evaporation::Exponential { decay_per_s: 1.0 },
                stable_diffusion,
                false,
            ),
            ch("none", Evaporation::None, 0.0, true),
        ],
        ..FieldConfig::default()
    }
}

/// Special values every float field should meet sometimes.
const SPECIALS: [f32; 20] = [
    f32::NAN,
    -f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::MAX,
    f32::MIN,
    1.0e38,
    -1.0e38,
    f32::MIN_POSITIVE,
    1.0e-45, // smallest subnormal
    -1.0e-45,
    1.0e-40, // subnormal
    f32::EPSILON,
    1.0e-30,
    1.0e30,
    -0.0,
    0.0,
    1.0,
    -1.0,
    1.0e6,
];

/// A fast deterministic source of wild deposits (SplitMix64). proptest picks the seed, the cell
/// size and the origin of each case; generating the million deposits with proptest strategies
/// themselves would take minutes in a debug build. A failing case prints its seed and the batch.
struct Wild(u64);

impl Wild {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }

    /// Uniform in [lo, hi).
    fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A float: raw bits, a special value, or a plausible value in units of `scale`.
    fn f32(&mut self, scale: f32) -> f32 {
        match self.below(20) {
            0 => f32::from_bits(self.next() as u32),
            1 => SPECIALS[self.below(SPECIALS.len() as u64) as usize],
            2..=4 => self.uniform(0.0, 1.0),
            _ => self.uniform(-1.0, 6.0) * scale,
        }
    }

    /// Mostly `0..valid`, sometimes just past it, sometimes any u32.
    fn index(&mut self, valid: u32) -> u32 {
        match self.below(14) {
            0 => self.next() as u32,
            1 => valid + self.below(2) as u32,
            _ => self.below(valid as u64) as u32,
        }
    }

    /// A deposit message: either every field an arbitrary bit pattern (what a broken or hostile
    /// publisher could put on the wire), or a structured one — mostly a valid channel and
    /// kernel, positions and lengths in cells, covariances in cells², each field sometimes wild.
    fn msg(&mut self, cell_size_m: f32, origin_m: (f32, f32), channels: u32) -> DepositMsg {
        if self.below(6) == 0 {
            let mut f = [0f32; 11];
            for v in &mut f {
                *v = f32::from_bits(self.next() as u32);
            }
            return DepositMsg {
                stamp_ns: self.next(),
                robot_id: self.next() as u32,
                channel: if self.below(2) == 0 {
                    self.next() as u32
                } else {
                    self.below(6) as u32
                },
                kernel: if self.below(2) == 0 {
                    self.next() as u32
                } else {
                    self.below(5) as u32
                },
                x_m: f[0],
                y_m: f[1],
                amount: f[2],
                cov_xx: f[3],
                cov_xy: f[4],
                cov_yy: f[5],
                range_m: f[6],
                gamma_max: f[7],
                sigma_m: f[8],
                plateau_m: f[9],
                slope_m: f[10],
            };
        }
        let h = cell_size_m;
        let (x_m, y_m) = if self.below(4) == 0 {
            // Exactly on a cell centre: d = 0 is where 0·∞ could hide.
            (origin_m.0 + 2.5 * h, origin_m.1 + 3.5 * h)
        } else {
            (
                origin_m.0 + self.f32(4.0 * h),
                origin_m.1 + self.f32(3.0 * h),
            )
        };
        let plausible = |w: &mut Self, lo: f32, hi: f32, scale: f32| {
            if w.below(4) == 0 {
                w.f32(scale)
            } else {
                w.uniform(lo, hi) * scale
            }
        };
        DepositMsg {
            stamp_ns: 1,
            robot_id: 7,
            channel: self.index(channels),
            kernel: self.index(4),
            x_m,
            y_m,
            amount: plausible(self, -1.5, 1.5, 1.0),
            cov_xx: self.f32(h * h),
            cov_xy: self.f32(h * h),
            cov_yy: self.f32(h * h),
            range_m: plausible(self, 0.0, 4.0, h),
            gamma_max: plausible(self, 0.0, 200.0, 1.0),
            sigma_m: self.f32(h),
            plateau_m: self.f32(h),
            slope_m: self.f32(h),
        }
    }
}

/// What a whole fuzz run saw.
#[derive(Debug, Default)]
struct Totals {
    cases: u64,
    offered: u64,
    applied: u64,
    rejected: [u64; REJECT_REASONS],
    ticks: u64,
    cells_checked: u64,
}

/// Offers `msgs` in ticks of `PER_TICK`, checking the invariants after every offer and tick.
fn run_case(
    cfg: FieldConfig,
    msgs: &[DepositMsg],
    totals: &mut Totals,
) -> Result<(), TestCaseError> {
    let ranges: Vec<(f32, f32)> = cfg.channels.iter().map(|c| c.value_range()).collect();
    let n = cfg.geometry().cells();
    let mut f = OwnedField::new(cfg).map_err(|e| TestCaseError::fail(format!("config: {e}")))?;
    let mut offered = 0u64;
    for batch in msgs.chunks(PER_TICK) {
        let mut accepted_this_tick = 0u32;
        for msg in batch {
            let before = f.stepper.counters;
            let pending = f.stepper.pending();
            offered += 1;
            match f.offer(msg) {
                Ok(()) => {
                    accepted_this_tick += 1;
                    prop_assert_eq!(
                        before,
                        f.stepper.counters,
                        "an accepted deposit counted as rejected"
                    );
                    prop_assert_eq!(f.stepper.pending(), pending + 1);
                }
                Err(r) => {
                    let i = r.reason as usize;
                    prop_assert!(!r.detail.is_empty(), "a rejection without detail: {:?}", r);
                    let mut expected = before.rejected;
                    expected[i] += 1;
                    prop_assert_eq!(
                        expected,
                        f.stepper.counters.rejected,
                        "{} not counted once under its reason",
                        r
                    );
                    prop_assert_eq!(f.stepper.pending(), pending);
                    totals.rejected[i] += 1;
                }
            }
        }
        let report = f.tick();
        totals.ticks += 1;
        prop_assert_eq!(report.deposits_applied, accepted_this_tick);
        prop_assert!(
            report.mass_added.is_finite(),
            "mass added {}",
            report.mass_added
        );
        for (c, &(lo, hi)) in ranges.iter().enumerate() {
            let plane = &f.cells()[c * n..(c + 1) * n];
            if let Some(i) = plane
                .iter()
                .position(|v| !(v.is_finite() && *v >= lo && *v <= hi))
            {
                prop_assert!(
                    false,
                    "channel {} cell {} = {} (range [{}, {}]) after a tick of {:?}",
                    c,
                    i,
                    plane[i],
                    lo,
                    hi,
                    batch
                );
            }
        }
        totals.cells_checked += f.cells().len() as u64;
        prop_assert_eq!(f.view().non_finite_cells(), 0);
        // The header every reader gets carries the same counts.
        let header = f.stepper.header(0, 0, &report);
        prop_assert_eq!(header.deposits_rejected, f.stepper.counters.rejected);
        prop_assert_eq!(header.deposits_applied, f.stepper.counters.applied);
        prop_assert_eq!(header.deposits_this_tick, accepted_this_tick);
        totals.applied += accepted_this_tick as u64;
    }
    let c = f.stepper.counters;
    prop_assert_eq!(
        c.applied + c.rejected_total(),
        offered,
        "offered ≠ applied + rejected"
    );
    totals.offered += offered;
    totals.cases += 1;
    Ok(())
}

#[test]
fn a_million_wild_deposits_never_make_a_non_finite_cell_and_every_rejection_is_counted() {
    let strategy = (
        prop::sample::select(&CELL_SIZES_M[..]),
        prop::sample::select(vec![(0.0f32, 0.0f32), (-3.0, 2.0), (-1.0e6, 5.0e5)]),
        any::<u64>(),
    )
        .prop_map(|(h, origin, seed)| {
            // A huge origin on tiny cells is not a valid grid (its cells would not be
            // distinguishable in f32); keep the origin in proportion to the grid.
            (h, (origin.0 * h.min(1.0), origin.1 * h.min(1.0)), seed)
        });
    let totals = RefCell::new(Totals::default());
    let started = std::time::Instant::now();
    let result = runner(cases(256)).run(&strategy, |(h, origin, seed)| {
        let cfg = fuzz_field(h, origin);
        let channels = cfg.channels.len() as u32;
        let mut wild = Wild(seed);
        let msgs: Vec<DepositMsg> = (0..DEPOSITS_PER_CASE)
            .map(|_| wild.msg(h, origin, channels))
            .collect();
        run_case(cfg, &msgs, &mut totals.borrow_mut())
    });
    let t = totals.into_inner();
    let reasons: Vec<String> = RejectReason::ALL
        .iter()
        .map(|r| format!("{} {}", r.name(), t.rejected[*r as usize]))
        .collect();
    eprintln!(
        "deposit fuzz: {} cases, {} deposits offered, {} applied, {} rejected ({}), {} ticks, \
         {} cells checked finite, {:.1} s",
        t.cases,
        t.offered,
        t.applied,
        t.rejected.iter().sum::<u64>(),
        reasons.join(", "),
        t.ticks,
        t.cells_checked,
        started.elapsed().as_secs_f64()
    );
    if let Err(e) = result {
        panic!("{e}");
    }
    assert_eq!(t.offered, t.applied + t.rejected.iter().sum::<u64>());
    // The generator must reach every branch, or the test proves little.
    assert!(t.applied > 0, "no deposit was ever valid: {t:?}");
    for r in RejectReason::ALL {
        assert!(
            t.rejected[r as usize] > 0,
            "no deposit was rejected as {}: {t:?}",
            r.name()
        );
    }
}

/// The configuration loader with mutated TOML: every input is either a valid configuration or an
/// error naming the line (parse errors) or the setting and its value (validation) — never a panic.
#[test]
fn mutated_config_files_are_refused_with_a_reason_never_a_panic() {
    let good = toml::to_string_pretty(&fuzz_field(0.05, (0.0, 0.0))).unwrap();
    assert!(FieldConfig::from_toml(&good).unwrap().validate().is_ok());
    let lines: Vec<String> = good.lines().map(str::to_string).collect();
    let refused = std::cell::Cell::new(0u64);
    let accepted = std::cell::Cell::new(0u64);
    let result = runner(cases(256) * 4).run(&toml_fuzz::mutations(lines.len()), |muts| {
        let text = toml_fuzz::apply(&lines, &muts);
        match FieldConfig::from_toml(&text) {
            Ok(c) => match c.validate() {
                Ok(()) => accepted.set(accepted.get() + 1),
                Err(e) => {
                    refused.set(refused.get() + 1);
                    let e = e.to_string();
                    prop_assert!(
                        e.contains(" = "),
                        "validation error names no setting: {}",
                        e
                    );
                }
            },
            Err(e) => {
                refused.set(refused.get() + 1);
                let e = e.to_string();
                prop_assert!(
                    e.contains("line ") || e.contains("missing field"),
                    "parse error without a line: {}\n--- input ---\n{}",
                    e,
                    text
                );
            }
        }
        Ok(())
    });
    let (accepted, refused) = (accepted.get(), refused.get());
    eprintln!("config fuzz: {accepted} accepted, {refused} refused");
    if let Err(e) = result {
        panic!("{e}");
    }
    assert!(
        refused > 0 && accepted > 0,
        "{accepted} accepted, {refused} refused"
    );
}

/// The same deposits through shared memory: a `DepositPublisher` sends wild deposits to a
/// `FieldServer` in this process; the frames' headers account for every one and no frame holds a
/// non-finite cell.
#[test]
fn wild_deposits_through_shared_memory_are_accounted_in_the_frame_header() {
    use pheromone_field::shm::{create_node, DepositPublisher, FieldReader, FieldServer};
    use std::time::Duration;
    pheromone_field::shm::set_verbose(false);
    let name = format!(
        "fuzz-{}-{}",
        std::process::id(),
        pheromone_field::shm::now_ns() % 1_000_000_007
    );
    let node = create_node(&name).unwrap();
    let cfg = FieldConfig {
        deposit_buffer: 512,
        max_readers: 2,
        ..fuzz_field(0.1, (-0.3, 0.2))
    };
    let mut server = FieldServer::start(&node, &name, cfg, None).unwrap();
    let mut reader = FieldReader::attach(&node, &name).unwrap();
    let mut publisher = DepositPublisher::attach(&node, &name, 3).unwrap();
    // Every batch is taken by the tick that follows it: nothing to wait for when dropped.
    publisher.flush_timeout = Duration::ZERO;
    let mut wild = Wild(0x5eed);
    let msgs: Vec<DepositMsg> = (0..4 * 512)
        .map(|_| wild.msg(0.1, (-0.3, 0.2), 5))
        .collect();
    let mut sent = 0u64;
    for batch in msgs.chunks(512) {
        for m in batch {
            publisher
                .send(*m)
                .expect("the field's buffer holds a whole batch");
            sent += 1;
        }
        server.tick().unwrap();
        assert!(reader.wait_frame(Duration::from_secs(5)).unwrap());
        let f = reader.frame().unwrap();
        assert_eq!(f.view.non_finite_cells(), 0);
        assert_eq!(
            f.header.deposits_applied + f.header.deposits_rejected_total(),
            sent,
            "every deposit sent is applied or rejected by reason: {:?}",
            f.header
        );
    }
    let c = server.stepper().counters;
    eprintln!(
        "shared-memory fuzz: {sent} deposits sent, {} applied, {} rejected",
        c.applied,
        c.rejected_total()
    );
    assert!(c.applied > 0 && c.rejected_total() > 0);
}
