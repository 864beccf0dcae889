//! `--only peers` (issue 53): the two hot passes beside what a user would reach for instead, on
//! the same grids in the same run.
//!
//! - the ambient tick (one thread) against OpenCV's `cv2.boxFilter` (f32, normalized,
//!   `BORDER_CONSTANT`) and `scipy.ndimage.uniform_filter` (mode `constant`), each followed by
//!   the correction of its r-wide border strips to our clipped window's mean;
//! - seed 004's merge (`merge_planes`, both rules) against `cv2.warpAffine` (nearest, inverse
//!   map) of both source planes and the same per-cell rule in NumPy (f32).
//!
//! The peers run in a Python process (`py/peers.py`, embedded here and written to a temporary
//! directory with the job): the grids and our outputs go as `.npy` files, the peer times and
//! compares, and prints one JSON object. Each row carries the peer's time, ours / the peer's,
//! the largest difference from our output and the bound it must stay within. A missing
//! interpreter or module is a row that says so (`unavailable`), not an error of the run.

use std::collections::BTreeMap;
use std::hint::black_box;
use std::path::Path;
use std::process::Command;

use pheromone_field::{ChannelSpec, Evaporation, FieldConfig, Stepper};
use pheromone_report::export::npy::npy_bytes;
use pheromone_roles::mapper::merge::average_logodds_bound;
use pheromone_roles::mapper::{MappingConfig, MergeRule, MergeTransform};
use serde::Serialize;
use serde_json::{json, Value};

use crate::tick::{median_ns, median_ns_from};
use crate::BenchError;

/// The peer script, run by `PeersRun::python`.
const SCRIPT: &str = include_str!("../py/peers.py");

/// What to measure.
#[derive(Debug, Clone)]
pub struct PeersRun<'a> {
    /// The Python interpreter that runs the peers (`--peers-python`).
    pub python: &'a str,
    pub ambient_sides: &'a [u32],
    pub radii_cells: &'a [u32],
    pub merge_sides: &'a [u32],
    pub reps: usize,
}

/// One peer's figures on one case; `unavailable` says why there are none.
#[derive(Debug, Clone, Serialize, Default)]
pub struct PeerFigure {
    pub us: Option<f64>,
    /// Our time / the peer's.
    pub ratio: Option<f64>,
    /// The largest |peer − ours| over the compared cells, and the bound it must stay within.
    pub max_abs_diff: Option<f64>,
    pub bound: Option<f64>,
    pub within_bound: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unavailable: Option<String>,
}

/// The ambient tick at one size and radius beside its peers.
#[derive(Debug, Clone, Serialize)]
pub struct AmbientPeerRow {
    pub side: u32,
    pub radius_cells: u32,
    pub ours_us: f64,
    pub opencv_box: PeerFigure,
    pub scipy_uniform: PeerFigure,
}

/// The merge at one size by one rule beside its peer.
#[derive(Debug, Clone, Serialize)]
pub struct MergePeerRow {
    pub side: u32,
    pub rule: &'static str,
    pub ours_us: f64,
    pub opencv_numpy: PeerFigure,
    /// Destination cells compared, and those left out: their source coordinate lies within
    /// 2⁻⁸ cell of a cell edge, where OpenCV's fixed-point walk (2⁻¹⁰ pixel) may pick the
    /// neighbour.
    pub cells_compared: Option<u64>,
    pub cells_near_an_edge: Option<u64>,
    /// Of those, the cells where the peer's output is not ours bit for bit.
    pub cells_near_an_edge_differing: Option<u64>,
}

/// The `peers` section.
#[derive(Debug, Clone, Serialize)]
pub struct PeersReport {
    /// The interpreter asked, its version and the peers' module versions.
    pub python: String,
    pub python_version: Option<String>,
    pub versions: BTreeMap<String, Option<String>>,
    /// Modules the interpreter could not import, with its message.
    pub missing: BTreeMap<String, String>,
    pub ambient: Vec<AmbientPeerRow>,
    pub merge: Vec<MergePeerRow>,
}

