//! `rgm merge` end to end on thinned Stanford scans (each moved into a frame of its own) with
//! `rgm register`'s default method: the scans placed as the `.conf` ground truth places them;
//! a scan of another object and a scan that overlaps nothing left unplaced without moving the
//! others; `poses.conf` read back by rgm's own `.conf` reader; a bad file named.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rgm_data::multiway::{pose_errors, MovedScan};
use rgm_data::{write_point_cloud, ScanFolder};
use rgm_geom::euler::rotation_xyz_intrinsic;
use rgm_geom::{KnnIndex, Matrix3, Matrix4, PointCloud, RigidTransform, Vector3};
use rgm_tests::Scratch;

fn rgm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(args)
        .output()
        .expect("the rgm binary runs")
}

fn stanford(object: &str) -> ScanFolder {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/stanford");
    ScanFolder::open(dir.join(object)).expect("the Stanford scans")
}

/// The scan thinned to one point per 2 mm cube (≈ 3,000 points), moved by turns of `k` × 40°,
/// 25° and 60° about x, y and z and a shift: its own frame, far from the truth's.
fn moved(cloud: &PointCloud, k: usize) -> (PointCloud, RigidTransform) {
    let k = k as f64;
    let turn = rotation_xyz_intrinsic(
        (40.0 * k).to_radians(),
        (25.0 * k).to_radians(),
        (60.0 * k).to_radians(),
    );
    let motion = RigidTransform::new(turn, Vector3::new(0.05 * k, -0.1, 0.02));
    (cloud.voxel_downsampled(0.002).transformed(&motion), motion)
}

/// What one merge printed in poses.json: each scan's pose (or none).
fn poses(out: &Path) -> (Vec<Option<RigidTransform>>, serde_json::Value) {
    let text = std::fs::read_to_string(out.join("poses.json")).unwrap();
    let value: serde_json::Value = serde_json::from_str(&text).unwrap();
    let poses = value["poses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|rows| {
            (!rows.is_null()).then(|| {
                let m = Matrix4::from_fn(|r, c| rows[r][c].as_f64().unwrap());
                RigidTransform::from_matrix4(&m, 1e-6).unwrap()
            })
        })
        .collect();
    (poses, value)
}

