use super::*;

#[test]
fn each_test_set_gets_the_models_trained_for_it() {
    let entry = |name: &str, setting: &str, unseen: bool, variant: &str| {
        serde_json::json!({"name": name, "setting": setting, "unseen": unseen,
            "variant": variant, "preset": "tiny", "match_points": null, "file": "x",
            "builtin": false, "trained_with": "rgm train", "epochs": 1.0, "pairs_seen": 8})
    };
    let manifest: Manifest = serde_json::from_value(serde_json::json!({"models": [
        entry("a", "partial", false, "rgm"),
        entry("b", "partial", true, "rgm"),
        entry("c", "partial", false, "var1"),
        entry("d", "clean", false, "var2"),
    ]}))
    .unwrap();
    let names = |set: TestSet| {
        models_for(&manifest, set)
            .map(|m| format!("{}:{}", m.name, m.variant.name()))
            .collect::<Vec<_>>()
    };
    assert_eq!(names(TestSet::ALL[0]), ["a:rgm", "c:var1"]);
    assert_eq!(names(TestSet::ALL[1]), ["b:rgm"]);
    assert_eq!(names(TestSet::ALL[2]), ["d:var2"]);
    assert!(names(TestSet::ALL[3]).is_empty());
}

#[test]
fn only_keeps_the_named_rows_and_refuses_unknown_names() {
    let manifest: Manifest = serde_json::from_value(serde_json::json!({"models": []})).unwrap();
    let names = |set: TestSet, only: &[&str]| {
        let only: Vec<String> = only.iter().map(|s| s.to_string()).collect();
        candidates(set, &manifest, &only)
            .unwrap()
            .into_iter()
            .map(|c| c.name)
            .collect::<Vec<_>>()
    };
    assert_eq!(
        names(TestSet::ALL[0], &["fgr+icp", "icp"]),
        ["icp", "fgr+icp"]
    );
    assert!(names(TestSet::ALL[2], &["fgr+icp"]).is_empty());
    assert_eq!(names(TestSet::ALL[2], &[]), ["icp", "fgr"]);
    assert!(check_only(&manifest, &["icp".into(), "fgr+icp".into()]).is_ok());
    let err = check_only(&manifest, &["icp".into(), "var9".into()]).unwrap_err();
    assert!(
        err.to_string().starts_with("--only var9: no such row"),
        "{err}"
    );
}

#[test]
fn fgr_refined_by_icp_is_a_row_of_the_partial_tables_only() {
    let manifest: Manifest = serde_json::from_value(serde_json::json!({"models": []})).unwrap();
    let names = |set: TestSet| {
        let list = candidates(set, &manifest, &[]).unwrap();
        list.iter()
            .map(|c| (c.name.clone(), c.method.name()))
            .map(|(a, b)| format!("{a}={b}"))
            .collect::<Vec<_>>()
    };
    let partial = names(TestSet::ALL[0]);
    assert_eq!(partial.last().unwrap(), "fgr+icp=fgr+icp");
    assert_eq!(names(TestSet::ALL[1]), partial);
    assert_eq!(names(TestSet::ALL[2]), ["icp=icp", "fgr=fgr"]);
}

#[test]
fn every_table_has_the_default_of_rgm_register() {
    // Only the default's row: the models of the manifest that earlier commits hold
    // (`git:REV:PATH`) are not read, so that a shallow clone passes too.
    let manifest = Manifest::builtin();
    for set in TestSet::ALL {
        let list = candidates(set, &manifest, &[default_row()]).unwrap();
        let default = list.iter().find(|c| c.name == "auto+icp").unwrap();
        assert_eq!(default.method.name(), "auto+icp", "{}", set.key());
        assert!(
            default.stem.starts_with("auto-partial-fast-"),
            "{}",
            default.stem
        );
    }
}

#[test]
fn a_missing_per_pair_file_is_read_back_from_the_last_commit_that_held_it() {
    let root = std::env::temp_dir().join(format!("rgm-tables-history-{}", std::process::id()));
    let _ = fs::remove_dir_all(&root);
    fs::create_dir_all(root.join("docs/results/clean")).unwrap();
    let git = |args: &[&str]| {
        let out = Command::new("git")
            .args(["-c", "user.name=t", "-c", "user.email=t@t"])
            .args(["-c", "commit.gpgsign=false"])
            .args(args)
            .current_dir(&root)
            .output()
            .unwrap();
        assert!(out.status.success(), "git {args:?}: {out:?}");
        String::from_utf8(out.stdout).unwrap().trim().to_string()
    };
    git(&["init", "-q"]);
    let file = root.join("docs/results/clean/icp.jsonl.gz");
    for content in ["first", "second"] {
        fs::write(&file, content).unwrap();
        git(&["add", "docs"]);
        git(&["commit", "-q", "-m", content]);
    }
    let holder = git(&["rev-parse", "--short", "HEAD"]);
    git(&["rm", "-q", "-r", "docs"]);
    git(&["commit", "-q", "-m", "records out of the tree"]);
    assert!(!root.join("docs").exists());
    let restored = restore_from_history(&root, &file).unwrap();
    assert_eq!(restored.as_deref(), Some(holder.as_str()));
    assert_eq!(fs::read_to_string(&file).unwrap(), "second");
    // A path no commit held, and one outside the repository: nothing is written.
    let other = root.join("docs/results/clean/fgr.jsonl.gz");
    assert_eq!(restore_from_history(&root, &other).unwrap(), None);
    assert!(!other.exists());
    let outside = root.with_extension("outside").join("icp.jsonl.gz");
    assert_eq!(restore_from_history(&root, &outside).unwrap(), None);
    assert!(!outside.exists());
    fs::remove_dir_all(root.with_extension("outside")).unwrap();
    fs::remove_dir_all(&root).unwrap();
}

#[test]
fn the_command_line_is_the_one_typed_quoted_where_a_shell_needs_it() {
    let args = [
        "target/debug/xtask",
        "reproduce-tables",
        "--only",
        "icp,fgr+icp",
    ]
    .map(String::from);
    assert_eq!(
        command_line(args.into_iter()),
        "cargo xtask reproduce-tables --only icp,fgr+icp"
    );
    let args = [
        "xtask",
        "reproduce-tables",
        "--out",
        "my results",
        "--commit",
        "it's",
    ]
    .map(String::from);
    assert_eq!(
        command_line(args.into_iter()),
        r"cargo xtask reproduce-tables --out 'my results' --commit 'it'\''s'"
    );
}
