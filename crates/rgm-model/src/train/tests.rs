//! The module's tests. Training on a small hand-made dataset: resuming is exact (also after a
//! kill at any file operation, injected through [`super::run_dir::Faults`]), runs refuse other
//! settings, and the loss goes down; and the records of validations.

use std::collections::BTreeMap;
use std::fs;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rgm_data::{Correspondence, ModelNet40, Pair, Shape};
use rgm_geom::euler::rotation_xyz_intrinsic;
use rgm_geom::{Point3, PointCloud, RigidTransform, Vector3};

use super::validation::refined_recall;
use super::*;
use crate::network::{Config, TestStatistics};

#[test]
fn validations_logged_before_the_refinement_changed_read_as_point_to_point_icp() {
    // Epoch 9 of runs/partial-fast, as its log holds it.
    let old = r#"{"epoch":8,"pairs":300,"loss":2.48,"match_accuracy":0.25,"mie_r_deg":8.9,"mie_t":0.11,"mae_r_deg":4.5,"mae_t":0.05,"recall":0.23,"recall_refined":0.6,"failures":0}"#;
    let old: Validation = serde_json::from_str(old).unwrap();
    assert_eq!(old.refined_with, Refinement::PointToPointIcp);
    let new = Validation {
        refined_with: Refinement::TrimmedPointToPlane,
        ..old
    };
    let line = serde_json::to_string(&new).unwrap();
    assert!(
        line.contains(r#""refined_with":"trimmed_point_to_plane""#),
        "{line}"
    );
    assert_eq!(serde_json::from_str::<Validation>(&line).unwrap(), new);
}

#[test]
fn recall_after_refinement_compares_only_like_refinements() {
    let before = r#"{"epoch":16,"pairs":300,"loss":2.25,"match_accuracy":0.3,"mie_r_deg":5.7,"mie_t":0.06,"mae_r_deg":3.1,"mae_t":0.03,"recall":0.41,"recall_refined":0.92,"refined_with":"trimmed_point_to_plane","failures":0}"#;
    let before: Validation = serde_json::from_str(before).unwrap();
    // Refined more sharply, worse alone: not better.
    let sharper = Validation {
        refined_with: Refinement::PlaneThenPoint,
        recall_refined: 0.96,
        recall: 0.40,
        ..before
    };
    assert!(!sharper.beats(&before, BestBy::Refined) && before.beats(&sharper, BestBy::Refined));
    // Alike, the refined recall decides.
    let alike = Validation {
        refined_with: Refinement::TrimmedPointToPlane,
        ..sharper
    };
    assert!(alike.beats(&before, BestBy::Refined));
}

#[test]
fn the_best_by_the_network_alone_ignores_the_refined_recall() {
    let before = r#"{"epoch":3,"pairs":300,"loss":2.157,"match_accuracy":0.41,"mie_r_deg":3.0,"mie_t":0.03,"mae_r_deg":1.5,"mae_t":0.02,"recall":0.643,"recall_refined":0.913,"refined_with":"plane_then_point","failures":0,"sample":"spread"}"#;
    let before: Validation = serde_json::from_str(before).unwrap();
    // unseen-long-drop's epochs 2 and 4 (Table 4 took the later one): better alone, one pair
    // fewer refined.
    let later = Validation {
        epoch: 4,
        recall: 0.65,
        recall_refined: 0.91,
        ..before
    };
    assert!(before.beats(&later, BestBy::Refined) && !later.beats(&before, BestBy::Refined));
    assert!(later.beats(&before, BestBy::Alone) && !before.beats(&later, BestBy::Alone));
    // Equal alone: the lower loss, whatever the refined recall.
    let lower = Validation {
        loss: 2.15,
        recall_refined: 0.5,
        ..later
    };
    assert!(lower.beats(&later, BestBy::Alone) && !later.beats(&lower, BestBy::Alone));
}

#[test]
fn a_validation_on_another_sample_beats_the_best_whatever_its_numbers() {
    // Epoch 25 of runs/partial-fast (first 300 shapes) and a worse one on the spread sample.
    let first = r#"{"epoch":24,"pairs":300,"loss":2.0,"match_accuracy":0.4,"mie_r_deg":3.0,"mie_t":0.03,"mae_r_deg":1.6,"mae_t":0.02,"recall":0.487,"recall_refined":0.983,"refined_with":"plane_then_point","failures":0}"#;
    let first: Validation = serde_json::from_str(first).unwrap();
    assert_eq!(first.sample, ValSample::First);
    let spread = Validation {
        epoch: 25,
        sample: ValSample::Spread,
        recall: 0.29,
        recall_refined: 0.89,
        ..first
    };
    assert!(spread.beats(&first, BestBy::Refined));
    // On the same sample the numbers decide again.
    let next = Validation {
        epoch: 26,
        recall: 0.28,
        ..spread
    };
    assert!(!next.beats(&spread, BestBy::Refined) && spread.beats(&next, BestBy::Refined));
    let line = serde_json::to_string(&spread).unwrap();
    assert!(line.contains(r#""sample":"spread""#), "{line}");
}

#[test]
fn the_spread_sample_takes_evenly_spaced_shapes_and_the_first_the_head() {
    let shapes: Vec<Shape> = (0..10)
        .map(|i| Shape {
            name: format!("shape_{i}"),
            label: i / 2,
            points: vec![[i as f32, 0.0, 0.0]],
        })
        .collect();
    let refs: Vec<&Shape> = shapes.iter().collect();
    let labels = |taken: Vec<&Shape>| taken.iter().map(|s| s.label).collect::<Vec<_>>();
    assert_eq!(labels(ValSample::Spread.take(&refs, 5)), [0, 1, 2, 3, 4]);
    assert_eq!(labels(ValSample::First.take(&refs, 5)), [0, 0, 1, 1, 2]);
    assert_eq!(
        ValSample::Spread
            .take(&refs, 3)
            .iter()
            .map(|s| s.name.as_str())
            .collect::<Vec<_>>(),
        ["shape_0", "shape_3", "shape_6"]
    );
    assert_eq!(ValSample::Spread.take(&refs, 50).len(), 10);
}

#[test]
fn refined_recall_is_the_refinement_from_the_given_transform() {
    // A pair of 300 points on a sphere of radius 0.8, the source the target turned by
    // 10° about z and moved: refining from the truth or from 2° off registers it, from 90°
    // off it cannot.
    let target = PointCloud::new(
        (0..300)
            .map(|i| {
                let (a, b) = (i as f64 * 2.399_963, (1.0 - 2.0 * (i as f64 + 0.5) / 300.0));
                let r = (1.0 - b * b).sqrt();
                Point3::new(0.8 * r * a.cos(), 0.8 * r * a.sin(), 0.6 * b)
            })
            .collect(),
    );
    let turn = |deg: f64| {
        RigidTransform::new(
            rotation_xyz_intrinsic(0.0, 0.0, deg.to_radians()),
            Vector3::new(0.1, -0.2, 0.05),
        )
    };
    let truth = turn(10.0);
    let source = target.transformed(&truth.inverse());
    let correspondence = Correspondence::rebuild(&target.points, &target.points);
    let pair = Pair {
        source,
        target,
        t_target_source: truth,
        correspondence,
        shape_index: 0,
        label: 0,
    };
    assert!(refined_recall(&pair, &truth).unwrap());
    assert!(refined_recall(&pair, &turn(12.0)).unwrap());
    assert!(!refined_recall(&pair, &turn(100.0)).unwrap());
}

/// Two categories of ten 64-point shapes: noisy spheres and noisy boxes (8 train + 2
/// validation shapes each).
fn dataset() -> ModelNet40 {
    let mut rng = StdRng::seed_from_u64(1);
    let mut shape = |label: usize, k: usize| {
        let points = (0..64)
            .map(|_| {
                let p: [f32; 3] = [rng.gen(), rng.gen(), rng.gen()];
                let p = p.map(|v| 2.0 * v - 1.0);
                let scale = if label == 0 {
                    0.9 / (p.iter().map(|v| v * v).sum::<f32>().sqrt() + 1e-3) // onto a sphere
                } else {
                    0.5 // a box
                };
                p.map(|v| v * scale)
            })
            .collect();
        Shape {
            name: format!("s{label}_{k}"),
            label,
            points,
        }
    };
    let official_train = (0..20).map(|k| shape(k % 2, k)).collect();
    ModelNet40 {
        categories: vec!["sphere".into(), "box".into()],
        official_train,
        official_test: Vec::new(),
    }
}

fn config() -> TrainConfig {
    TrainConfig {
        match_points: Some(32),
        epochs: 2,
        batch: 3,
        optimizer: OptimizerKind::Adam,
        lr: 3e-3,
        milestones: vec![1],
        checkpoint_every: 100,
        ..TrainConfig::paper(rgm_data::Setting::Partial, Config::tiny())
    }
}

fn run_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rgm-train-{name}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&dir);
    dir
}

/// Trains the run in `dir`, stopping after batch `stop_at` (epoch, batch) if given.
fn train(config: TrainConfig, dir: &Path, stop_at: Option<(usize, usize)>) -> Trainer {
    let mut trainer = Trainer::open(config, dir).unwrap();
    trainer
        .run(&dataset(), &mut |event| match event {
            Event::Batch { epoch, batch, .. } if Some((epoch, batch)) == stop_at => {
                ControlFlow::Break(())
            }
            _ => ControlFlow::Continue(()),
        })
        .unwrap();
    trainer
}

fn validations(dir: &Path) -> Vec<Validation> {
    fs::read_to_string(dir.join("log.jsonl"))
        .unwrap()
        .lines()
        .filter_map(|line| match serde_json::from_str(line).unwrap() {
            LogRecord::Validation { result, .. } => Some(result),
            LogRecord::Train { .. } => None,
        })
        .collect()
}

#[test]
fn an_interrupted_run_resumes_to_the_same_weights() {
    let straight = run_dir("straight");
    let whole = train(config(), &straight, None);
    assert_eq!(whole.state().epoch, 2);
    assert_eq!(whole.state().steps, 12); // 2 epochs × ⌈16 train shapes / 3⌉
    let broken = run_dir("broken");
    // Stopped inside epoch 0, then inside epoch 1, then run to the end.
    // Each trainer holds the folder until dropped.
    let first = train(config(), &broken, Some((0, 2))).state().clone();
    assert_eq!((first.epoch, first.batch), (0, 2));
    let second = train(config(), &broken, Some((1, 1))).state().clone();
    assert_eq!((second.epoch, second.batch), (1, 1));
    let done = train(config(), &broken, None);
    assert_eq!(done.state().steps, whole.state().steps);
    assert_eq!(done.state().pairs_seen, whole.state().pairs_seen);
    for file in [
        "last.safetensors",
        "last.optim.safetensors",
        "best.safetensors",
    ] {
        // Compared as tensors and metadata: the metadata's order in the file is a hash map's.
        let read = |dir: &Path| rgm_nn::io::read_tensors::<f32>(&dir.join(file)).unwrap();
        assert!(
            read(&straight) == read(&broken),
            "{file} differs after resuming"
        );
    }
    assert_eq!(validations(&straight), validations(&broken));
    assert_eq!(validations(&straight).len(), 2);
}

#[test]
fn a_run_refuses_other_settings_but_may_be_extended() {
    let dir = run_dir("settings");
    let one_epoch = TrainConfig {
        epochs: 1,
        val_shapes: Some(2),
        val_sample: ValSample::First,
        ..config()
    };
    train(one_epoch.clone(), &dir, None);
    let other = TrainConfig {
        lr: 1e-2,
        ..one_epoch.clone()
    };
    let err = Trainer::open(other, &dir)
        .err()
        .expect("other settings refused");
    assert!(matches!(err, TrainError::Config { .. }), "{err}");
    assert!(err.to_string().contains("other settings"), "{err}");
    // Extended, and validated on another sample (of the 4 validation shapes, 0 and 2 instead
    // of 0 and 1): its first validation there becomes the best whatever its numbers.
    // The figure that picks the best may change too.
    let longer = train(
        TrainConfig {
            val_shapes: Some(2),
            best_by: BestBy::Alone,
            ..config()
        },
        &dir,
        None,
    );
    assert_eq!(longer.state().epoch, 2);
    let samples: Vec<ValSample> = validations(&dir).iter().map(|v| v.sample).collect();
    assert_eq!(samples, [ValSample::First, ValSample::Spread]);
    assert_eq!(longer.state().best.map(|b| b.epoch), Some(1));
    let bad = TrainConfig {
        match_points: Some(4),
        ..config()
    };
    assert!(
        Trainer::open(bad, &run_dir("bad")).is_err(),
        "K + 1 points at least"
    );
}

#[test]
fn a_run_started_from_weights_starts_where_they_ended() {
    // Each cloud's own batch-norm statistics at validation: training updates the running ones
    // whatever the learning rate, so only these show the weights alone.
    let one_epoch = TrainConfig {
        epochs: 1,
        test_statistics: TestStatistics::Cloud,
        ..config()
    };
    let source = run_dir("init-source");
    train(one_epoch.clone(), &source, None);
    // Fine-tuning at a learning rate too small to move the weights: its first validation is
    // the source's, and a run from the seeded initialisation validates far worse.
    let still = TrainConfig {
        lr: 1e-12,
        init: Some(source.join("last.safetensors")),
        ..one_epoch.clone()
    };
    let tuned = run_dir("init-tuned");
    train(still.clone(), &tuned, None);
    let scratch = run_dir("init-scratch");
    train(
        TrainConfig {
            init: None,
            ..still.clone()
        },
        &scratch,
        None,
    );
    let (source_val, tuned_val, scratch_val) = (
        validations(&source)[0],
        validations(&tuned)[0],
        validations(&scratch)[0],
    );
    assert!(
        (tuned_val.loss - source_val.loss).abs() < 1e-4 * source_val.loss,
        "{source_val:?} vs {tuned_val:?}"
    );
    assert!(
        (scratch_val.loss - source_val.loss).abs() > 1e-2 * source_val.loss,
        "{source_val:?} vs {scratch_val:?}"
    );
    let missing = TrainConfig {
        init: Some(source.join("no-such.safetensors")),
        ..one_epoch
    };
    let err = Trainer::open(missing, &run_dir("init-missing"))
        .err()
        .expect("missing weights refused");
    assert!(err.to_string().contains("no-such.safetensors"), "{err}");
}

#[test]
fn a_finished_run_without_its_optimiser_state_goes_on_with_a_fresh_one() {
    let dir = run_dir("no-optim");
    let one_epoch = TrainConfig {
        epochs: 1,
        ..config()
    };
    train(one_epoch, &dir, None);
    fs::remove_file(dir.join("last.optim.safetensors")).unwrap();
    let longer = train(config(), &dir, None);
    assert_eq!(longer.state().epoch, 2);
    assert_eq!(validations(&dir).len(), 2);
    assert!(dir.join("last.optim.safetensors").exists());
}

#[test]
fn training_lowers_the_validation_loss() {
    let dir = run_dir("learn");
    let trainer = train(
        TrainConfig {
            epochs: 8,
            lr: 1e-2,
            milestones: vec![],
            ..config()
        },
        &dir,
        None,
    );
    let curve = validations(&dir);
    assert_eq!(curve.len(), 8);
    let (first, last) = (curve[0], curve[7]);
    // The run is deterministic: the loss falls by more than 5 % and the accuracy rises.
    assert!(last.loss < 0.95 * first.loss, "{first:?} → {last:?}");
    assert!(
        last.match_accuracy > first.match_accuracy,
        "{first:?} → {last:?}"
    );
    // The best is the highest recall after ICP, then the highest recall, then the lowest loss.
    let best = trainer.state().best.expect("validated");
    let key = |v: &Validation| (v.recall_refined, v.recall, -v.loss);
    let expected = curve
        .iter()
        .copied()
        .reduce(|a, b| if key(&b) > key(&a) { b } else { a })
        .unwrap();
    assert_eq!(best, expected);
    assert!(dir.join("best.safetensors").exists());
}

/// Every tensor of the safetensors file `name` in `dir`, as bits.
fn tensor_bits(dir: &Path, name: &str) -> BTreeMap<String, Vec<u32>> {
    let (tensors, _) = rgm_nn::io::read_tensors::<f32>(&dir.join(name)).unwrap();
    tensors
        .into_iter()
        .map(|(n, t)| (n, t.iter().map(|v| v.to_bits()).collect()))
        .collect()
}

/// The log's records and the state without their wall-clock fields (seconds, and the log's
/// length in bytes, which holds them).
fn log_and_state(dir: &Path) -> (Vec<serde_json::Value>, TrainState) {
    let log = fs::read_to_string(dir.join("log.jsonl"))
        .unwrap()
        .lines()
        .map(|line| {
            let mut record: serde_json::Value = serde_json::from_str(line).unwrap();
            record.as_object_mut().unwrap().remove("seconds");
            record
        })
        .collect();
    let state = fs::read_to_string(dir.join("state.json")).unwrap();
    let state = TrainState {
        seconds: 0.0,
        log_bytes: None,
        ..serde_json::from_str(&state).unwrap()
    };
    (log, state)
}

/// Issue 14, case 3: a checkpoint was three renames, and a kill between them left the weights
/// ahead of the state (the resumed run replayed batches on weights that held them, and logged
/// them twice). Here the run fails at each file operation of its checkpoints and log in turn,
/// as if killed there, and is resumed: weights, optimiser, best weights, log and state end
/// bit-identical to those of a run never interrupted.
#[test]
fn a_run_killed_at_any_file_operation_resumes_exactly() {
    let config = TrainConfig {
        epochs: 1,
        checkpoint_every: 2,
        ..config()
    };
    let straight = run_dir("kill-straight");
    let operations = train(config.clone(), &straight, None).dir.faults.operations;
    // 3 checkpoints in the epoch and 1 after validation, each a log line and a commit.
    assert!(operations >= 4 * 8, "{operations} file operations");
    for n in 1..=operations {
        let dir = run_dir(&format!("kill-{n}"));
        let mut trainer = Trainer::open(config.clone(), &dir).unwrap();
        trainer.dir.faults.fail_at = Some(n);
        let err = trainer
            .run(&dataset(), &mut |_| ControlFlow::Continue(()))
            .unwrap_err();
        assert!(err.to_string().contains("failure injected"), "{err}");
        drop(trainer);
        train(config.clone(), &dir, None);
        for file in [
            "last.safetensors",
            "last.optim.safetensors",
            "best.safetensors",
        ] {
            assert!(
                tensor_bits(&straight, file) == tensor_bits(&dir, file),
                "{file} differs after a kill at file operation {n}"
            );
        }
        assert_eq!(
            log_and_state(&straight),
            log_and_state(&dir),
            "killed at {n}"
        );
        assert!(!dir.join("checkpoint").exists() && !dir.join("checkpoint.tmp").exists());
        fs::remove_dir_all(&dir).unwrap();
    }
}

/// Issue 14, case 4: two trainers on one folder shared temporary names and mixed their logs.
#[test]
fn a_run_folder_is_held_by_one_trainer_at_a_time() {
    let dir = run_dir("lock");
    let first = Trainer::open(config(), &dir).unwrap();
    let err = Trainer::open(config(), &dir)
        .err()
        .expect("the folder is held");
    assert!(matches!(err, TrainError::Busy { .. }), "{err}");
    let message = err.to_string();
    assert!(
        message.contains(&format!(
            "in use by another `rgm train` (process {})",
            std::process::id()
        )),
        "{message}"
    );
    drop(first);
    // The lock goes with its holder; the file it leaves (as a killed process does) holds
    // nobody back.
    assert!(dir.join("lock").exists());
    drop(Trainer::open(config(), &dir).unwrap());
}

/// Runs committed before checkpoints were commits (no `log_bytes` in the state, no
/// `checkpoint/` folder) resume, and take the new layout at their first checkpoint; weights and
/// Adam moments stored as bf16 (snapshots kept small in git) load too.
#[test]
fn a_run_saved_in_the_old_layout_resumes_and_so_does_a_bf16_snapshot() {
    // A finished run as a snapshot commits it: `config.json`, `state.json` and the end of
    // `log.jsonl` of runs/partial-fast as last committed (1487761; the folder has left the
    // tree, its files are in the history), bf16 weights and no Adam state (`cargo xtask
    // snapshot-runs --finished`: it resumes with a fresh one, and writes its own below). The
    // weights are made here (the run's own are 3 MB each): fresh ones of the run's sizes,
    // rounded to bf16 as a snapshot rounds them.
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/finished-run");
    let dir = run_dir("legacy");
    fs::create_dir_all(&dir).unwrap();
    for name in ["config.json", "state.json", "log.jsonl"] {
        fs::copy(committed.join(name), dir.join(name)).unwrap();
    }
    let saved_config: TrainConfig =
        serde_json::from_str(&fs::read_to_string(dir.join("config.json")).unwrap()).unwrap();
    let f32_weights = dir.join("f32.safetensors");
    let network = crate::network::Rgm::<f32>::new(saved_config.network.clone(), 7).unwrap();
    rgm_nn::io::save_params(&f32_weights, &network).unwrap();
    for name in ["last.safetensors", "best.safetensors"] {
        rgm_nn::io::rewrite_with_bf16(&f32_weights, &dir.join(name), &|_| true).unwrap();
    }
    fs::remove_file(&f32_weights).unwrap();
    let mut config: TrainConfig =
        serde_json::from_str(&fs::read_to_string(dir.join("config.json")).unwrap()).unwrap();
    // The state as the old code wrote it, whatever the snapshot's age.
    let mut state: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(dir.join("state.json")).unwrap()).unwrap();
    state.as_object_mut().unwrap().remove("log_bytes");
    fs::write(dir.join("state.json"), state.to_string()).unwrap();
    let saved: TrainState = serde_json::from_value(state).unwrap();
    assert_eq!(saved.log_bytes, None);
    // A snapshot at the end of its schedule still has an epoch to go on with.
    config.epochs = config.epochs.max(saved.epoch + 2);
    let log_before = fs::read(dir.join("log.jsonl")).unwrap();
    // The small dataset: the run goes on from its saved position and stops after a batch.
    let mut trainer = Trainer::open(config.clone(), &dir).unwrap();
    assert_eq!(trainer.state(), &saved);
    trainer
        .run(&dataset(), &mut |event| match event {
            Event::Batch { .. } => ControlFlow::Break(()),
            _ => ControlFlow::Continue(()),
        })
        .unwrap();
    let state = trainer.state().clone();
    drop(trainer);
    // Saved at an epoch's end, the run stops after that epoch's first batch (one record); saved
    // inside an epoch (past this dataset's batches), it validates first (two records).
    let (position, records) = match saved.batch {
        0 => ((saved.epoch, 1), 1),
        _ => ((saved.epoch + 1, 1), 2),
    };
    assert_eq!((state.epoch, state.batch), position);
    let log = fs::read(dir.join("log.jsonl")).unwrap();
    assert_eq!(state.log_bytes, Some(log.len() as u64));
    assert!(log.starts_with(&log_before));
    assert_eq!(
        String::from_utf8_lossy(&log[log_before.len()..])
            .lines()
            .count(),
        records
    );
    // The Adam moments as bf16, the weights as they were: the run resumes from them.
    let optim = dir.join("last.optim.safetensors");
    let bf16 = dir.join("bf16.safetensors");
    rgm_nn::io::rewrite_with_bf16(&optim, &bf16, &|n| {
        n.starts_with("m.") || n.starts_with("v.")
    })
    .unwrap();
    // Two moments per weight, half the bytes each: about the size of the weights.
    let weights = fs::metadata(dir.join("last.safetensors")).unwrap().len();
    assert!(fs::metadata(&bf16).unwrap().len() < weights * 11 / 10);
    fs::rename(&bf16, &optim).unwrap();
    // The weights as bf16 too (`cargo xtask snapshot-runs`): half the bytes, and they resume.
    let last = dir.join("last.safetensors");
    rgm_nn::io::rewrite_with_bf16(&last, &bf16, &|_| true).unwrap();
    assert!(fs::metadata(&bf16).unwrap().len() < weights * 51 / 100);
    fs::rename(&bf16, &last).unwrap();
    let resumed = Trainer::open(config, &dir).unwrap();
    assert_eq!(resumed.state(), &state);
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_run_of_no_epoch_is_refused() {
    let err = Trainer::open(
        TrainConfig {
            epochs: 0,
            ..config()
        },
        &run_dir("none"),
    )
    .err()
    .expect("refused");
    assert_eq!(
        err.to_string(),
        "training configuration: epochs must be positive"
    );
}

#[test]
fn numeric_settings_out_of_range_are_refused_by_name() {
    // Issue 27, case 10: a NaN gamma was accepted and saved as `null` in config.json (the run
    // could never be resumed); a NaN momentum was refused by Sinkhorn's check.
    let cases = [
        (
            TrainConfig {
                gamma: f64::NAN,
                ..config()
            },
            "gamma must be a positive number, got NaN",
        ),
        (
            TrainConfig {
                gamma: -0.2,
                ..config()
            },
            "gamma must be a positive number, got -0.2",
        ),
        (
            TrainConfig {
                momentum: f64::NAN,
                ..config()
            },
            "momentum must be a number from 0 up to 1 (1 excluded), got NaN",
        ),
        (
            TrainConfig {
                weight_decay: f64::INFINITY,
                ..config()
            },
            "weight_decay must be a number from 0 up, got inf",
        ),
        (
            TrainConfig {
                lr: 0.0,
                ..config()
            },
            "lr must be a positive number, got 0",
        ),
    ];
    for (k, (bad, expected)) in cases.into_iter().enumerate() {
        let dir = run_dir(&format!("numbers-{k}"));
        let err = Trainer::open(bad, &dir).err().expect("refused");
        assert_eq!(
            err.to_string(),
            format!("training configuration: {expected}")
        );
        assert!(!dir.join("config.json").exists(), "nothing saved");
    }
}

#[test]
fn the_default_training_is_the_built_in_models_recipe() {
    let manifest = crate::weights::Manifest::builtin();
    let builtin = manifest.builtin_entry().unwrap();
    let default = TrainConfig::default();
    assert_eq!(builtin.preset, super::DEFAULT_PRESET);
    assert_eq!(builtin.setting, default.setting);
    assert!(!builtin.unseen && !default.unseen);
    // Trained on the default's match points; the manifest's own are the test-time choice.
    let points = default
        .match_points
        .expect("the default trains on a subset");
    assert!(
        builtin
            .trained_with
            .contains(&format!("--match-points {points} ")),
        "{}",
        builtin.trained_with
    );
    assert_eq!(builtin.test_statistics, default.test_statistics);
    assert_eq!(builtin.config().unwrap(), default.network);
}