fn io(what: String) -> impl FnOnce(std::io::Error) -> BenchError {
    move |source| BenchError::Io { what, source }
}

fn write_npy(path: &Path, side: u32, cells: &[f32]) -> Result<String, BenchError> {
    let s = side as usize;
    std::fs::write(path, npy_bytes(&[s, s], cells))
        .map_err(io(format!("write {}", path.display())))?;
    Ok(path.display().to_string())
}

const CELL_M: f32 = 0.05;

/// The ambient model at `radius_cells` (5 cm cells) and its stepper (one thread).
fn ambient_stepper(side: u32, radius_cells: u32) -> Result<Stepper, BenchError> {
    Stepper::new(FieldConfig {
        width: side,
        height: side,
        cell_size_m: CELL_M,
        channels: vec![ChannelSpec::new(
            "trail",
            Evaporation::Ambient {
                decay_per_s: 0.0057,
                alpha: 0.5,
                radius_m: radius_cells as f32 * CELL_M,
            },
        )],
        ..FieldConfig::default()
    })
    .map_err(|e| BenchError::Peer(format!("peers bench configuration: {e}")))
}

fn us(ns: u64) -> f64 {
    (ns as f64 / 100.0).round() / 10.0
}

/// One of our cases: the side, the radius (cells) or the rule, and our median time (ns).
type Timed<T> = (u32, T, u64);

/// Times ours on every ambient case and writes the job's files; returns the cases and our times.
fn ambient_cases(run: &PeersRun, dir: &Path) -> Result<(Vec<Value>, Vec<Timed<u32>>), BenchError> {
    let (mut cases, mut ours) = (Vec::new(), Vec::new());
    for &side in run.ambient_sides {
        let n = side as usize * side as usize;
        let prev: Vec<f32> = (0..n).map(|i| (i % 977) as f32 * 0.01).collect();
        let prev_path = write_npy(&dir.join(format!("prev-{side}.npy")), side, &prev)?;
        let mut next = vec![0.0f32; n];
        for &r in run.radii_cells.iter().filter(|&&r| 2 * r < side) {
            let mut s = ambient_stepper(side, r)?;
            let ns = median_ns(run.reps, || {
                s.step(black_box(&prev), &mut next);
                black_box(&mut next);
            });
            let mean =
                pheromone_field::models::ambient_mean_plane(&prev, side as usize, r as usize);
            let mean_path = write_npy(&dir.join(format!("mean-{side}-{r}.npy")), side, &mean)?;
            cases.push(json!({"prev": prev_path, "mean": mean_path, "radius": r}));
            ours.push((side, r, ns));
        }
    }
    Ok((cases, ours))
}

/// The affine map from a destination cell (x, y) to the source grid coordinates of its centre
/// (cell i spans [i, i + 1)): what `merge_planes` walks.
fn merge_matrix(
    dst: &pheromone_field::GridGeometry,
    src: &pheromone_field::GridGeometry,
    t: &MergeTransform,
) -> [[f64; 3]; 2] {
    let (h, hs) = (dst.cell_size_m as f64, src.cell_size_m as f64);
    let at = |x: f64, y: f64| {
        let q = [
            dst.origin_x_m as f64 + (x + 0.5) * h,
            dst.origin_y_m as f64 + (y + 0.5) * h,
        ];
        let p = t.inverse(q);
        [
            (p[0] - src.origin_x_m as f64) / hs,
            (p[1] - src.origin_y_m as f64) / hs,
        ]
    };
    let (g0, g1, g2) = (at(0.0, 0.0), at(1.0, 0.0), at(0.0, 1.0));
    [
        [g1[0] - g0[0], g2[0] - g0[0], g0[0]],
        [g1[1] - g0[1], g2[1] - g0[1], g0[1]],
    ]
}

