//! End-to-end tests of the `rgm` command: files in, transforms and tables out, clear errors.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rgm_data::{read_point_cloud, write_point_cloud};
use rgm_geom::euler::rotation_xyz_intrinsic;
use rgm_geom::{Matrix4, RigidTransform, Vector3};
use rgm_tests::Scratch;

fn rgm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(args)
        .output()
        .expect("the rgm binary runs")
}

fn stdout(out: &Output) -> String {
    assert!(
        out.status.success(),
        "rgm failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).expect("utf-8 output")
}

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/modelnet40_npy1024")
}

fn airplane() -> PathBuf {
    data_dir().join("airplane/test/airplane_0627.npy")
}

/// A known pose within the protocol's range (20°, 10°, 30°; t = (0.2, −0.1, 0.3)).
fn known_pose() -> RigidTransform {
    let r = rotation_xyz_intrinsic(20f64.to_radians(), 10f64.to_radians(), 30f64.to_radians());
    RigidTransform::new(r, Vector3::new(0.2, -0.1, 0.3))
}

fn parse_transform(value: &serde_json::Value) -> RigidTransform {
    let rows = value["transform"].as_array().expect("transform rows");
    let m = Matrix4::from_fn(|r, c| rows[r][c].as_f64().expect("a number"));
    RigidTransform::from_matrix4(&m, 1e-6).expect("a rigid transform")
}

#[test]
fn register_recovers_a_known_pose_as_json() {
    let dir = Scratch::new("cli-register");
    let source = read_point_cloud(airplane()).unwrap();
    let target = source.transformed(&known_pose());
    let (src, tgt, aligned) = (
        dir.join("src.ply"),
        dir.join("tgt.xyz"),
        dir.join("aligned.npy"),
    );
    write_point_cloud(&src, &source).unwrap();
    write_point_cloud(&tgt, &target).unwrap();
    let out = rgm(&[
        "register",
        src.to_str().unwrap(),
        tgt.to_str().unwrap(),
        "--method",
        "fgr",
        "--no-refine",
        "--json",
        "--out",
        aligned.to_str().unwrap(),
    ]);
    let value: serde_json::Value = serde_json::from_str(&stdout(&out)).expect("one JSON object");
    assert_eq!(value["method"], "fgr");
    assert!(value["time_ms"].as_f64().unwrap() > 0.0);
    let found = parse_transform(&value);
    let residual = known_pose().inverse().compose(&found);
    assert!(
        residual.rotation_angle_deg() < 1.0,
        "rotation error {}°",
        residual.rotation_angle_deg()
    );
    assert!(
        residual.translation.norm() < 0.02,
        "translation error {}",
        residual.translation.norm()
    );
    // The moved source lies on the target.
    let moved = read_point_cloud(&aligned).unwrap();
    let worst = moved
        .points
        .iter()
        .zip(&target.points)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    assert!(worst < 0.05, "aligned source is {worst} from the target");
}

#[test]
fn register_prints_a_matrix_by_default() {
    let dir = Scratch::new("cli-text");
    let cloud = read_point_cloud(airplane()).unwrap();
    let path = dir.join("same.ply");
    write_point_cloud(&path, &cloud).unwrap();
    let text = stdout(&rgm(&[
        "register",
        path.to_str().unwrap(),
        path.to_str().unwrap(),
        "--method",
        "icp",
    ]));
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_whitespace().map(|v| v.parse().unwrap()).collect())
        .collect();
    // A cloud onto itself: the identity.
    assert_eq!(rows.len(), 4);
    for (r, row) in rows.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            assert!((v - if r == c { 1.0 } else { 0.0 }).abs() < 1e-9, "{text}");
        }
    }
}

