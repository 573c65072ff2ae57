//! Training on a small hand-made dataset: resuming is exact, runs refuse other settings, and the
//! loss goes down.

use std::fs;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rgm_data::{ModelNet40, Shape};
use rgm_model::network::Config;
use rgm_model::train::{
    Event, LogRecord, OptimizerKind, TrainConfig, TrainError, Trainer, Validation,
};

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
    let first = train(config(), &broken, Some((0, 2)));
    assert_eq!((first.state().epoch, first.state().batch), (0, 2));
    let second = train(config(), &broken, Some((1, 1)));
    assert_eq!((second.state().epoch, second.state().batch), (1, 1));
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
    let longer = train(config(), &dir, None);
    assert_eq!(longer.state().epoch, 2);
    assert_eq!(validations(&dir).len(), 2);
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
    // Deterministic run: loss 2.38 → 2.21 and matching accuracy 5 % → 13 % when written.
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
