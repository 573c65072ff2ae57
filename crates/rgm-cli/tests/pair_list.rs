//! `rgm register --pairs LIST`: the lines of one-by-one `rgm register --json` calls, a failed
//! pair as a line, errors in LIST naming the file, the line and the value, and a resumable
//! `--output` that never holds a pair twice, is rgm's by its header, records the settings and
//! is written by one run at a time.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use rgm_tests::Scratch;

fn rgm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(args)
        .output()
        .expect("the rgm binary runs")
}

/// The arguments `register --pairs LIST OPTIONS… --output OUTPUT`.
fn list_args<'a>(list: &'a Path, options: &[&'a str], output: &'a Path) -> Vec<&'a str> {
    let mut args = vec!["register", "--pairs", list.to_str().unwrap()];
    args.extend_from_slice(options);
    args.extend_from_slice(&["--output", output.to_str().unwrap()]);
    args
}

/// `rgm register --pairs LIST OPTIONS… --output OUTPUT`.
fn register_list(list: &Path, options: &[&str], output: &Path) -> Output {
    rgm(&list_args(list, options, output))
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The first `count` partial test pairs written by `rgm pairs` into `dir/pairs`; their
/// `pairs.json` is a LIST.
fn written_pairs(dir: &Path, count: usize) -> PathBuf {
    let data =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/modelnet40_npy1024");
    let out = dir.join("pairs");
    let written = rgm(&[
        "pairs",
        "--data",
        data.to_str().unwrap(),
        "--limit",
        &count.to_string(),
        // Full clouds: FGR registers each (ICP from the identity slides into a wrong pose on
        // some, and on a partial pair it may find no overlap: those pairs are rightly not
        // registered).
        "--setting",
        "clean",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(written.status.success(), "{}", stderr(&written));
    out.join("pairs.json")
}

/// The JSON lines of `file` after its header, each checked to be one complete object.
fn lines(file: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(file).unwrap();
    assert!(text.ends_with('\n'), "a cut-off line in {text}");
    let mut lines = text
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).expect("a JSON line"));
    assert_eq!(
        lines.next().unwrap()["rgm_many_pairs"],
        1,
        "no header in {text}"
    );
    lines.collect()
}

/// `lines` by their pair, each pair once.
fn by_pair(lines: &[serde_json::Value]) -> HashMap<(String, String), serde_json::Value> {
    let mut pairs = HashMap::new();
    for line in lines {
        let key = (
            line["source"].as_str().unwrap().to_string(),
            line["target"].as_str().unwrap().to_string(),
        );
        assert!(pairs.insert(key, line.clone()).is_none(), "twice: {line}");
    }
    pairs
}

#[test]
fn every_line_is_what_rgm_register_json_prints_for_its_pair() {
    let dir = Scratch::new("pair-list-same");
    let list = written_pairs(&dir, 3);
    let output = dir.join("out.jsonl");
    let out = register_list(&list, &[], &output);
    assert!(out.status.success(), "{}", stderr(&out));
    let found = lines(&output);
    assert_eq!(found.len(), 3);
    for mut line in found {
        let (source, target) = (
            line["source"].as_str().unwrap().to_string(),
            line["target"].as_str().unwrap().to_string(),
        );
        let folder = list.parent().unwrap();
        let one = rgm(&[
            "register",
            folder.join(&source).to_str().unwrap(),
            folder.join(&target).to_str().unwrap(),
            "--json",
        ]);
        let mut alone: serde_json::Value =
            serde_json::from_slice(&one.stdout).expect("rgm register --json prints an object");
        assert_eq!(alone["method"], "auto+refine");
        // The method's own time (and each candidate's) differs from run to run; everything else
        // is the same.
        for value in [&mut line, &mut alone] {
            let object = value.as_object_mut().unwrap();
            assert!(object.remove("time_ms").unwrap().as_f64().unwrap() > 0.0);
            for candidate in object["candidates"].as_array_mut().unwrap() {
                let candidate = candidate.as_object_mut().unwrap();
                assert!(candidate.remove("time_ms").unwrap().as_f64().unwrap() > 0.0);
            }
        }
        let object = line.as_object_mut().unwrap();
        assert_eq!(object.remove("source").unwrap(), source.as_str());
        assert_eq!(object.remove("target").unwrap(), target.as_str());
        // The files the line stands for (what a resume checks), resolved.
        let inputs = object.remove("inputs").unwrap();
        let resolved = std::fs::canonicalize(folder.join(&source)).unwrap();
        assert_eq!(inputs["source"]["path"], resolved.to_str().unwrap());
        assert_eq!(line, alone, "{source} → {target}");
    }
}

#[test]
fn a_rerun_registers_only_the_pairs_without_a_line_and_never_writes_one_twice() {
    let dir = Scratch::new("pair-list-resume");
    let list = written_pairs(&dir, 6);
    let output = dir.join("out.jsonl");
    let run = || register_list(&list, &["--method", "fgr", "--no-refine"], &output);
    let first = run();
    assert!(first.status.success(), "{}", stderr(&first));
    let text = std::fs::read_to_string(&output).unwrap();
    let whole = by_pair(&lines(&output));
    assert_eq!(whole.len(), 6);
    // Line 2 removed and the last line cut in the middle, as a killed run leaves it, and the
    // first line written twice.
    let (header, kept) = text.split_once('\n').unwrap();
    let kept: Vec<&str> = kept.lines().collect();
    let cut = &kept[5][..kept[5].len() / 2];
    let damaged = format!(
        "{header}\n{}\n{}\n{}\n{}\n{}\n{cut}",
        kept[0], kept[2], kept[3], kept[0], kept[4]
    );
    std::fs::write(&output, damaged).unwrap();
    let rerun = run();
    assert!(rerun.status.success(), "{}", stderr(&rerun));
    assert!(
        stderr(&rerun).contains("4 of the 6 pairs have their line in"),
        "{}",
        stderr(&rerun)
    );
    let again = by_pair(&lines(&output));
    assert_eq!(again.len(), 6);
    // The kept lines are the first run's (a pair registered again would have another
    // time_ms); the two redone pairs have the first run's transforms.
    for k in [0, 2, 3, 4] {
        let line: serde_json::Value = serde_json::from_str(kept[k]).unwrap();
        let key = (
            line["source"].as_str().unwrap().to_string(),
            line["target"].as_str().unwrap().to_string(),
        );
        assert_eq!(again[&key], line);
    }
    for (key, line) in &whole {
        assert_eq!(again[key]["transform"], line["transform"]);
    }
    // Finished: a third run registers nothing and changes nothing.
    let before = std::fs::read_to_string(&output).unwrap();
    let third = run();
    assert!(third.status.success(), "{}", stderr(&third));
    assert!(
        stderr(&third).contains("registering 0"),
        "{}",
        stderr(&third)
    );
    assert_eq!(std::fs::read_to_string(&output).unwrap(), before);
}

#[test]
fn an_output_of_before_issue_58_resumes_with_today_s_header() {
    let dir = Scratch::new("pair-list-issue58");
    let list = written_pairs(&dir, 2);
    let output = dir.join("out.jsonl");
    let run = || register_list(&list, &["--method", "fgr"], &output);
    let first = run();
    assert!(first.status.success(), "{}", stderr(&first));
    let text = std::fs::read_to_string(&output).unwrap();
    let (header, rest) = text.split_once('\n').unwrap();
    assert!(header.contains(r#""method":"fgr+refine""#), "{header}");
    // The file as an rgm of before issue 58 wrote it: `rgm_batch`, the method `fgr+icp`.
    let old = header
        .replace("rgm_many_pairs", "rgm_batch")
        .replace("fgr+refine", "fgr+icp");
    let old_lines = rest.replace("fgr+refine", "fgr+icp");
    std::fs::write(&output, format!("{old}\n{old_lines}")).unwrap();
    let rerun = run();
    assert!(rerun.status.success(), "{}", stderr(&rerun));
    assert!(
        stderr(&rerun).contains("2 of the 2 pairs have their line in"),
        "{}",
        stderr(&rerun)
    );
    assert!(
        stderr(&rerun).contains("registering 0"),
        "{}",
        stderr(&rerun)
    );
    // Today's header, the lines as they were.
    assert_eq!(
        std::fs::read_to_string(&output).unwrap(),
        format!("{header}\n{old_lines}")
    );
}

#[test]
fn a_killed_run_finishes_on_a_rerun_without_redoing_its_pairs() {
    let dir = Scratch::new("pair-list-killed");
    let list = written_pairs(&dir, 8);
    let output = dir.join("out.jsonl");
    let args = list_args(&list, &["--method", "fgr", "--workers", "1"], &output);
    let mut child = Command::new(env!("CARGO_BIN_EXE_rgm"))
        .args(&args)
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Killed once its first line after the header is written (or left alone, should it
    // finish first).
    while std::fs::read_to_string(&output).map_or(0, |t| t.lines().count()) < 2 {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let _ = child.kill();
    child.wait().unwrap();
    let text = std::fs::read_to_string(&output).unwrap();
    let finished: Vec<serde_json::Value> = text
        .split_inclusive('\n')
        .skip(1)
        .filter(|l| l.ends_with('\n'))
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(!finished.is_empty());
    let rerun = rgm(&args);
    assert!(rerun.status.success(), "{}", stderr(&rerun));
    let all = by_pair(&lines(&output));
    assert_eq!(all.len(), 8);
    for line in &finished {
        let key = (
            line["source"].as_str().unwrap().to_string(),
            line["target"].as_str().unwrap().to_string(),
        );
        assert_eq!(&all[&key], line, "a finished pair registered again");
    }
}

#[test]
fn a_pair_that_fails_is_a_line_naming_why_and_the_status_says_so() {
    let dir = Scratch::new("pair-list-fails");
    let list = written_pairs(&dir, 2);
    let csv = dir.join("list.csv");
    std::fs::write(
        &csv,
        "# a comment, then the header\nid,target,source\n\
         1,pairs/0000_target.ply,\"pairs/0000_source.ply\"\n\
         2,pairs/0000_target.ply,pairs/missing.ply\n\
         3,pairs/0000_target.ply,pairs/0000_source.ply\n",
    )
    .unwrap();
    assert!(list.is_file());
    let out = rgm(&[
        "register",
        "--pairs",
        csv.to_str().unwrap(),
        "--method",
        "icp",
    ]);
    assert!(!out.status.success());
    let text = String::from_utf8(out.stdout.clone()).unwrap();
    let printed: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // The repeated pair runs once.
    assert_eq!(printed.len(), 2, "{text}");
    let failed = printed
        .iter()
        .find(|l| l["source"] == "pairs/missing.ply")
        .expect("a line for the missing file");
    let why = failed["error"].as_str().unwrap();
    assert!(
        why.contains(&format!("{}", dir.join("pairs/missing.ply").display())),
        "{why}"
    );
    assert!(printed.iter().any(|l| l["registered"] == true));
    let said = stderr(&out);
    assert!(said.contains("list.csv:5 repeats the pair of"), "{said}");
    assert!(
        said.contains("2 pairs: 1 registered, 0 not registered, 1 failed"),
        "{said}"
    );
}

#[test]
fn errors_in_the_list_name_the_file_the_line_and_the_value() {
    let dir = Scratch::new("pair-list-list");
    let cases = [
        (
            "header.csv",
            "src,tgt\na.ply,b.ply\n",
            "header.csv:1: the header must name the columns `source` and `target`: `src,tgt`",
        ),
        (
            "row.csv",
            "source,target\na.ply,b.ply\n\nc.ply\n",
            "row.csv:4: no target file (column 2): `c.ply`",
        ),
        (
            "quote.csv",
            "source,target\n\"a.ply,b.ply\n",
            "quote.csv:2: a quoted field has no closing quote: `\"a.ply,b.ply`",
        ),
        ("empty.csv", "source,target\n", "empty.csv: no pair listed"),
        (
            "entry.json",
            r#"[{"source": "a.ply", "target": "b.ply"}, {"source": "c.ply"}]"#,
            r#"entry.json entry 2: no "target" file name: `{"source":"c.ply"}`"#,
        ),
        (
            "shape.json",
            r#"{"sources": []}"#,
            r#"shape.json: a JSON list of pairs is a list of {"source": FILE, "target": FILE}"#,
        ),
        (
            "broken.json",
            "[{\"source\": \"a.ply\",\n \"target\" 3}]",
            "broken.json: not valid JSON: expected `:` at line 2 column 11",
        ),
    ];
    for (name, text, says) in cases {
        let list = dir.join(name);
        std::fs::write(&list, text).unwrap();
        let out = rgm(&[
            "register",
            "--pairs",
            list.to_str().unwrap(),
            "--method",
            "icp",
        ]);
        assert!(!out.status.success());
        assert!(out.stdout.is_empty(), "{name}");
        let said = stderr(&out);
        assert!(said.contains(says), "{name}: {said}");
    }
    // An --output that is not ours is refused and left as it was, one line or more, with a
    // newline or without (the list itself, notes, a JSON config).
    let list = dir.join("header.csv");
    std::fs::write(&list, "source,target\na.ply,b.ply\n").unwrap();
    for text in [
        "not json\n",
        "some notes",
        r#"{"source": "a.ply", "target": "b.ply", "method": "icp"}"#,
        "{\"config\": 1}\n{\"source\": \"a.ply\", \"target\": \"b.ply\"}\n",
    ] {
        let output = dir.join("other.jsonl");
        std::fs::write(&output, text).unwrap();
        let out = register_list(&list, &["--method", "icp"], &output);
        assert!(!out.status.success());
        assert!(
            stderr(&out).contains("other.jsonl:1: not an output of rgm's pair lists"),
            "{}",
            stderr(&out)
        );
        assert_eq!(std::fs::read_to_string(&output).unwrap(), text);
    }
    let out = register_list(&list, &[], &list);
    assert!(stderr(&out).contains("header.csv:1: not an output of rgm's pair lists"));
    assert_eq!(
        std::fs::read_to_string(&list).unwrap(),
        "source,target\na.ply,b.ply\n"
    );
    // One pair and a list are one or the other.
    let out = rgm(&[
        "register",
        "a.ply",
        "b.ply",
        "--pairs",
        list.to_str().unwrap(),
    ]);
    assert!(!out.status.success() && stderr(&out).contains("cannot be used with"));
    let out = rgm(&["register", "a.ply", "b.ply", "--workers", "2"]);
    assert!(!out.status.success() && stderr(&out).contains("--workers applies to --pairs"));
}

#[test]
fn a_second_run_on_a_locked_output_is_refused_and_changes_nothing() {
    let dir = Scratch::new("pair-list-locked");
    let list = written_pairs(&dir, 2);
    let output = dir.join("out.jsonl");
    let args = list_args(&list, &["--method", "fgr", "--no-refine"], &output);
    let first = rgm(&args);
    assert!(first.status.success(), "{}", stderr(&first));
    let before = std::fs::read_to_string(&output).unwrap();
    // Another run holds the file: its lock, as a running `rgm register --pairs` holds it.
    let holder = std::fs::File::open(&output).unwrap();
    holder.lock().unwrap();
    let second = rgm(&args);
    assert!(!second.status.success());
    assert!(
        stderr(&second).contains("out.jsonl: another run is writing this file"),
        "{}",
        stderr(&second)
    );
    assert_eq!(std::fs::read_to_string(&output).unwrap(), before);
    holder.unlock().unwrap();
    let third = rgm(&args);
    assert!(third.status.success(), "{}", stderr(&third));
    assert!(
        stderr(&third).contains("registering 0"),
        "{}",
        stderr(&third)
    );
}

#[test]
fn a_resume_with_other_settings_is_refused_naming_the_setting() {
    let dir = Scratch::new("pair-list-settings");
    let list = written_pairs(&dir, 1);
    let output = dir.join("out.jsonl");
    let weights = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../rgm-model/tests/fixtures/rgm_tiny_state_dict.safetensors");
    let run = |more: &[&str]| {
        let mut options = vec!["--method", "rgm", "--no-refine"];
        options.extend_from_slice(more);
        register_list(&list, &options, &output)
    };
    let first = run(&["--match-points", "64", "--passes", "1"]);
    // The header is this test's subject, not the pair's verdict: 64 points unrefined may be
    // doubted (unrefined results are checked since issue 59), and the line is written either way.
    assert!(
        first.status.success() || stderr(&first).contains("1 were not registered"),
        "{}",
        stderr(&first)
    );
    let header: serde_json::Value = serde_json::from_str(
        std::fs::read_to_string(&output)
            .unwrap()
            .lines()
            .next()
            .unwrap(),
    )
    .unwrap();
    assert_eq!(header["settings"]["method"], "rgm");
    assert_eq!(header["settings"]["passes"], 1);
    assert_eq!(header["settings"]["match_points"], 64);
    assert!(
        header["settings"]["weights"]
            .as_str()
            .unwrap()
            .starts_with("built-in partial-fast, CRC-32 "),
        "{header}"
    );
    let before = std::fs::read_to_string(&output).unwrap();
    for (more, says) in [
        (
            vec!["--match-points", "64", "--passes", "2"],
            "made with passes 1, this run asks for passes 2",
        ),
        (
            vec!["--match-points", "128", "--passes", "1"],
            "made with match_points 64, this run asks for match_points 128",
        ),
        (
            vec![
                "--match-points",
                "64",
                "--passes",
                "1",
                "--weights",
                weights.to_str().unwrap(),
                "--preset",
                "tiny",
            ],
            "this run asks for preset \"tiny\"",
        ),
    ] {
        let out = run(&more);
        assert!(!out.status.success(), "{more:?}");
        assert!(stderr(&out).contains(says), "{more:?}: {}", stderr(&out));
        assert!(stderr(&out).contains("give another output file"));
        assert_eq!(std::fs::read_to_string(&output).unwrap(), before);
    }
}
