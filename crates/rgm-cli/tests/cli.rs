//! End-to-end tests of the `rgm` command: files in, transforms and tables out, clear errors.

use std::process::Command;

use rgm_data::{read_point_cloud, write_point_cloud};
use rgm_tests::Scratch;

mod common;

use common::*;

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
        (&"rgm+refine".into(), &true.into())
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
        (&"auto+refine".into(), &true.into())
    );
    assert_eq!(names(&out), ["fgr+refine"]);
    assert_eq!(out["chosen"], "fgr+refine");
    // --accept inf runs both.
    let out: serde_json::Value = serde_json::from_str(&stdout(&rgm(&[
        "register", src, tgt, "--json", "--accept", "inf",
    ])))
    .unwrap();
    assert_eq!(names(&out), ["fgr+refine", "rgm+refine"]);
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
        text.contains("# candidate rgm+refine: overlap score"),
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
            "apply to the rgm, auto and scene methods only",
        ),
        (["--method", "icp", "--refine", "--json"], "ICP already"),
        (
            ["--method", "rgm", "--accept", "1"],
            "accept applies to the auto and scene methods only",
        ),
        (
            ["--method", "auto", "--accept=-1", "--json"],
            "accept must be a score of at least 0",
        ),
        (
            ["--method", "scene", "--no-refine", "--json"],
            "the scene method refines its results",
        ),
    ] {
        let out = rgm(&[&["register", src, tgt][..], &args[..]].concat());
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{err}");
    }
}

#[test]
fn fgr_refined_is_named_and_recovers_the_pose() {
    let dir = Scratch::new("cli-fgr-refine");
    let (src, tgt) = known_pair(&dir);
    let (src, tgt) = (src.to_str().unwrap(), tgt.to_str().unwrap());
    let out: serde_json::Value = serde_json::from_str(&stdout(&rgm(&[
        "register", src, tgt, "--json", "--method", "fgr", "--refine",
    ])))
    .unwrap();
    assert_eq!(
        (&out["method"], &out["refined"]),
        (&"fgr+refine".into(), &true.into())
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