/// Times ours on every merge case (both rules) and writes the job's files.
fn merge_cases(
    run: &PeersRun,
    dir: &Path,
) -> Result<(Vec<Value>, Vec<Timed<&'static str>>), BenchError> {
    let (mut cases, mut ours) = (Vec::new(), Vec::new());
    let logodds_max = MappingConfig::default().logodds_max;
    let fail = |e| BenchError::Peer(format!("peers bench merge: {e}"));
    for &side in run.merge_sides {
        let (src, dst) = (crate::merge::map(side, 1)?, crate::merge::map(side, 2)?);
        let t = crate::merge::transform();
        let geometry = *dst.geometry();
        let matrix = merge_matrix(&geometry, &src.view().geometry, &t);
        let file = |name: &str, cells: &[f32]| {
            write_npy(&dir.join(format!("{name}-{side}.npy")), side, cells)
        };
        let files = [
            ("src_occ", file("src-occ", &src.occupancy)?),
            ("src_pher", file("src-pher", &src.pheromone)?),
            ("dst_occ", file("dst-occ", &dst.occupancy)?),
            ("dst_pher", file("dst-pher", &dst.pheromone)?),
        ];
        for (rule, name, bound) in [
            (MergeRule::AdoptUnknown, "adopt-unknown", 0.0),
            (
                MergeRule::Average,
                "average",
                2.0 * average_logodds_bound(logodds_max),
            ),
        ] {
            let planes = std::cell::RefCell::new((dst.occupancy.clone(), dst.pheromone.clone()));
            let mut result = Ok(());
            let restore = || {
                let mut p = planes.borrow_mut();
                p.0.copy_from_slice(&dst.occupancy);
                p.1.copy_from_slice(&dst.pheromone);
            };
            let ns = median_ns_from(run.reps, restore, || {
                let mut p = planes.borrow_mut();
                let (occ, pher) = &mut *p;
                let r = pheromone_roles::mapper::merge_planes(
                    &geometry,
                    (&mut occ[..], &mut pher[..]),
                    black_box(&src.view()),
                    &t,
                    (rule, logodds_max),
                );
                if let Err(e) = r {
                    result = Err(fail(e));
                }
            });
            result?;
            let (occ, pher) = planes.into_inner();
            let mut case = json!({
                "side": side, "rule": name, "logodds_max": logodds_max, "bound": bound,
                "matrix": matrix,
                "ours_occ": file(&format!("ours-occ-{name}"), &occ)?,
                "ours_pher": file(&format!("ours-pher-{name}"), &pher)?,
            });
            for (k, v) in &files {
                case[*k] = json!(v);
            }
            cases.push(case);
            ours.push((side, name, ns));
        }
    }
    Ok((cases, ours))
}

/// Runs the peer script on `job`; `Err` is why no peer could run (a message for the rows).
fn run_script(python: &str, dir: &Path, job: &Value) -> Result<Value, String> {
    let script = dir.join("peers.py");
    let job_path = dir.join("job.json");
    std::fs::write(&script, SCRIPT).map_err(|e| format!("write {}: {e}", script.display()))?;
    std::fs::write(&job_path, job.to_string())
        .map_err(|e| format!("write {}: {e}", job_path.display()))?;
    let out = Command::new(python)
        .arg(&script)
        .arg(&job_path)
        .output()
        .map_err(|e| {
            format!("cannot run the Python interpreter '{python}' (--peers-python): {e}")
        })?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = err.lines().rev().take(3).collect();
        return Err(format!(
            "the peer script failed under '{python}' ({}): {}",
            out.status,
            tail.into_iter().rev().collect::<Vec<_>>().join(" | ")
        ));
    }
    serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("the peer script's output is not JSON: {e}"))
}

