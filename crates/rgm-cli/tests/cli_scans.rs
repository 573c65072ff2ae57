//! End-to-end tests of the `rgm` command on real-scan folders (the Stanford layout) and scene
//! folders (the 3DMatch layout): pairs written, scored and evaluated, clear errors.

mod common;

use std::path::Path;
use std::process::Command;

use rgm_data::write_point_cloud;
use rgm_geom::euler::rotation_xyz_intrinsic;
use rgm_geom::{RigidTransform, Vector3};
use rgm_tests::Scratch;

use common::*;

/// A scan folder in the Stanford layout: the surface of a cube seen three ways (each scan the
/// points with one coordinate ≥ −0.3), each in its own frame, one gzip-compressed.
fn cube_scans(dir: &Path) {
    let grid: Vec<f64> = (0..=12).map(|i| -0.5 + i as f64 / 12.0).collect();
    let mut cube = Vec::new();
    for axis in 0..3 {
        for side in [-0.5, 0.5] {
            for &u in &grid {
                for &v in &grid {
                    let mut p = [u, v, u];
                    p[axis] = side;
                    p[(axis + 1) % 3] = u;
                    p[(axis + 2) % 3] = v;
                    cube.push(rgm_geom::Point3::new(p[0], p[1], p[2]));
                }
            }
        }
    }
    let mut conf = String::from("camera 0 0 0 0 0 0 1\n");
    for k in 0..3 {
        // Pose: p_world = R(q)ᵀ p + t with q = (0, 0, sin θ/2, cos θ/2), θ = 30° k.
        let half = (15.0 * k as f64).to_radians();
        let t = Vector3::new(0.1 * k as f64, -0.2, 0.05);
        let rt = rgm_geom::Matrix3::new(
            half.cos().powi(2) - half.sin().powi(2),
            2.0 * half.sin() * half.cos(),
            0.0,
            -2.0 * half.sin() * half.cos(),
            half.cos().powi(2) - half.sin().powi(2),
            0.0,
            0.0,
            0.0,
            1.0,
        ); // R(q)ᵀ
        let pose = RigidTransform::new(rt, t);
        let seen: Vec<_> = cube
            .iter()
            .filter(|p| p[k] >= -0.3)
            .map(|p| pose.inverse().apply(p))
            .collect();
        let name = format!("view{k}.ply");
        let file = if k == 1 {
            format!("{name}.gz")
        } else {
            name.clone()
        };
        write_point_cloud(dir.join(file), &rgm_geom::PointCloud::new(seen)).unwrap();
        conf += &format!(
            "bmesh {name} {} {} {} 0 0 {} {}\n",
            t.x,
            t.y,
            t.z,
            half.sin(),
            half.cos()
        );
    }
    std::fs::write(dir.join("cube.conf"), conf).unwrap();
}

