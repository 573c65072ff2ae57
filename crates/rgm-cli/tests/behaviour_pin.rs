//! The behaviour pin: `rgm register --json` on ModelNet40 test pairs of the benchmark protocol
//! (`rgm pairs`), with every method, must give the transforms recorded in
//! `tests/golden/register_transforms.json`, to 1e-9 per matrix entry (bit-identical is
//! expected: the same arithmetic in the same order gives the same bits), and trust them or not
//! (`registered`) as recorded.
//!
//! It guards redesigns that must not change results. A change that is meant to change results
//! regenerates the file with `scripts/regen-behaviour-pin.sh` (which sets `RGM_PIN_BLESS=1`) and
//! says why in its commit message; the file records the commit it was made at.
//!
//! The pairs: 20 partial, 5 noise and 5 clean test pairs, spread over the test split by
//! `--every` (the split is ordered by category). The classical methods run on all 30; the
//! network's (rgm and auto, each refined and not) on every third pair of each setting, which keeps
//! the test near a minute in the test profile. The test says so and passes when the data
//! (`../shared/data/modelnet40_npy1024` beside the repository, or `$RGM_DATA`) is absent.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Entries further apart than this in any matrix entry fail the pin.
const TOLERANCE: f64 = 1e-9;

/// (setting, pairs, --every): the pairs of each setting the pin runs.
const SETTINGS: [(&str, usize, usize); 3] =
    [("partial", 20, 120), ("noise", 5, 480), ("clean", 5, 480)];

/// The network's methods run on pairs whose position in their setting is a multiple of this.
const NETWORK_STRIDE: usize = 3;

/// (variant name, `rgm register` options, whether it runs the network). The variant with no
/// option is `rgm register`'s default (auto, refined).
const VARIANTS: [(&str, &[&str], bool); 7] = [
    ("icp", &["--method", "icp"], false),
    ("fgr", &["--method", "fgr", "--no-refine"], false),
    ("fgr+refine", &["--method", "fgr", "--refine"], false),
    ("rgm", &["--method", "rgm", "--no-refine"], true),
    ("rgm+refine", &["--method", "rgm", "--refine"], true),
    ("auto", &["--method", "auto", "--no-refine"], true),
    ("default", &[], true),
];

fn golden_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/register_transforms.json")
}

fn data_dir() -> PathBuf {
    std::env::var_os("RGM_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/modelnet40_npy1024")
        })
}

/// What `rgm ARGS` prints; a result reported as not registered (ICP from the identity that
/// finds no overlap) is printed and pinned like any other.
fn rgm(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(args)
        .output()
        .expect("the rgm binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() || stderr.contains("rgm: error: not registered: "),
        "rgm {}: {stderr}",
        args.join(" "),
    );
    String::from_utf8(out.stdout).expect("utf-8 output")
}

/// What one registration is pinned by: the method name the command reported, whether it
/// trusted the result, and the 4×4 transform.
#[derive(Clone, Debug, PartialEq)]
struct Entry {
    method: String,
    registered: bool,
    transform: [[f64; 4]; 4],
}

/// The pinned registrations by key (`setting/index/variant`).
type Pinned = BTreeMap<String, Entry>;

/// Writes the pairs of every setting into `dir` and registers them with every variant.
fn register_all(data: &Path, dir: &Path) -> Pinned {
    let mut pinned = Pinned::new();
    for (setting, limit, every) in SETTINGS {
        let out = dir.join(setting);
        let (limit, every) = (limit.to_string(), every.to_string());
        rgm(&[
            "pairs",
            "--data",
            data.to_str().unwrap(),
            "--setting",
            setting,
            "--limit",
            &limit,
            "--every",
            &every,
            "--out",
            out.to_str().unwrap(),
        ]);
        let manifest: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("pairs.json")).unwrap())
                .unwrap();
        for (position, pair) in manifest["pairs"].as_array().unwrap().iter().enumerate() {
            let file = |key: &str| out.join(pair[key].as_str().unwrap());
            let (source, target) = (file("source"), file("target"));
            for (variant, options, network) in VARIANTS {
                if network && position % NETWORK_STRIDE != 0 {
                    continue;
                }
                let mut args = vec![
                    "register",
                    source.to_str().unwrap(),
                    target.to_str().unwrap(),
                    "--json",
                ];
                args.extend_from_slice(options);
                let value: serde_json::Value = serde_json::from_str(&rgm(&args)).unwrap();
                let key = format!("{setting}/{}/{variant}", pair["index"]);
                pinned.insert(key, entry(&value));
            }
        }
    }
    pinned
}

/// The pinned parts of `rgm register --json`'s output, or of a golden file's entry.
fn entry(value: &serde_json::Value) -> Entry {
    Entry {
        method: value["method"].as_str().expect("a method").to_string(),
        registered: value["registered"]
            .as_bool()
            .expect("registered: true or false"),
        transform: transform(&value["transform"]),
    }
}