/// A peer's figures from the script's answer `v` (its object for this peer, or null), against
/// our time `ours_ns`; `why` says what is missing when there is none.
fn figure(v: &Value, ours_ns: u64, why: &str) -> PeerFigure {
    let Some(ns) = v["ns"].as_f64() else {
        return PeerFigure {
            unavailable: Some(why.to_string()),
            ..PeerFigure::default()
        };
    };
    let (diff, bound) = (v["max_abs_diff"].as_f64(), v["bound"].as_f64());
    PeerFigure {
        us: Some((ns / 100.0).round() / 10.0),
        ratio: Some(((ours_ns as f64 / ns) * 1000.0).round() / 1000.0),
        max_abs_diff: diff,
        bound,
        within_bound: diff.zip(bound).map(|(d, b)| d <= b),
        unavailable: None,
    }
}

/// Why a peer needing `modules` has no figures: the whole script failed, or a module is missing.
fn why_missing(answer: &Result<Value, String>, modules: &[&str], python: &str) -> String {
    match answer {
        Err(e) => e.clone(),
        Ok(a) => {
            let missing: Vec<String> = modules
                .iter()
                .filter_map(|m| a["missing"][m].as_str().map(|e| format!("{m} ({e})")))
                .collect();
            match missing.is_empty() {
                true => "the peer script gave no figure".into(),
                false => format!(
                    "not importable by '{python}': {}; install with `pip install ./python[peers]`",
                    missing.join(", ")
                ),
            }
        }
    }
}

/// The `peers` section.
pub fn measure(run: &PeersRun) -> Result<PeersReport, BenchError> {
    let dir = tempfile::Builder::new()
        .prefix("pheromone-bench-peers-")
        .tempdir()
        .map_err(io("create the peers' directory".into()))?;
    let (ambient, ours_ambient) = ambient_cases(run, dir.path())?;
    let (merge, ours_merge) = merge_cases(run, dir.path())?;
    let job = json!({"reps": run.reps, "ambient": ambient, "merge": merge});
    let answer = run_script(run.python, dir.path(), &job);
    let a = answer.as_ref().ok();
    let none = Value::Null;
    let row = |key: &str, i: usize| a.map_or(&none, |a| &a[key][i]);
    let why_cv = why_missing(&answer, &["numpy", "cv2"], run.python);
    let why_sp = why_missing(&answer, &["numpy", "scipy.ndimage"], run.python);
    let ambient = ours_ambient
        .iter()
        .enumerate()
        .map(|(i, &(side, radius_cells, ns))| AmbientPeerRow {
            side,
            radius_cells,
            ours_us: us(ns),
            opencv_box: figure(&row("ambient", i)["opencv_box"], ns, &why_cv),
            scipy_uniform: figure(&row("ambient", i)["scipy_uniform"], ns, &why_sp),
        })
        .collect();
    let merge = ours_merge
        .iter()
        .enumerate()
        .map(|(i, &(side, rule, ns))| {
            let p = &row("merge", i)["opencv_numpy"];
            MergePeerRow {
                side,
                rule,
                ours_us: us(ns),
                opencv_numpy: figure(p, ns, &why_cv),
                cells_compared: p["cells_compared"].as_u64(),
                cells_near_an_edge: p["cells_near_an_edge"].as_u64(),
                cells_near_an_edge_differing: p["cells_near_an_edge_differing"].as_u64(),
            }
        })
        .collect();
    let text = |v: &Value| v.as_str().map(String::from);
    Ok(PeersReport {
        python: run.python.to_string(),
        python_version: a.and_then(|a| text(&a["python"])),
        versions: a
            .and_then(|a| a["versions"].as_object())
            .map(|m| m.iter().map(|(k, v)| (k.clone(), text(v))).collect())
            .unwrap_or_default(),
        missing: a
            .and_then(|a| a["missing"].as_object())
            .map(|m| {
                m.iter()
                    .map(|(k, v)| (k.clone(), text(v).unwrap_or_default()))
                    .collect()
            })
            .unwrap_or_else(|| match &answer {
                Err(e) => BTreeMap::from([("python".to_string(), e.clone())]),
                Ok(_) => BTreeMap::new(),
            }),
        ambient,
        merge,
    })
}