fn merge(dir: &Path, files: &[PathBuf], out: &str) -> PathBuf {
    let out = dir.join(out);
    let mut args = vec![
        "merge".to_string(),
        "--out".into(),
        out.display().to_string(),
    ];
    args.extend(files.iter().map(|f| f.display().to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let result = rgm(&args);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    out
}

#[test]
fn scans_are_placed_as_the_truth_and_strangers_are_left_unplaced() {
    let dir = Scratch::new("cli-merge");
    let bunny = stanford("bunny");
    // bun000, bun045 and bun315: three views 45° apart that overlap by half or more.
    let chosen = ["bun000.ply", "bun045.ply", "bun315.ply"];
    let mut scans = Vec::new();
    let mut files = Vec::new();
    for (k, name) in chosen.iter().enumerate() {
        let scan = bunny.scans.iter().find(|s| s.name == *name).unwrap();
        let (cloud, motion) = moved(&scan.cloud, k + 1);
        let file = dir.join(format!("scan{k}.ply"));
        write_point_cloud(&file, &cloud).unwrap();
        files.push(file);
        scans.push(MovedScan {
            original: k,
            cloud,
            truth: scan.pose.compose(&motion.inverse()),
        });
    }
    let out = merge(&dir, &files, "three");
    let (three, summary) = poses(&out);
    assert_eq!(summary["registered"], serde_json::json!([true, true, true]));
    // Three pairs make a loop: each scan's placement is checked by the others.
    assert_eq!(summary["on_loop"], serde_json::json!([true, true, true]));
    let component = vec![Some(0); 3];
    let diagonal = bunny.diagonal();
    for error in pose_errors(&scans, &three, &component) {
        let error = error.unwrap();
        assert!(
            error.rotation_deg < 1.0 && error.rms < 0.005 * diagonal,
            "{error:?}"
        );
    }
    // poses.conf read by rgm's own `.conf` reader, beside the scans it names: the same poses.
    std::fs::copy(out.join("poses.conf"), dir.join("poses.conf")).unwrap();
    let read = ScanFolder::open(&*dir).unwrap();
    for (k, scan) in read.scans.iter().enumerate() {
        assert_eq!(scan.name, format!("scan{k}.ply"));
        let off = three[k].unwrap().inverse().compose(&scan.pose);
        assert!(off.rotation_angle_deg() < 1e-6 && off.translation.norm() < 1e-9);
    }
    // model.ply: the three scans in one frame, a `scan` property per point.
    let model = std::fs::read(out.join("model.ply")).unwrap();
    let header = String::from_utf8_lossy(&model[..300]).to_string();
    assert!(header.contains("property uint scan"), "{header}");

    // A scan of another object (a dragon scan), and the part of bun180 (the back) that lies
    // farther than 5 mm from every one of the three: nothing of it overlaps them.
    let dragon = stanford("dragon_stand");
    let (stranger, _) = moved(&dragon.scans[0].cloud, 4);
    let world: Vec<PointCloud> = scans
        .iter()
        .map(|s| s.cloud.transformed(&s.truth))
        .collect();
    let indices: Vec<KnnIndex> = world.iter().map(|c| KnnIndex::new(&c.points)).collect();
    let back = bunny.scans.iter().find(|s| s.name == "bun180.ply").unwrap();
    let alone: Vec<usize> = (0..back.cloud.len())
        .filter(|&i| {
            let p = back.pose.apply(&back.cloud.points[i]);
            indices
                .iter()
                .all(|index| index.nearest_within(&p, 0.005).is_none())
        })
        .collect();
    let (apart, _) = moved(&back.cloud.select(&alone), 5);
    assert!(apart.len() > 500, "{} points", apart.len());
    for (name, cloud) in [("dragon.ply", &stranger), ("apart.ply", &apart)] {
        let file = dir.join(name);
        write_point_cloud(&file, cloud).unwrap();
        files.push(file);
    }
    let out = merge(&dir, &files, "five");
    let (five, summary) = poses(&out);
    assert_eq!(
        summary["registered"],
        serde_json::json!([true, true, true, false, false])
    );
    assert_eq!(summary["component"][3], serde_json::Value::Null);
    assert_eq!(
        summary["on_loop"],
        serde_json::json!([true, true, true, false, false])
    );
    // model.html: every scan named, the two strangers with no point in the model.
    let page = std::fs::read_to_string(out.join("model.html")).unwrap();
    let start = page.find(r#"type="application/json">"#).unwrap() + 24;
    let end = start + page[start..].find("</script>").unwrap();
    let data: serde_json::Value = serde_json::from_str(&page[start..end]).unwrap();
    let in_model: Vec<u64> = (0..5)
        .map(|s| data["model"]["scans"][s]["inModel"].as_u64().unwrap())
        .collect();
    assert!(in_model[..3].iter().all(|&n| n > 1000), "{in_model:?}");
    assert_eq!(in_model[3..], [0, 0]);
    assert_eq!(
        data["model"]["scans"][3]["name"],
        files[3].display().to_string()
    );
    for k in 0..3 {
        let off = three[k].unwrap().inverse().compose(&five[k].unwrap());
        assert!(
            (off.rotation - Matrix3::identity()).norm() < 1e-12 && off.translation.norm() < 1e-12,
            "scan {k} moved by {off:?}"
        );
    }
}

#[test]
fn a_bad_scan_is_named() {
    let dir = Scratch::new("cli-merge-bad");
    let good = dir.join("good.xyz");
    std::fs::write(&good, "0 0 0\n1 0 0\n0 1 0\n0 0 1\n").unwrap();
    let bad = dir.join("bad.ply");
    std::fs::write(&bad, "not a ply file\n").unwrap();
    let out = dir.join("out");
    let result = rgm(&[
        "merge",
        good.to_str().unwrap(),
        bad.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("bad.ply"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    // Two clouds that share nothing: outputs written, then a failure that says so.
    let far = dir.join("far.xyz");
    std::fs::write(&far, "5 5 5\n6 5 5\n5 6 5\n5 5 6\n7 7 7\n").unwrap();
    let result = rgm(&[
        "merge",
        good.to_str().unwrap(),
        far.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        !result.status.success() && stderr.contains("no pair of the scans was registered"),
        "{stderr}"
    );
    assert!(out.join("poses.json").is_file());
    let missing = dir.join("missing.ply");
    let result = rgm(&[
        "merge",
        good.to_str().unwrap(),
        missing.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        !result.status.success() && stderr.contains("missing.ply"),
        "{stderr}"
    );
}

/// bun000, bun045 and bun315 thinned to 2 mm: (name, cloud, `.conf` pose).
fn three_thinned_bunny_scans() -> Vec<(String, PointCloud, RigidTransform)> {
    let bunny = stanford("bunny");
    ["bun000.ply", "bun045.ply", "bun315.ply"]
        .iter()
        .map(|name| {
            let scan = bunny.scans.iter().find(|s| s.name == *name).unwrap();
            (
                scan.name.clone(),
                scan.cloud.voxel_downsampled(0.002),
                scan.pose,
            )
        })
        .collect()
}

/// `rgm eval --multiway FOLDER --json`: the table's row of `FOLDER` (named `name`), split at
/// its tabs, and the JSON file's records.
fn eval_multiway(dir: &Path, folder: &Path, name: &str) -> (Vec<String>, Vec<serde_json::Value>) {
    let json = dir.join("errors.json");
    let out = rgm(&[
        "eval",
        "--multiway",
        folder.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let row = stdout
        .lines()
        .find(|l| l.starts_with(&format!("{name}\t")))
        .unwrap_or_else(|| panic!("{stdout}"))
        .split('\t')
        .map(str::to_string)
        .collect();
    let value: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    (row, value["records"].as_array().unwrap().clone())
}

#[test]
fn eval_multiway_scores_a_small_folder_against_its_conf() {
    // Three thinned bunny scans in a folder of their own, with their `.conf` poses.
    let dir = Scratch::new("cli-eval-multiway");
    let folder = dir.join("three");
    std::fs::create_dir_all(&folder).unwrap();
    let scans = three_thinned_bunny_scans();
    for (name, cloud, _) in &scans {
        write_point_cloud(folder.join(name), cloud).unwrap();
    }
    let conf =
        rgm_data::scans::conf_text(scans.iter().map(|(name, _, pose)| (name.as_str(), pose)));
    std::fs::write(folder.join("three.conf"), conf).unwrap();
    let (row, records) = eval_multiway(&dir, &folder, "three");
    // folder, scans, placed, within 1° and 0.5 %, …
    assert_eq!(row[1..4], ["3", "3", "3"], "{row:?}");
    let scored: Vec<f64> = records
        .iter()
        .filter_map(|r| r["rotation_deg"].as_f64())
        .collect();
    assert_eq!(scored.len(), 3);
    assert!(scored.iter().all(|&deg| deg < 1.0), "{scored:?}");
}

#[test]
fn eval_multiway_scores_a_scene_folder_against_its_gt_log() {
    // The three thinned bunny scans as fragments in the 3DMatch layout, each in its own frame,
    // with gt.log's relative poses made from the `.conf` ones (p_i = T p_j).
    let dir = Scratch::new("cli-eval-multiway-scene");
    let folder = dir.join("room");
    std::fs::create_dir_all(&folder).unwrap();
    let scans = three_thinned_bunny_scans();
    for (k, (_, cloud, _)) in scans.iter().enumerate() {
        write_point_cloud(folder.join(format!("cloud_bin_{k}.ply")), cloud).unwrap();
    }
    let mut log = String::new();
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let t = scans[i].2.inverse().compose(&scans[j].2);
        log += &format!("{i} {j} 3\n");
        for row in t.to_rows() {
            log += &format!("{} {} {} {}\n", row[0], row[1], row[2], row[3]);
        }
    }
    std::fs::write(folder.join("gt.log"), log).unwrap();
    let (row, records) = eval_multiway(&dir, &folder, "room");
    // folder, fragments, placed, pairs, in one component, within 15° and 0.3, …
    assert_eq!(row[1..6], ["3", "3", "3", "3", "3"], "{row:?}");
    let errors: Vec<(f64, f64)> = records
        .iter()
        .filter_map(|r| Some((r["rotation_deg"].as_f64()?, r["translation"].as_f64()?)))
        .collect();
    assert_eq!(errors.len(), 3);
    // The bunny is 0.15 m across: far within 3DMatch's criterion, so held to 1° and 1 mm.
    assert!(
        errors.iter().all(|&(r, t)| r < 1.0 && t < 0.001),
        "{errors:?}"
    );
}
