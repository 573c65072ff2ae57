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
        names(TestSet::ALL[0], &["fgr+refine", "icp"]),
        ["icp", "fgr+refine"]
    );
    assert!(names(TestSet::ALL[2], &["fgr+refine"]).is_empty());
    assert_eq!(names(TestSet::ALL[2], &[]), ["icp", "fgr"]);
    assert!(check_only(&manifest, &["icp".into(), "fgr+refine".into()]).is_ok());
    let err = check_only(&manifest, &["icp".into(), "var9".into()]).unwrap_err();
    assert!(
        err.to_string().starts_with("--only var9: no such row"),
        "{err}"
    );
}

#[test]
fn only_reads_a_row_name_of_before_issue_58_as_today_s() {
    #[derive(clap::Parser)]
    struct Command {
        #[command(flatten)]
        args: Args,
    }
    let parsed = <Command as clap::Parser>::try_parse_from([
        "reproduce-tables",
        "--only",
        "icp,fgr+icp,auto+refine,partial-fast",
    ])
    .unwrap();
    assert_eq!(
        parsed.args.only,
        ["icp", "fgr+refine", "auto+refine", "partial-fast"]
    );
    let manifest: Manifest = serde_json::from_value(serde_json::json!({"models": []})).unwrap();
    assert!(check_only(&manifest, &parsed.args.only[..3]).is_ok());
}

#[test]
fn a_refined_row_s_stem_of_before_issue_58_is_the_same_with_icp() {
    assert_eq!(older_stem("fgr-refine").as_deref(), Some("fgr-icp"));
    assert_eq!(
        older_stem("auto-partial-fast-755305pairs-refine").as_deref(),
        Some("auto-partial-fast-755305pairs-icp")
    );
    assert_eq!(older_stem("partial-fast-755305pairs"), None);
    assert_eq!(older_stem("icp"), None);
}

#[test]
fn fgr_refined_is_a_row_of_the_partial_tables_only() {
    let manifest: Manifest = serde_json::from_value(serde_json::json!({"models": []})).unwrap();
    let names = |set: TestSet| {
        let list = candidates(set, &manifest, &[]).unwrap();
        list.iter()
            .map(|c| (c.name.clone(), c.method.name()))
            .map(|(a, b)| format!("{a}={b}"))
            .collect::<Vec<_>>()
    };
    let partial = names(TestSet::ALL[0]);
    assert_eq!(partial.last().unwrap(), "fgr+refine=fgr+refine");
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
        let default = list.iter().find(|c| c.name == "auto+refine").unwrap();
        assert_eq!(default.method.name(), "auto+refine", "{}", set.key());
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
    // A refined row's file under its name of before issue 58, read back under today's.
    let old = root.join("docs/results/clean/fgr-icp.jsonl.gz");
    fs::write(&old, "refined").unwrap();
    git(&["add", "docs"]);
    git(&["commit", "-q", "-m", "a refined row"]);
    let renamed = git(&["rev-parse", "--short", "HEAD"]);
    git(&["rm", "-q", "-r", "docs"]);
    git(&["commit", "-q", "-m", "records out of the tree again"]);
    let new = root.join("docs/results/clean/fgr-refine.jsonl.gz");
    assert_eq!(restore_from_history(&root, &new).unwrap(), None);
    let restored = restore_renamed_from_history(&root, &old, &new).unwrap();
    assert_eq!(restored.as_deref(), Some(renamed.as_str()));
    assert_eq!(fs::read_to_string(&new).unwrap(), "refined");
    assert!(!old.exists());
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
        "icp,fgr+refine",
    ]
    .map(String::from);
    assert_eq!(
        command_line(args.into_iter()),
        "cargo xtask reproduce-tables --only icp,fgr+refine"
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