#[test]
fn bad_input_names_the_file_and_the_line() {
    let dir = Scratch::new("cli-bad");
    let bad = dir.join("bad.xyz");
    std::fs::write(&bad, "0 0 0\n1 2 nope\n").unwrap();
    let out = rgm(&["register", bad.to_str().unwrap(), bad.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.xyz:2"), "{err}");
    let missing = rgm(&["register", "/no/such/file.ply", bad.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&missing.stderr);
    // The file once, the operating system's reason once.
    assert!(err.starts_with("rgm: error: /no/such/file.ply: "), "{err}");
    assert_eq!(err.matches("os error 2").count(), 1, "{err}");
}

/// The cells of the ICP row `rgm eval --method icp ARGS --data …` prints.
fn icp_eval_row(args: &[&str]) -> Vec<String> {
    let data = data_dir();
    let command = [
        &["eval", "--method", "icp"][..],
        args,
        &["--data", data.to_str().unwrap()],
    ];
    let text = stdout(&rgm(&command.concat()));
    let row = text
        .lines()
        .find(|l| l.starts_with("| icp"))
        .expect("a row for icp");
    row.split('|').map(|c| c.trim().to_string()).collect()
}

#[test]
fn eval_prints_the_metrics_table_whatever_the_workers() {
    let cells =
        |workers: &str| icp_eval_row(&["--setting", "clean", "--limit", "5", "--workers", workers]);
    let (one, three) = (cells("1"), cells("3"));
    assert_eq!((one[2].as_str(), one[3].as_str()), ("clean", "5"));
    // Every metric the same; only the time column (the last) may differ.
    assert_eq!(one[..one.len() - 2], three[..three.len() - 2]);
}

#[test]
fn eval_on_the_validation_split_says_so_and_differs_from_test() {
    let row = |split: &str| icp_eval_row(&["--limit", "2", "--split", split]);
    let (val, test) = (row("validation"), row("test"));
    assert_eq!(
        (val[2].as_str(), test[2].as_str()),
        ("partial (validation)", "partial")
    );
    // Other shapes, so other errors.
    assert_ne!(val[4], test[4]);
}

#[test]
fn rgm_passes_are_an_option() {
    let dir = Scratch::new("cli-passes");
    let (src, tgt) = known_pair(&dir);
    let (src, tgt) = (src.to_str().unwrap(), tgt.to_str().unwrap());
    for passes in ["1", "3"] {
        let out: serde_json::Value = serde_json::from_str(&stdout(&rgm(&[
            "register",
            src,
            tgt,
            "--json",
            "--method",
            "rgm",
            "--no-refine",
            "--passes",
            passes,
        ])))
        .unwrap();
        assert_eq!(out["iterations"].to_string(), passes, "{out}");
    }
    let out = rgm(&["register", src, tgt, "--method", "rgm", "--passes", "0"]);
    assert!(!out.status.success());
}

#[test]
fn every_nth_pair_is_the_same_pair_as_in_the_whole_run() {
    let data = data_dir();
    let written = |name: &str, extra: &[&str]| -> Vec<serde_json::Value> {
        let dir = Scratch::new(&format!("cli-{name}"));
        let mut args = vec![
            "pairs",
            "--setting",
            "noise",
            "--out",
            dir.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--data", data.to_str().unwrap()]);
        stdout(&rgm(&args));
        let manifest: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("pairs.json")).unwrap())
                .unwrap();
        manifest["pairs"].as_array().unwrap().clone()
    };
    let whole = written("pairs-first", &["--limit", "7"]);
    let sample = written("pairs-every", &["--every", "3", "--limit", "3"]);
    let indices: Vec<u64> = sample
        .iter()
        .map(|p| p["index"].as_u64().unwrap())
        .collect();
    assert_eq!(indices, [0, 3, 6]);
    for p in &sample {
        let same = &whole[p["index"].as_u64().unwrap() as usize];
        assert_eq!(p["shape"], same["shape"]);
        assert_eq!(p["t_target_source"], same["t_target_source"]);
    }
}

#[test]
fn pairs_then_score_reproduces_eval() {
    let dir = Scratch::new("cli-pairs");
    let data = data_dir();
    stdout(&rgm(&[
        "pairs",
        "--setting",
        "partial",
        "--limit",
        "4",
        "--out",
        dir.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
    ]));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("pairs.json")).unwrap()).unwrap();
    assert_eq!(manifest["pairs"].as_array().unwrap().len(), 4);
    // Scoring the ground truth itself: perfect rotation and translation on every pair.
    let truth: Vec<serde_json::Value> = manifest["pairs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| serde_json::json!({"index": p["index"], "transform": p["t_target_source"], "time_ms": 0.0}))
        .collect();
    let file = dir.join("truth.json");
    std::fs::write(
        &file,
        serde_json::json!({"method": "truth", "pairs": truth}).to_string(),
    )
    .unwrap();
    let text = stdout(&rgm(&[
        "score",
        file.to_str().unwrap(),
        "--pairs",
        dir.to_str().unwrap(),
    ]));
    let row = text
        .lines()
        .find(|l| l.starts_with("| truth"))
        .expect("a row for truth");
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    assert_eq!(cells[2], "partial");
    assert!(
        cells[4].parse::<f64>().unwrap() < 1e-3,
        "MIE(R) of the truth: {row}"
    );
    assert_eq!(cells[9], "100.00%");
    // Issue 14, case 7: a pair left out, or scored twice, is an error, not a better score.
    for (name, entries) in [
        ("missing", vec![truth[0].clone(), truth[2].clone()]),
        (
            "twice",
            vec![
                truth[0].clone(),
                truth[1].clone(),
                truth[1].clone(),
                truth[2].clone(),
                truth[3].clone(),
            ],
        ),
    ] {
        let file = dir.join(format!("{name}.json"));
        let json = serde_json::json!({"method": name, "pairs": entries});
        std::fs::write(&file, json.to_string()).unwrap();
        let out = rgm(&[
            "score",
            file.to_str().unwrap(),
            "--pairs",
            dir.to_str().unwrap(),
        ]);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        let expected = if name == "missing" {
            "2 of the 4 pairs of"
        } else {
            "pair 1 has more than one transform"
        };
        assert!(err.contains(expected), "{err}");
    }
}

#[test]
fn eval_without_data_says_how_to_give_it() {
    let out = Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(["eval", "--method", "icp"])
        .env_remove("RGM_DATA")
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--data"));
}

/// The airplane and its copy at `known_pose`, as files in `dir`.
fn known_pair(dir: &Path) -> (PathBuf, PathBuf) {
    let source = read_point_cloud(airplane()).unwrap();
    let (src, tgt) = (dir.join("src.npy"), dir.join("tgt.npy"));
    write_point_cloud(&src, &source).unwrap();
    write_point_cloud(&tgt, &source.transformed(&known_pose())).unwrap();
    (src, tgt)
}

#[test]
fn register_runs_rgm_with_the_built_in_model() {
    let dir = Scratch::new("cli-builtin");
    let (src, tgt) = known_pair(&dir);
    let (src, tgt) = (src.to_str().unwrap(), tgt.to_str().unwrap());
    let plain: serde_json::Value = serde_json::from_str(&stdout(&rgm(&[
        "register",
        src,
        tgt,
        "--json",
        "--method",
        "rgm",
        "--no-refine",
    ])))
    .unwrap();
    assert_eq!(plain["method"], "rgm");
    assert_eq!(plain["refined"], false);
    assert_eq!(plain["candidates"], serde_json::json!([]));
    assert_eq!(plain["chosen"], serde_json::Value::Null);
    // Matched on every point (the manifest's match points): at most 1,024 one-to-one
    // correspondences, more than the 384 the model was trained on.
    let used = plain["correspondences"].as_u64().unwrap();
    assert!((385..=1024).contains(&used), "{plain}");
    let refined: serde_json::Value = serde_json::from_str(&stdout(&rgm(&[
        "register", src, tgt, "--json", "--method", "rgm", "--refine",
    ])))
    .unwrap();
    assert_eq!(
        (&refined["method"], &refined["refined"]),
        (&"rgm+icp".into(), &true.into())
    );
    // Refined, the correspondences are the refinement's inliers: every source point of this
    // clean pair.
    assert_eq!(refined["correspondences"], 1024);
    let residual = known_pose().inverse().compose(&parse_transform(&refined));
    assert!(
        residual.rotation_angle_deg() < 1.0 && residual.translation.norm() < 0.01,
        "refined: {}° and {}",
        residual.rotation_angle_deg(),
        residual.translation.norm()
    );
}

#[test]
fn register_by_default_runs_fgr_first_and_rgm_when_asked_and_names_the_winner() {
    let dir = Scratch::new("cli-auto");
    let (src, tgt) = known_pair(&dir);
    let (src, tgt) = (src.to_str().unwrap(), tgt.to_str().unwrap());
    let names = |out: &serde_json::Value| -> Vec<String> {
        out["candidates"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["method"].as_str().unwrap().to_string())
            .collect()
    };
    // FGR's result is taken: it overlaps nearly every point and no turned pose as well.
    let out: serde_json::Value =
        serde_json::from_str(&stdout(&rgm(&["register", src, tgt, "--json"]))).unwrap();
    assert_eq!(
        (&out["method"], &out["refined"]),
        (&"auto+icp".into(), &true.into())
    );
    assert_eq!(names(&out), ["fgr+icp"]);
    assert_eq!(out["chosen"], "fgr+icp");
    // --accept inf runs both.
    let out: serde_json::Value = serde_json::from_str(&stdout(&rgm(&[
        "register", src, tgt, "--json", "--accept", "inf",
    ])))
    .unwrap();
    assert_eq!(names(&out), ["fgr+icp", "rgm+icp"]);
    let candidates = out["candidates"].as_array().unwrap();
    let chosen = candidates
        .iter()
        .find(|c| c["method"] == out["chosen"])
        .unwrap();
    assert_eq!(chosen["transform"], out["transform"]);
    for c in candidates {
        let score = c["score"].as_f64().unwrap();
        assert!(
            score <= chosen["score"].as_f64().unwrap() && score > 1.9,
            "{out}"
        );
    }
    let residual = known_pose().inverse().compose(&parse_transform(&out));
    assert!(
        residual.rotation_angle_deg() < 0.1 && residual.translation.norm() < 1e-3,
        "{}° and {}",
        residual.rotation_angle_deg(),
        residual.translation.norm()
    );
    // The text output lists both, the winner marked.
    let text = stdout(&rgm(&["register", src, tgt, "--accept", "inf"]));
    assert!(
        text.contains("# candidate rgm+icp: overlap score"),
        "{text}"
    );
    assert!(text.contains("(chosen)"), "{text}");
}

#[test]
fn rgm_options_with_another_method_are_refused() {
    let dir = Scratch::new("cli-options");
    let (src, tgt) = known_pair(&dir);
    let (src, tgt) = (src.to_str().unwrap(), tgt.to_str().unwrap());
    for (args, says) in [
        (
            ["--method", "fgr", "--match-points", "100"],
            "apply to the rgm and auto methods only",
        ),
        (["--method", "icp", "--refine", "--json"], "ICP already"),
        (
            ["--method", "rgm", "--accept", "1"],
            "accept applies to the auto method only",
        ),
        (
            ["--method", "auto", "--accept=-1", "--json"],
            "accept must be a score of at least 0",
        ),
    ] {
        let out = rgm(&[&["register", src, tgt][..], &args[..]].concat());
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{err}");
    }
}

#[test]
fn fgr_refined_with_icp_is_named_and_recovers_the_pose() {
    let dir = Scratch::new("cli-fgr-icp");
    let (src, tgt) = known_pair(&dir);
    let (src, tgt) = (src.to_str().unwrap(), tgt.to_str().unwrap());
    let out: serde_json::Value = serde_json::from_str(&stdout(&rgm(&[
        "register", src, tgt, "--json", "--method", "fgr", "--refine",
    ])))
    .unwrap();
    assert_eq!(
        (&out["method"], &out["refined"]),
        (&"fgr+icp".into(), &true.into())
    );
    let residual = known_pose().inverse().compose(&parse_transform(&out));
    assert!(
        residual.rotation_angle_deg() < 0.1 && residual.translation.norm() < 1e-3,
        "{}° and {}",
        residual.rotation_angle_deg(),
        residual.translation.norm()
    );
}

#[test]
fn eval_of_rgm_without_weights_uses_the_built_in_model() {
    let text = stdout(&rgm(&[
        "eval",
        "--method",
        "rgm",
        "--limit",
        "2",
        "--data",
        data_dir().to_str().unwrap(),
    ]));
    let row = text
        .lines()
        .find(|l| l.starts_with("| rgm"))
        .expect("a row for rgm");
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    assert_eq!((cells[2], cells[3]), ("partial", "2"), "{row}");
}

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
    let row = text.lines().find(|l| l.starts_with("| auto+icp")).unwrap();
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