fn transform(rows: &serde_json::Value) -> [[f64; 4]; 4] {
    let mut m = [[0.0; 4]; 4];
    for (r, row) in m.iter_mut().enumerate() {
        for (c, x) in row.iter_mut().enumerate() {
            *x = rows[r][c].as_f64().expect("a number");
        }
    }
    m
}

fn read_golden(path: &Path) -> Pinned {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| {
        panic!(
            "{}: {e}; scripts/regen-behaviour-pin.sh makes it",
            path.display()
        )
    });
    let value: serde_json::Value = serde_json::from_str(&text).unwrap();
    value["registrations"]
        .as_object()
        .expect("a \"registrations\" object")
        .iter()
        .map(|(key, value)| (key.clone(), entry(value)))
        .collect()
}

fn write_golden(path: &Path, pinned: &Pinned) {
    let commit = Command::new("git")
        .args(["rev-parse", "--short", "HEAD"])
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map_or_else(|| "unknown".to_string(), |s| s.trim().to_string());
    // One registration per line, so that a regeneration's diff names the registrations it moved.
    let lines: Vec<String> = pinned
        .iter()
        .map(|(key, found)| {
            let entry = serde_json::json!({
                "method": found.method,
                "registered": found.registered,
                "transform": found.transform,
            });
            format!("    {}: {entry}", serde_json::Value::from(key.as_str()))
        })
        .collect();
    let about = "rgm register --json transforms, and whether each is trusted, on ModelNet40 test \
                 pairs (setting/index/variant); \
                 crates/rgm-cli/tests/behaviour_pin.rs checks them, \
                 scripts/regen-behaviour-pin.sh regenerates them";
    let text = format!(
        "{{\n  \"about\": {},\n  \"commit\": {},\n  \"registrations\": {{\n{}\n  }}\n}}\n",
        serde_json::Value::from(about),
        serde_json::Value::from(commit),
        lines.join(",\n")
    );
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

/// Every difference between `found` and `golden`, one line each: a method name, a
/// `registered`, or a transform entry further than [`TOLERANCE`] apart, or a registration only
/// one of them has.
fn differences(found: &Pinned, golden: &Pinned) -> Vec<String> {
    let mut out = Vec::new();
    for (key, found) in found {
        let Some(pinned) = golden.get(key) else {
            out.push(format!("{key}: not in the golden file"));
            continue;
        };
        let (method, want_method) = (&found.method, &pinned.method);
        if method != want_method {
            out.push(format!("{key}: method {method}, pinned {want_method}"));
        }
        if found.registered != pinned.registered {
            let (registered, want) = (found.registered, pinned.registered);
            out.push(format!("{key}: registered {registered}, pinned {want}"));
        }
        let (t, want) = (&found.transform, &pinned.transform);
        let worst = (0..16)
            .map(|k| (t[k / 4][k % 4] - want[k / 4][k % 4]).abs())
            .fold(0.0, f64::max);
        if worst.is_nan() || worst > TOLERANCE {
            out.push(format!(
                "{key}: transform differs by {worst:e}\n  found  {t:?}\n  pinned {want:?}"
            ));
        }
    }
    for key in golden.keys().filter(|k| !found.contains_key(*k)) {
        out.push(format!("{key}: pinned but not run"));
    }
    out
}

#[test]
fn register_transforms_match_the_pinned_values() {
    let data = data_dir();
    if !data.is_dir() {
        println!(
            "SKIPPED behaviour pin: no ModelNet40 data at {} (set RGM_DATA)",
            data.display()
        );
        return;
    }
    let found = register_all(&data, &rgm_tests::Scratch::new("behaviour-pin"));
    if std::env::var_os("RGM_PIN_BLESS").is_some() {
        write_golden(&golden_path(), &found);
        println!(
            "wrote {} registrations to {}",
            found.len(),
            golden_path().display()
        );
        return;
    }
    let diffs = differences(&found, &read_golden(&golden_path()));
    assert!(
        diffs.is_empty(),
        "{} of {} registrations differ from {}:\n{}",
        diffs.len(),
        found.len(),
        golden_path().display(),
        diffs.join("\n")
    );
}

#[test]
fn a_changed_value_fails_the_pin() {
    let t = [
        [1.0, 0.0, 0.0, 0.1],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let pinned = |method: &str, registered, transform| {
        let entry = Entry {
            method: method.to_string(),
            registered,
            transform,
        };
        Pinned::from([("partial/0/rgm".to_string(), entry)])
    };
    let golden = pinned("rgm", true, t);
    assert!(differences(&golden, &golden).is_empty());
    let mut moved = t;
    moved[0][3] += 2e-9;
    assert_eq!(differences(&pinned("rgm", true, moved), &golden).len(), 1);
    moved[0][3] = t[0][3] + 5e-10;
    assert!(differences(&pinned("rgm", true, moved), &golden).is_empty());
    assert_eq!(
        differences(&pinned("rgm+refine", true, t), &golden).len(),
        1
    );
    assert_eq!(
        differences(&pinned("rgm", false, t), &golden),
        ["partial/0/rgm: registered false, pinned true"]
    );
    assert_eq!(
        differences(&Pinned::new(), &golden),
        ["partial/0/rgm: pinned but not run"]
    );
}