#[test]
fn scan_pairs_are_written_scored_and_evaluated() {
    let dir = Scratch::new("cli-scans");
    let scans = dir.join("cube");
    std::fs::create_dir_all(&scans).unwrap();
    cube_scans(&scans);
    let out = dir.join("pairs");
    let text = stdout(&rgm(&[
        "pairs",
        "--scans",
        scans.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]));
    assert!(text.contains("wrote 3 pairs"), "{text}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("cube/pairs.json")).unwrap())
            .unwrap();
    let pairs = manifest["pairs"].as_array().unwrap();
    assert_eq!(pairs[0]["source_scan"], "view0.ply");
    assert_eq!(pairs[0]["target_scan"], "view1.ply");
    // The cube's diagonal, √3, up to the float32 of the files.
    let diagonal = pairs[0]["diagonal"].as_f64().unwrap();
    assert!((diagonal - 3f64.sqrt()).abs() < 1e-6, "{diagonal}");
    // The ground truth scores perfectly; a transform 1.5° off succeeds at 2° only.
    let off = RigidTransform::new(
        rotation_xyz_intrinsic(1.5f64.to_radians(), 0.0, 0.0),
        Vector3::zeros(),
    );
    for (name, tilt, at_2, at_1) in [
        ("truth", RigidTransform::identity(), "3 / 3", "3 / 3"),
        ("tilted", off, "3 / 3", "0 / 3"),
    ] {
        let found: Vec<serde_json::Value> = pairs
            .iter()
            .map(|p| {
                let truth =
                    parse_transform(&serde_json::json!({"transform": p["t_target_source"]}));
                let moved = truth.compose(&tilt).to_rows();
                serde_json::json!({"index": p["index"], "transform": moved, "time_ms": 1.0})
            })
            .collect();
        let file = dir.join(format!("{name}.json"));
        let json = serde_json::json!({"method": name, "pairs": found});
        std::fs::write(&file, json.to_string()).unwrap();
        let pairs_dir = out.join("cube");
        let text = stdout(&rgm(&[
            "score",
            file.to_str().unwrap(),
            "--pairs",
            pairs_dir.to_str().unwrap(),
        ]));
        let row = text
            .lines()
            .find(|l| l.starts_with(&format!("| {name}")))
            .unwrap();
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        assert_eq!(&cells[2..6], ["cube", "3", at_2, at_1], "{row}");
    }
    let text = stdout(&rgm(&[
        "eval",
        "--scans",
        scans.to_str().unwrap(),
        "--method",
        "icp",
    ]));
    let row = text
        .lines()
        .find(|l| l.starts_with("| icp"))
        .expect("a row");
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    assert_eq!(&cells[2..4], ["cube", "3"], "{row}");
}

#[test]
fn scan_folders_go_by_their_own_names_and_never_share_one() {
    let dir = Scratch::new("cli-scan-names");
    for site in ["site1", "site2"] {
        let scans = dir.join(site).join("cube");
        std::fs::create_dir_all(&scans).unwrap();
        cube_scans(&scans);
    }
    // Issue 44, D7: both were written to OUT/cube, the second's pairs.json over the first's.
    let out = dir.join("out");
    let both = rgm(&[
        "pairs",
        "--scans",
        dir.join("site1/cube").to_str().unwrap(),
        dir.join("site2/cube").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!both.status.success());
    let said = String::from_utf8_lossy(&both.stderr);
    assert!(said.contains("site2/cube are both named cube"), "{said}");
    assert!(!out.exists());
    // D11: `.` was named `.`, written to ../out/. (an error, or OUT itself).
    let here = Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(["pairs", "--scans", ".", "--out", "../out"])
        .current_dir(dir.join("site1/cube"))
        .output()
        .unwrap();
    assert!(stdout(&here).contains("wrote 3 pairs"));
    let manifest: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("site1/out/cube/pairs.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(manifest["scans"], "cube");
}

#[test]
fn scans_without_an_overlapping_pair_say_so() {
    // Issue 44, D14: `rgm eval --scans` printed an empty table and succeeded.
    let dir = Scratch::new("cli-scan-apart");
    let scans = dir.join("apart");
    std::fs::create_dir_all(&scans).unwrap();
    let grid = |x0: f64| {
        rgm_geom::PointCloud::new(
            (0..400)
                .map(|i| {
                    rgm_geom::Point3::new(x0 + (i % 20) as f64 * 0.05, (i / 20) as f64 * 0.05, 0.0)
                })
                .collect(),
        )
    };
    write_point_cloud(scans.join("a.ply"), &grid(0.0)).unwrap();
    write_point_cloud(scans.join("b.ply"), &grid(10.0)).unwrap();
    std::fs::write(
        scans.join("apart.conf"),
        "bmesh a.ply 0 0 0 0 0 0 1\nbmesh b.ply 0 0 0 0 0 0 1\n",
    )
    .unwrap();
    let (scans, out) = (scans.to_str().unwrap(), dir.join("out"));
    for args in [
        ["eval", "--scans", scans, "--method", "icp"],
        ["pairs", "--scans", scans, "--out", out.to_str().unwrap()],
    ] {
        let out = rgm(&args);
        let said = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && out.stdout.is_empty(),
            "{args:?}: {said}"
        );
        assert!(
            said.contains("no two of its 2 scans overlap by 45 % or more"),
            "{said}"
        );
        assert!(said.contains("no pair of scans"), "{said}");
    }
}

#[test]
fn threads_past_four_per_core_are_cut_with_a_warning() {
    // Issue 44, D10: --threads 65535 started 65,535 threads: no result in 150 s.
    let dir = Scratch::new("cli-threads");
    let (src, tgt) = known_pair(&dir);
    let cores = std::thread::available_parallelism().unwrap().get();
    let out = rgm(&[
        "--threads",
        "65535",
        "register",
        src.to_str().unwrap(),
        tgt.to_str().unwrap(),
        "--method",
        "icp",
        "--json",
    ]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains(&format!(
            "--threads 65535 is more than 4 per core on this machine's {cores}; using {}",
            4 * cores
        )),
        "{said}"
    );
    let found: serde_json::Value = serde_json::from_str(&stdout(&out)).unwrap();
    assert_eq!(found["method"], "icp");
}

#[test]
fn scene_pairs_of_a_gt_log_are_scored_by_the_3dmatch_criterion() {
    // Two pairs of the redkitchen fragments (../shared/data/scenes): 6 → 5, and 21 → 5, where
    // 27 % of the source overlaps the target and RANSAC found a room slid along its floor.
    let kitchen = data_dir().join("../scenes/redkitchen");
    let scratch = Scratch::new("cli-scenes");
    let dir = scratch.join("kitchen");
    std::fs::create_dir_all(&dir).unwrap();
    for k in [5, 6, 21] {
        let name = format!("cloud_bin_{k}.ply.gz");
        std::fs::copy(kitchen.join(&name), dir.join(&name)).unwrap();
    }
    let log = std::fs::read_to_string(kitchen.join("gt.log")).unwrap();
    let lines: Vec<&str> = log.lines().collect();
    let blocks: Vec<&[&str]> = lines.chunks(5).collect();
    let block = |head: &str| {
        blocks
            .iter()
            .find(|b| b[0].starts_with(head))
            .unwrap()
            .join("\n")
    };
    std::fs::write(
        dir.join("gt.log"),
        block("5\t6\t") + "\n" + &block("5\t21\t"),
    )
    .unwrap();
    let json = dir.join("out.json");
    let text = stdout(&rgm(&[
        "eval",
        "--scenes",
        dir.to_str().unwrap(),
        "--turns",
        "0",
        "150@1,1,1",
        "--json",
        json.to_str().unwrap(),
    ]));
    // The method is `rgm register`'s default unless named.
    let row = text
        .lines()
        .find(|l| l.starts_with("| auto+refine"))
        .unwrap();
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    // Both right under both turns, none wrong and trusted.
    assert_eq!(&cells[2..6], ["kitchen", "4", "4 / 4", "0 / 4"], "{row}");
    let records: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let pairs = records["folders"][0]["pairs"].as_array().unwrap();
    let turns: Vec<&str> = pairs.iter().map(|p| p["turn"].as_str().unwrap()).collect();
    assert_eq!(
        turns,
        ["0°", "150° about (1, 1, 1)", "0°", "150° about (1, 1, 1)"]
    );
    for p in &pairs[..2] {
        assert_eq!(p["source"], "cloud_bin_6.ply.gz");
        assert!(p["rotation_error_deg"].as_f64().unwrap() < 2.0, "{p}");
        assert!(p["translation_error_m"].as_f64().unwrap() < 0.1, "{p}");
        assert_eq!(p["registered"], true);
    }
    // 21 → 5 is right within the criterion, but the default doubts it (its check of where
    // the clouds coincide), and says so.
    for p in &pairs[2..] {
        assert_eq!(p["source"], "cloud_bin_21.ply.gz");
        assert!(p["rotation_error_deg"].as_f64().unwrap() < 5.0, "{p}");
        assert!(p["translation_error_m"].as_f64().unwrap() < 0.25, "{p}");
        assert_eq!(p["registered"], false);
    }
    // A missing fragment names the line of gt.log and the number.
    std::fs::remove_file(dir.join("cloud_bin_21.ply.gz")).unwrap();
    let out = rgm(&["eval", "--scenes", dir.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(said.contains("gt.log:6: no fragment 21"), "{said}");
}

#[test]
fn a_lidar_pair_is_not_slid_along_the_road() {
    // The LiDAR pair of ../shared/data/scenes, as published: judged at the unit frame's 0.02
    // (a metre on a 50 m sweep), the object cascade's result slid 0.17 m along the road won
    // over the scene stage's right one; the scene stage's judge now looks closer.
    let lidar = data_dir().join("../scenes/lidar");
    let scratch = Scratch::new("cli-lidar");
    let dir = scratch.join("lidar");
    std::fs::create_dir_all(&dir).unwrap();
    for name in ["251370668.pcd", "251371071.pcd"] {
        std::fs::copy(lidar.join(name), dir.join(name)).unwrap();
    }
    let relative = std::fs::read_to_string(lidar.join("relative.txt")).unwrap();
    std::fs::write(
        dir.join("gt.log"),
        format!("251370668 251371071 2\n{relative}"),
    )
    .unwrap();
    let json = dir.join("out.json");
    stdout(&rgm(&[
        "eval",
        "--scenes",
        dir.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]));
    let records: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let pair = &records["folders"][0]["pairs"][0];
    assert!(pair["rotation_error_deg"].as_f64().unwrap() < 1.0, "{pair}");
    assert!(
        pair["translation_error_m"].as_f64().unwrap() < 0.05,
        "{pair}"
    );
    assert_eq!(pair["registered"], true);
}
