//! Issue 14's command-line cases: a closed stdout, outputs that cannot be written, options that
//! select nothing. Each ends with a clear error (or quietly, for a closed pipe), never a panic.

use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use rgm_tests::Scratch;

fn rgm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(args)
        .output()
        .expect("the rgm binary runs")
}

fn data_dir() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/modelnet40_npy1024")
        .to_string_lossy()
        .into_owned()
}

/// Two small clouds as `.xyz` files in `dir`: a grid and the same grid moved by 0.01. Its rows
/// are spaced unevenly along x and y (0.3 times the squares), so that no turn maps it onto
/// itself: an even grid's pose is ambiguous, and it is rightly not registered.
fn clouds(dir: &Path) -> (String, String) {
    let uneven = |k: usize| 0.3 * (k * k) as f64;
    let grid: Vec<[f64; 3]> = (0..125)
        .map(|i| [uneven(i % 5), uneven(i / 5 % 5), (i / 25) as f64 * 1.3])
        .collect();
    let write = |name: &str, shift: f64| {
        let path = dir.join(name);
        let text: String = grid
            .iter()
            .map(|p| format!("{} {} {}\n", p[0] + shift, p[1], p[2]))
            .collect();
        std::fs::write(&path, text).unwrap();
        path.to_string_lossy().into_owned()
    };
    (write("a.xyz", 0.0), write("b.xyz", 0.01))
}

/// Runs rgm with its stdout a pipe closed before rgm writes: the output and stderr.
fn with_closed_stdout(args: &[&str]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    child.wait_with_output().unwrap()
}

/// Issue 14, case 5: `rgm register a b | head -1` and `rgm eval … | true` panicked (exit 101).
#[test]
fn a_closed_stdout_ends_rgm_quietly() {
    let dir = Scratch::new("hostile-pipe");
    let (a, b) = clouds(&dir);
    let register = with_closed_stdout(&["register", &a, &b, "--method", "icp"]);
    let data = data_dir();
    let eval = with_closed_stdout(&["eval", "--method", "icp", "--limit", "2", "--data", &data]);
    for out in [register, eval] {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.signal(), Some(13), "SIGPIPE: {stderr}");
        assert!(stderr.is_empty(), "{stderr}");
    }
}

