use std::io::BufReader;
use std::sync::atomic::{AtomicU32, Ordering};

use super::*;
use pheromone_messages::FollowerState;
use pheromone_sim::recording::ProbeReading;
use std::fs::File;

use super::heatmap::{fmt_sig, Layout};
use super::style::{lighter, Rgb, NAN_RGB, ROBOT_RGB, VIRIDIS};
use pheromone_sim::recording::RobotSample;

/// A directory under the system temp dir, unique per test and process, removed on drop.
pub(super) struct TempDir(pub(super) PathBuf);

impl TempDir {
    pub(super) fn new(tag: &str) -> TempDir {
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        TempDir(std::env::temp_dir().join(format!(
            "pheromone-report-{tag}-{}-{nanos}-{n}",
            std::process::id()
        )))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

pub(super) fn sample(t_s: f64, x: f64, y: f64) -> RobotSample {
    RobotSample {
        t_s,
        true_pose: [x, y, 0.0],
        est_pose: None,
        est_sigma_m: None,
        v_m_per_s: 0.5,
        omega_rad_per_s: 0.0,
        state: None,
        sensed_level: None,
        deposit_peak: None,
    }
}

/// 100 × 50 cells of 0.1 m, channel "trail", zero except `(80, 40)` = 7 (the max). Robot 0
/// drives along y = 1 m from x = 1 to 6 m without estimates; robot 1 drives along y = 3 m
/// with estimates 0.5 m below its true path.
pub(super) fn scene() -> Recording {
    let (w, h) = (100u32, 50u32);
    let mut planes = vec![0.0f32; (w * h) as usize];
    planes[(40 * w + 80) as usize] = 7.0;
    let mut rec = Recording::default();
    rec.snapshots.push(Snapshot {
        t_s: 10.0,
        width: w,
        height: h,
        cell_size_m: 0.1,
        channels: vec!["trail".into()],
        planes,
    });
    rec.robots.insert(
        0,
        (0..=10)
            .map(|i| sample(i as f64, 1.0 + 0.5 * i as f64, 1.0))
            .collect(),
    );
    rec.robots.insert(
        1,
        (0..=10)
            .map(|i| {
                let mut s = sample(i as f64, 1.0 + 0.5 * i as f64, 3.0);
                s.est_pose = Some([1.0 + 0.5 * i as f64, 2.5, 0.0]);
                s
            })
            .collect(),
    );
    rec
}

pub(super) fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
    let file = File::open(path).unwrap();
    let mut reader = png::Decoder::new(BufReader::new(file)).read_info().unwrap();
    let mut buf = vec![0u8; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

fn pixel(img: &(u32, u32, Vec<u8>), x: usize, y: usize) -> Rgb {
    let i = (y * img.0 as usize + x) * 3;
    [img.2[i], img.2[i + 1], img.2[i + 2]]
}

#[test]
fn robot_csv_has_a_row_per_sample_and_empty_cells_for_none() {
    let tmp = TempDir::new("csv");
    let mut rec = Recording::default();
    let mut full = sample(0.5, 1.25, -2.0);
    full.est_pose = Some([1.0, -2.5, 0.25]);
    full.est_sigma_m = Some(0.125);
    full.state = Some(FollowerState::TrailAbandoned);
    full.sensed_level = Some(3.5);
    full.deposit_peak = Some(12.5);
    rec.robots.insert(
        3,
        vec![sample(0.0, 1.0, -2.0), full, sample(1.0, 1.5, -2.0)],
    );
    rec.probes.push(ProbeReading {
        t_s: 2.0,
        x_m: 1.5,
        y_m: 0.5,
        channel: 0,
        value: 0.25,
    });
    let metrics = serde_json::json!({"robots": 1, "distance_m": 0.5});
    let written = write_outputs(&tmp.0, &rec, &metrics, &[]).unwrap();
    let names: Vec<String> = written
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["metrics.json", "robot_3.csv", "probes.csv"]);

    let text = fs::read_to_string(tmp.0.join("robot_3.csv")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 1 + 3);
    assert_eq!(lines[0], ROBOT_CSV_HEADER);
    let columns = lines[0].split(',').count();
    assert_eq!(columns, 13);
    for line in &lines[1..] {
        assert_eq!(line.split(',').count(), columns, "{line}");
    }
    assert_eq!(lines[1], "0,1,-2,0,,,,,0.5,0,,,");
    assert_eq!(
        lines[2],
        "0.5,1.25,-2,0,1,-2.5,0.25,0.125,0.5,0,trail_abandoned,3.5,12.5"
    );

    let probes = fs::read_to_string(tmp.0.join("probes.csv")).unwrap();
    assert_eq!(probes, format!("{PROBES_CSV_HEADER}\n2,1.5,0.5,0,0.25\n"));
    let back: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(tmp.0.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(back, metrics);
}

#[test]
fn png_has_the_expected_size_trajectories_and_top_of_the_colour_map() {
    let tmp = TempDir::new("png");
    let rec = scene();
    let written = write_outputs(&tmp.0, &rec, &serde_json::json!({}), &[]).unwrap();
    let final_png = tmp.0.join("field_final.png");
    let snap_png = tmp.0.join("field_trail_t010.0s.png");
    assert!(written.contains(&snap_png), "{written:?}");
    assert!(written.contains(&final_png), "{written:?}");
    assert_eq!(fs::read(&snap_png).unwrap(), fs::read(&final_png).unwrap());

    let img = decode(&snap_png);
    // 100 cells × 8 px wide, 50 cells × 8 px high, with the axes and the strip around them.
    let layout = Layout::for_grid(100, 50, 0.1);
    assert_eq!(layout.scale, 8);
    assert_eq!((img.0, img.1), layout.picture_px());
    assert_eq!((img.0, img.1), (48 + 800 + 24, 28 + 400 + 40 + 64));

    // Robot 0's true trajectory (y = 1 m) passes through x = 3 m: the middle of its 3 px line.
    let (x, y) = layout.pixel_from_world(3.0, 1.0);
    assert_eq!((x, y), (48.0 + 240.0, 28.0 + 320.0));
    assert_eq!(pixel(&img, 288, 348), ROBOT_RGB[0]);
    // Robot 1's estimate (y = 2.5 m, row 228) is dashed in a lighter shade of its colour.
    let est: Vec<Rgb> = (150..450).map(|x| pixel(&img, x, 228)).collect();
    assert!(est.contains(&lighter(ROBOT_RGB[1])));
    assert!(est.iter().any(|&c| c == VIRIDIS[0]), "dashes have gaps");
    assert_eq!(
        pixel(&img, 288, 188),
        ROBOT_RGB[1],
        "true path of robot 1 (y = 3 m)"
    );

    // The max cell (80, 40) is drawn at the top of the colour map, y up: block row
    // 50 − 1 − 40 = 9 from the top of the field, i.e. picture rows 100..108, columns 688..696.
    assert_eq!(pixel(&img, 692, 104), VIRIDIS[9]);
    assert_eq!(pixel(&img, 692, 112), VIRIDIS[0]);
    assert_eq!(pixel(&img, 692, 28 + 400 - 76), VIRIDIS[0]);
    // A zero cell away from every line is the bottom of the map.
    assert_eq!(pixel(&img, 98, 78), VIRIDIS[0]);
    // The strip has text and the colour bar: its top colour is there, at the right.
    let strip_top = 28 + 400 + 40;
    let bar: Vec<Rgb> = (436..872).map(|x| pixel(&img, x, strip_top + 30)).collect();
    assert!(
        bar.contains(&VIRIDIS[9]) && bar.contains(&VIRIDIS[0]),
        "colour bar"
    );
    let text: usize = (strip_top..img.1 as usize)
        .flat_map(|y| (0..436).map(move |x| (x, y)))
        .filter(|&(x, y)| pixel(&img, x, y)[0] > 200)
        .count();
    assert!(text > 300, "{text} light pixels: no title or legend");
}
/// trail-following has two channels: each gets its final picture showing its own trail, and
/// `field_final.png` shows both (it showed the first channel only).
#[test]
fn every_channel_has_a_final_picture_and_field_final_shows_them_all() {
    let tmp = TempDir::new("channels");
    let mut rec = scene();
    let snap = &mut rec.snapshots[0];
    let n = (snap.width * snap.height) as usize;
    let mut second = vec![0.0f32; n];
    second[20 * snap.width as usize + 20] = 3.0; // cell (20, 20): the "curved" trail
    snap.planes.extend(second);
    snap.channels.push("curved trail".into());
    let written = write_outputs(&tmp.0, &rec, &serde_json::json!({}), &[]).unwrap();
    let names = [
        "field_final.png",
        "field_final_trail.png",
        "field_final_curved_trail.png",
    ];
    for name in names {
        assert!(written.contains(&tmp.0.join(name)), "{name}: {written:?}");
    }
    assert_eq!(final_file_name("curved trail"), names[2]);
    let [all, first, curved] = names.map(|n| decode(&tmp.0.join(n)));
    // Cell (80, 40) (the first channel's max) and cell (20, 20) (the second's): columns
    // 48 + 8x + 4, rows 28 + (49 − y)·8 + 4.
    let at = |img: &(u32, u32, Vec<u8>), x: usize, y: usize| {
        pixel(img, 48 + 8 * x + 4, 28 + (49 - y) * 8 + 4)
    };
    assert_eq!(at(&first, 80, 40), VIRIDIS[9]);
    assert_eq!(
        at(&first, 20, 20),
        VIRIDIS[0],
        "the first channel has no curved trail"
    );
    assert_eq!(at(&curved, 20, 20), VIRIDIS[9]);
    assert_eq!(at(&curved, 80, 40), VIRIDIS[0]);
    assert_ne!(first.2, curved.2);
    // Both trails in field_final.png: the max at the top, the other above the bottom.
    assert_eq!(at(&all, 80, 40), VIRIDIS[9]);
    assert_ne!(at(&all, 20, 20), VIRIDIS[0]);
    assert_eq!(at(&all, 50, 45), VIRIDIS[0]);
}

/// Issue 51: a channel's snapshots share one colour scale (the run's max), so a trail that
/// grows looks it; `field_final.png` leaves out the walls' channel (`wall_channel`), whose
/// level would swamp the pheromone's, and scales the pheromone on its own.
#[test]
fn snapshots_share_the_runs_scale_and_the_final_picture_leaves_the_walls_out() {
    let tmp = TempDir::new("scale");
    let mut rec = scene();
    let mut early = rec.snapshots[0].clone();
    early.t_s = 5.0;
    early.planes.iter_mut().for_each(|v| *v /= 7.0); // max 1 of the run's 7
    rec.snapshots.insert(0, early);
    write_outputs(&tmp.0, &rec, &serde_json::json!({}), &[]).unwrap();
    let at = |img: &(u32, u32, Vec<u8>), x: usize, y: usize| {
        pixel(img, 48 + 8 * x + 4, 28 + (49 - y) * 8 + 4)
    };
    let first = decode(&tmp.0.join(snapshot_file_name("trail", 5.0)));
    let last = decode(&tmp.0.join(snapshot_file_name("trail", 10.0)));
    assert_eq!(at(&last, 80, 40), VIRIDIS[9]);
    let c = at(&first, 80, 40);
    assert!(
        c != VIRIDIS[9] && c != VIRIDIS[0],
        "1 of 7 is low on the run's scale: {c:?}"
    );

    // Walls marked at 12 on channel 1, pheromone up to 0.5 on channel 0.
    let tmp = TempDir::new("walls");
    let mut rec = scene();
    let snap = &mut rec.snapshots[0];
    snap.planes.iter_mut().for_each(|v| *v /= 14.0);
    let n = (snap.width * snap.height) as usize;
    let mut walls = vec![0.0f32; n];
    walls[20 * snap.width as usize + 20] = 12.0;
    snap.planes.extend(walls);
    snap.channels.push("walls".into());
    rec.wall_channel = Some(1);
    write_outputs(&tmp.0, &rec, &serde_json::json!({}), &[]).unwrap();
    let all = decode(&tmp.0.join("field_final.png"));
    assert_eq!(at(&all, 80, 40), VIRIDIS[9], "the pheromone's max on top");
    assert_eq!(at(&all, 20, 20), VIRIDIS[0], "the walls' mark left out");
    assert_eq!(
        at(&decode(&tmp.0.join("field_final_walls.png")), 20, 20),
        VIRIDIS[9]
    );
}

#[test]
fn nan_cells_get_their_own_colour_without_panicking() {
    let tmp = TempDir::new("nan");
    let mut rec = scene();
    let w = rec.snapshots[0].width as usize;
    rec.snapshots[0].planes[10 * w + 10] = f32::NAN;
    rec.snapshots[0].planes[11 * w + 10] = f32::INFINITY;
    let written = write_outputs(&tmp.0, &rec, &serde_json::json!({}), &[]).unwrap();
    assert!(written.iter().any(|p| p.ends_with("field_final.png")));
    let img = decode(&tmp.0.join("field_final.png"));
    // Cell (10, 10): columns 48 + 80..88, rows 28 + (49 − 10)·8 = 340..348.
    assert_eq!(pixel(&img, 132, 343), NAN_RGB);
    assert!(!VIRIDIS.contains(&NAN_RGB) && !ROBOT_RGB.contains(&NAN_RGB));
    // NaN and ∞ do not spoil the scale: the finite max is still the top of the map.
    assert_eq!(pixel(&img, 692, 104), VIRIDIS[9]);
    assert_eq!(pixel(&img, 132, 335), VIRIDIS[9], "+inf clamps to the top");
}
#[test]
fn file_names_and_bad_snapshots() {
    assert_eq!(snapshot_file_name("trail", 12.0), "field_trail_t012.0s.png");
    assert_eq!(
        snapshot_file_name("anti trail", 3.26),
        "field_anti_trail_t003.3s.png"
    );
    assert_eq!(snapshot_file_name("x", 1234.5), "field_x_t1234.5s.png");
    let mut rec = scene();
    rec.snapshots[0].planes.pop();
    let tmp = TempDir::new("bad");
    let err = write_outputs(&tmp.0, &rec, &serde_json::json!({}), &[]).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("t = 10 s") && msg.contains("4999 values"),
        "{msg}"
    );
    assert!(!tmp.0.exists(), "nothing written for a bad recording");
    assert_eq!(fmt_sig(35.26), "35.3");
    assert_eq!(fmt_sig(50.0), "50");
    assert_eq!(fmt_sig(340.0), "340");
    assert_eq!(fmt_sig(0.012345), "0.0123");
    assert_eq!(fmt_sig(1.5e-5), "1.50e-5");
}

#[test]
fn io_errors_name_the_path() {
    let tmp = TempDir::new("io");
    fs::create_dir_all(&tmp.0).unwrap();
    let blocker = tmp.0.join("file");
    fs::write(&blocker, b"not a directory").unwrap();
    let dir = blocker.join("out");
    let err = write_outputs(&dir, &scene(), &serde_json::json!({}), &[]).unwrap_err();
    assert!(matches!(err, ReportError::Io { .. }), "{err:?}");
    assert!(
        err.to_string().contains(&dir.display().to_string()),
        "{err}"
    );
}

/// Fig. 23's threshold: the leader's deposits chart knows the follower's threshold (10 in
/// `wrong-area`) and the first deposit below it, and draws them.
#[test]
fn the_leader_deposits_chart_marks_where_the_deposit_fell_below_the_followers_threshold() {
    let scenario = Scenario::load("wrong-area").unwrap();
    let m = scenario.metrics.blind_leader.clone().unwrap();
    let mut rec = Recording::default();
    let peaks = [100.0f32, 50.0, 12.0, 8.0, 3.0, 11.0];
    let rows = (0..peaks.len()).map(|i| RobotSample {
        deposit_peak: Some(peaks[i]),
        ..sample(i as f64, 1.0 + i as f64, 1.5)
    });
    rec.robots.insert(m.leader, rows.collect());
    let d = series::leader_deposits(&scenario, &m, &rec);
    assert_eq!(d.threshold, Some(10.0));
    // The fourth deposit (8 < 10), 3 m along the path, at t = 3 s; not the later 3 or 11.
    assert_eq!(d.below_threshold_at(), Some((3.0, 3.0)));
    let pic = plots::leader_deposits_chart(&d).unwrap();
    // The threshold line and the mark are drawn in their own green.
    let green = pic.rgb.chunks(3).filter(|p| *p == [0, 120, 0]).count();
    assert!(green > 100, "{green} green pixels");
    // Seed 000's stated L11 and L12 at this run's L11, L12 (15 evenly spaced points on 5 m).
    let at = |l: f64| 5.0 * (l - 1.0) / 14.0;
    assert_eq!(d.paper.len(), 2);
    assert!((d.paper[0].0 - at(11.0)).abs() <= 1.0 && d.paper[0].1 == 11.35);
    assert!((d.paper[1].0 - at(12.0)).abs() <= 1.0 && d.paper[1].1 == 8.15);
    // The same crossing as metrics.wrong_area gives for the run (its first follower is this one).
    let w = pheromone_sim::wrong_area::wrong_area(
        &scenario,
        scenario.metrics.wrong_area.as_ref().unwrap(),
        &rec,
    );
    let c = w.deposit_below_threshold.expect("the metric's crossing");
    assert_eq!(d.below_threshold_at(), Some((c.along_m, c.t_s)));
    // A follower that does not follow by gradient has no threshold, and so no crossing.
    let mut other = scenario.clone();
    let f = other
        .robots
        .iter_mut()
        .find(|r| r.id == m.follower)
        .unwrap();
    f.follower.as_mut().unwrap().strategy = pheromone_roles::follower::StrategyKind::Inverse;
    let none = series::leader_deposits(&other, &m, &rec);
    assert_eq!((none.threshold, none.below_threshold_at()), (None, None));
}

/// Issue 48: the field picture of `wrong-area` marks where the leader's deposit first
/// fell below the follower's threshold (10), in the leader's colour, from that time on.
#[test]
fn the_field_marks_where_the_leaders_deposit_fell_below_the_threshold() {
    let scenario = Scenario::load("wrong-area").unwrap();
    let mut rec = Recording::default();
    let peaks = [100.0f32, 50.0, 12.0, 8.0, 3.0];
    let rows = (0..peaks.len()).map(|i| RobotSample {
        deposit_peak: Some(peaks[i]),
        ..sample(i as f64, 1.0 + i as f64, 1.5)
    });
    rec.robots.insert(0, rows.collect());
    let all = marks(&scenario, &rec);
    let m = all
        .iter()
        .find(|m| m.label.starts_with("R0 deposit < 10 at"))
        .unwrap_or_else(|| panic!("no threshold mark in {all:?}"));
    assert_eq!(m.label, "R0 deposit < 10 at x = 4.0 m (t = 3.0 s)");
    assert_eq!(m.shape, Shape::Point { at_m: [4.0, 1.5] });
    assert_eq!((m.rgb, m.from_s), (ROBOT_RGB[0], 3.0));
}