/// Issue 14, case 9: an output that cannot be written was found only after the work (an
/// evaluation printed its table, then failed); `render --out x.jpg` wrote PNG bytes.
#[test]
fn outputs_are_checked_before_the_work() {
    let dir = Scratch::new("hostile-out");
    let (a, b) = clouds(&dir);
    let data = data_dir();
    let nowhere = dir.join("missing/folder/pairs.json");
    let out = rgm(&[
        "eval",
        "--method",
        "icp",
        "--limit",
        "1",
        "--data",
        &data,
        "--json",
        nowhere.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(out.stdout.is_empty(), "the work ran first");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.starts_with(&format!("rgm: error: cannot write {}: ", nowhere.display())),
        "{err}"
    );
    let out = rgm(&["register", &a, &b, "--method", "icp", "--out", "moved.obj"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("moved.obj: unknown point-cloud extension"),
        "{err}"
    );
    let jpg = dir.join("x.jpg");
    let out = rgm(&[
        "render",
        &a,
        &b,
        "--method",
        "icp",
        "--out",
        jpg.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("writes PNG images; give the file a .png name"),
        "{err}"
    );
    assert!(!jpg.exists());
    // The check leaves no file behind.
    let png = dir.join("x.png");
    let out = rgm(&[
        "render",
        &a,
        &b,
        "--method",
        "icp",
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(png.exists());
}

/// Issue 14, case 9: `eval --limit 0` printed an internal message ("needs at least 1 points").
#[test]
fn a_limit_of_zero_pairs_is_refused_by_name() {
    let out = rgm(&[
        "eval",
        "--method",
        "icp",
        "--limit",
        "0",
        "--data",
        &data_dir(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("'0' for '--limit <N>'"), "{err}");
}

/// Issue 14, case 2: a `.ply` name for `/dev/zero` was read until memory ran out.
#[test]
fn an_endless_device_is_refused() {
    let dir = Scratch::new("hostile-zero");
    let link = dir.join("zero.ply");
    std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
    let link = link.to_str().unwrap();
    let out = rgm(&["register", link, link]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        err.trim_end(),
        format!("rgm: error: {link}: is a device, FIFO or socket, not a file")
    );
}

/// An airplane of the test split and its copy at the pose (20°, 10°, 30°), t (0.2, −0.1, 0.3),
/// one point of each replaced by `far` (none when `None`), as `.npy` files in `dir`.
fn airplane_pair(dir: &Path, far: Option<f64>) -> (String, String, rgm_geom::RigidTransform) {
    use rgm_geom::euler::rotation_xyz_intrinsic;
    use rgm_geom::{Point3, RigidTransform, Vector3};
    let path = Path::new(&data_dir()).join("airplane/test/airplane_0627.npy");
    let source = rgm_data::read_point_cloud(path).unwrap();
    let r = rotation_xyz_intrinsic(20f64.to_radians(), 10f64.to_radians(), 30f64.to_radians());
    let truth = RigidTransform::new(r, Vector3::new(0.2, -0.1, 0.3));
    let (mut s, mut t) = (source.clone(), source.transformed(&truth));
    if let Some(far) = far {
        s.points[3] = Point3::new(far, far, -far);
        t.points[500] = Point3::new(-far, 0.0, far);
    }
    let (src, tgt) = (dir.join("src.npy"), dir.join("tgt.npy"));
    rgm_data::write_point_cloud(&src, &s).unwrap();
    rgm_data::write_point_cloud(&tgt, &t).unwrap();
    let name = |p: PathBuf| p.to_string_lossy().into_owned();
    (name(src), name(tgt), truth)
}

/// The JSON object `rgm register --json` printed.
fn json(out: &Output) -> serde_json::Value {
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

/// Issue 27, case 1: a stray point at 1e5 in each cloud gave a rotation 152° wrong with
/// fitness 0.999.
#[test]
fn a_far_outlier_in_each_cloud_is_registered_right() {
    let dir = Scratch::new("hostile-outlier");
    let (src, tgt, truth) = airplane_pair(&dir, Some(1e5));
    let out = rgm(&["register", &src, &tgt, "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let value = json(&out);
    assert_eq!(value["registered"], true);
    let rows = value["transform"].as_array().unwrap();
    let r = rgm_geom::Matrix3::from_fn(|i, j| rows[i][j].as_f64().unwrap());
    let error = rgm_geom::RigidTransform::new(truth.rotation.transpose() * r, Default::default());
    assert!(error.rotation_angle_deg() < 2.0, "{value}");
    assert!(value["fitness"].as_f64().unwrap() < 1.0, "{value}");
}

/// Issue 27: clouds without overlap got a transform reported as right; now `registered: false`
/// with the reason, a failure status, and no `--out` written.
#[test]
fn clouds_without_overlap_are_not_registered() {
    let dir = Scratch::new("hostile-no-overlap");
    let (src, _, _) = airplane_pair(&dir, None);
    // A 10 × 10 × 10 grid 0.2 apart: nowhere within 0.02 of the airplane's surface but by chance.
    let grid: String = (0..1000)
        .map(|i| {
            format!(
                "{} {} {}\n",
                (i % 10) as f64 * 0.2,
                (i / 10 % 10) as f64 * 0.2,
                (i / 100) as f64 * 0.2
            )
        })
        .collect();
    let tgt = dir.join("grid.xyz");
    std::fs::write(&tgt, grid).unwrap();
    let moved = dir.join("moved.ply");
    let out = rgm(&[
        "register",
        &src,
        tgt.to_str().unwrap(),
        "--json",
        "--out",
        moved.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let value = json(&out);
    assert_eq!(value["registered"], false);
    let reason = value["reason"].as_str().unwrap();
    assert!(reason.contains("overlaps too little"), "{reason}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.starts_with("rgm: error: not registered: the best candidate"),
        "{err}"
    );
    assert!(!moved.exists());
}

/// Issue 27, cases 10 and 12: `--gamma nan` was accepted (saved as `null`: the run could never
/// be resumed); `--until-epoch 0` reported best weights that did not exist.
#[test]
fn training_options_out_of_range_are_refused_by_name() {
    let dir = Scratch::new("hostile-train");
    let run = dir.join("run");
    let run = run.to_str().unwrap();
    let data = data_dir();
    let train = |extra: &[&str]| {
        let mut args = vec!["train", "--data", &data, "--out", run];
        args.extend_from_slice(extra);
        rgm(&args)
    };
    for (extra, expected) in [
        (&["--until-epoch", "0"][..], "'0' for '--until-epoch <N>'"),
        (
            &["--gamma", "nan"][..],
            "gamma must be a positive number, got NaN",
        ),
        (
            &["--gamma=-0.5"][..],
            "gamma must be a positive number, got -0.5",
        ),
        (
            &["--momentum", "nan"][..],
            "momentum must be a number from 0 up to 1 (1 excluded), got NaN",
        ),
    ] {
        let out = train(extra);
        assert!(!out.status.success(), "{extra:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expected), "{extra:?}: {err}");
        assert!(!Path::new(run).join("config.json").exists(), "{extra:?}");
    }
}

/// Issue 27, case 13: scoring zero pairs said "needs at least 1 point", a 5-row transform
/// "trailing characters", a time of -1e300 was printed with 300 digits (`render --matrix` with
/// a method without correspondences: `tests/render.rs`).
#[test]
fn scores_of_the_wrong_shape_say_what_is_wrong() {
    let dir = Scratch::new("hostile-score");
    airplane_pair(&dir, None);
    let identity = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";
    let manifest =
        |pairs: &str| format!(r#"{{"setting": "clean", "unseen": false, "pairs": [{pairs}]}}"#);
    let entry = format!(
        r#"{{"index": 0, "label": 0, "source": "src.npy", "target": "tgt.npy", "t_target_source": {identity}}}"#
    );
    let transforms = dir.join("found.json");
    let score = |pairs_json: &str, found: &str| {
        std::fs::write(dir.join("pairs.json"), pairs_json).unwrap();
        std::fs::write(
            &transforms,
            format!(r#"{{"method": "x", "pairs": [{found}]}}"#),
        )
        .unwrap();
        let out = rgm(&[
            "score",
            transforms.to_str().unwrap(),
            "--pairs",
            dir.to_str().unwrap(),
        ]);
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = score(&manifest(""), "");
    assert!(
        err.contains("pairs.json lists no pairs: nothing to score"),
        "{err}"
    );
    let five = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1],[0,0,0,1]]";
    let err = score(
        &manifest(&entry),
        &format!(r#"{{"index": 0, "transform": {five}, "time_ms": 1}}"#),
    );
    assert!(
        err.contains(
            "transform of pair 0 has rows of [4, 4, 4, 4, 4] numbers; a transform is 4 rows of 4"
        ),
        "{err}"
    );
    let err = score(
        &manifest(&entry),
        &format!(r#"{{"index": 0, "transform": {identity}, "time_ms": -1e300}}"#),
    );
    assert!(
        err.contains("pair 0 has time_ms -1e300; a time is a number of milliseconds from 0 up"),
        "{err}"
    );
}

/// Waits for `child`, killing it (and failing) if it has not ended after a minute: a guard
/// against a hang, not a timing.
fn wait_or_kill(mut child: std::process::Child) -> Output {
    for _ in 0..600 {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    child.kill().unwrap();
    panic!("rgm hangs: {:?}", child.wait_with_output().unwrap());
}

/// Runs rgm with `args` and then a FIFO named `name` (in `dir`) as its last argument, reading
/// the FIFO meanwhile: rgm's output and what the FIFO carried.
fn through_fifo(dir: &Path, name: &str, args: &[&str]) -> (Output, String) {
    let fifo = dir.join(name);
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    let child = Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(args)
        .arg(&fifo)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let reader = std::thread::spawn(move || std::fs::read_to_string(fifo).unwrap());
    let out = wait_or_kill(child);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (out, reader.join().unwrap())
}

/// Issue 27, case 4: `--out` a FIFO hung for good (the writability check opened it, its reader
/// got an empty file, and the real write then waited for a second reader); so did `eval --json`.
#[test]
fn a_fifo_output_gets_its_content_once() {
    let dir = Scratch::new("hostile-fifo");
    let (a, b) = clouds(&dir);
    let (_, moved) = through_fifo(
        &dir,
        "moved.xyz",
        &["register", &a, &b, "--method", "icp", "--out"],
    );
    assert_eq!(moved.lines().count(), 125, "{moved}");
    let data = data_dir();
    let eval = [
        "eval", "--method", "icp", "--limit", "1", "--data", &data, "--json",
    ];
    let (_, json) = through_fifo(&dir, "eval.json", &eval);
    let value: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(value["pairs"].as_array().unwrap().len(), 1);
}

/// Issue 27, case 8: `--out` a dangling symbolic link, and the run fails: the link was deleted
/// and an empty file left at its target. On success the link became a regular file.
#[test]
fn a_symbolic_link_out_stays_a_link() {
    let dir = Scratch::new("hostile-link");
    let (a, b) = clouds(&dir);
    let link = dir.join("link.xyz");
    std::os::unix::fs::symlink("moved.xyz", &link).unwrap();
    let link_str = link.to_str().unwrap();
    let broken = dir.join("broken.xyz");
    std::fs::write(&broken, "1 2 three\n").unwrap();
    let out = rgm(&[
        "register",
        &a,
        broken.to_str().unwrap(),
        "--method",
        "icp",
        "--out",
        link_str,
    ]);
    assert!(!out.status.success());
    let is_link = |p: &Path| {
        std::fs::symlink_metadata(p)
            .unwrap()
            .file_type()
            .is_symlink()
    };
    assert!(is_link(&link));
    assert!(!dir.join("moved.xyz").exists());
    let out = rgm(&["register", &a, &b, "--method", "icp", "--out", link_str]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(is_link(&link));
    let moved = std::fs::read_to_string(dir.join("moved.xyz")).unwrap();
    assert_eq!(moved.lines().count(), 125);
}

/// Issue 27, case 5: under `ulimit -v 400000` RGM spun at 100 % CPU for good (OpenBLAS retrying
/// its allocations); the estimate checked only the system's free memory.
#[test]
fn a_memory_limit_is_respected_with_the_estimate() {
    let dir = Scratch::new("hostile-ulimit");
    let (src, tgt, _) = airplane_pair(&dir, None);
    let child = Command::new("sh")
        .args(["-c", "ulimit -v 400000 && exec \"$0\" \"$@\""])
        .arg(env!("CARGO_BIN_EXE_rgm"))
        .args(["register", &src, &tgt, "--method", "rgm"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let out = wait_or_kill(child);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("rgm: matching 1024 × 1024 points would need about")
            && err.contains("this process may take (free memory, ulimit -v, cgroup limit)"),
        "{err}"
    );
}

/// `--json /dev/stdout` with stdout redirected to a file: written into that file, not through a
/// temporary file renamed over it (the redirection would keep writing to the replaced one).
#[test]
fn json_to_dev_stdout_reaches_a_redirected_stdout() {
    let dir = Scratch::new("hostile-stdout");
    let log = dir.join("log.txt");
    let status = Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args([
            "eval",
            "--method",
            "icp",
            "--limit",
            "1",
            "--data",
            &data_dir(),
        ])
        .args(["--json", "/dev/stdout"])
        .stdout(std::fs::File::create(&log).unwrap())
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read_to_string(&log).unwrap();
    // The table first, then the JSON, then the line that says so: nothing overwritten.
    let (table, json) = (
        text.find("| method").unwrap(),
        text.find("\"pairs\"").unwrap(),
    );
    let said = text.find("wrote per-pair results to /dev/stdout").unwrap();
    assert!(table < json && json < said, "{text}");
}
