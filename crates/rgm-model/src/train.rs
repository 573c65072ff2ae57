//! Training RGM (spec §3): BCE between C̃ and the ground-truth correspondences, SGD with momentum
//! (or Adam) over batches of pairs, a step learning rate, validation after every epoch, and a run
//! folder that holds everything needed to resume after an interruption.
//!
//! The run folder:
//! - `config.json` — the [`TrainConfig`] (network sizes included);
//! - `state.json` — where the run is ([`TrainState`]: epoch, next batch, best validation);
//! - `last.safetensors`, `last.optim.safetensors` — weights and optimiser state, written every
//!   [`TrainConfig::checkpoint_every`] batches and at the end of every epoch;
//! - `best.safetensors` — the weights with the best validation result so far;
//! - `log.jsonl` — one JSON object per line: `"kind": "train"` (mean loss of the batches since
//!   the previous line) and `"kind": "validation"` (after every epoch), see [`LogRecord`];
//! - `lock` — the process id of the trainer that holds the folder (an exclusive `flock`, which
//!   the system releases when that process ends, however it ends).
//!
//! A checkpoint is one atomic commit: its files (state, weights, optimiser, best weights when
//! they changed) are written into `checkpoint.tmp/`, which one rename turns into
//! `checkpoint/`; its files are then moved over the run's own. [`Trainer::open`] finishes a
//! commit that a kill interrupted, drops an uncommitted one, and cuts `log.jsonl` back to the
//! length the state records, so a run killed at any moment resumes exactly where its last
//! commit left it, with the log it had then. The checkpoint's files are flushed to the disk
//! before the commit, so it also survives a power cut.
//!
//! Pairs are made on the fly ([`PairGenerator::train_pair`], a new random pose, crop and noise
//! every epoch), optionally cut to [`TrainConfig::match_points`] points per cloud. A batch is
//! spread over [`TrainConfig::workers`] threads, each with its own copy of the network; their
//! gradients are summed into the main network, which takes the step and hands its weights back.
//! Batch norm uses each cloud's own statistics (as in a batch of one); the workers' running
//! statistics are averaged after every batch.

use std::fs;
use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rayon::prelude::*;
use rgm_data::pairs::train_seed;
use rgm_data::{ModelNet40, Pair, PairGenerator, Setting, Shape, Split};
use rgm_geom::metrics::PairMetrics;
use rgm_geom::refine::{refine, RefineConfig};
use rgm_geom::RigidTransform;
use rgm_match::{bce_forward, Correspondences};
use rgm_nn::optim::{Adam, MultiStepLr, Sgd};
use rgm_nn::{Parameters, Precision, Scalar};
use serde::{Deserialize, Serialize};

use crate::evaluate::{evaluate_pair, PairRecord, Summary};
use crate::method::Method;
use crate::network::{Config, Mode, NetworkError, Rgm, RgmCache, TestStatistics};
use crate::pipeline::{as_rows, PipelineConfig, RgmRegistrar};

/// Why training could not start or go on.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Json {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("training configuration: {why}")]
    Config { why: String },
    #[error(
        "{}: the run folder is in use by another `rgm train` (process {pid}); wait for it to \
         end, stop it, or train into another --out folder",
        dir.display()
    )]
    Busy { dir: PathBuf, pid: String },
    #[error(transparent)]
    Network(#[from] NetworkError),
    #[error(transparent)]
    Nn(#[from] rgm_nn::NnError),
    #[error(transparent)]
    Data(#[from] rgm_data::DataError),
    #[error(transparent)]
    Match(#[from] rgm_match::MatchError),
    #[error(transparent)]
    Geom(#[from] rgm_geom::GeomError),
}

pub type Result<T> = std::result::Result<T, TrainError>;

/// The optimiser of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OptimizerKind {
    /// SGD with Nesterov momentum, as the reference code (spec §3).
    Sgd,
    /// Adam (β 0.9, 0.999).
    Adam,
}

/// Everything that defines a training run; saved as `config.json` in the run folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// "clean", "noise" or "partial" (spec §1).
    pub setting: String,
    /// Train and validate on categories 0–19 only.
    pub unseen: bool,
    /// The network's sizes.
    pub network: Config,
    /// Cut each cloud of every pair to at most this many points (None: the whole pair).
    pub match_points: Option<usize>,
    /// Epochs in all (one epoch = every training shape once).
    pub epochs: usize,
    /// Pairs per optimiser step.
    pub batch: usize,
    pub optimizer: OptimizerKind,
    /// Learning rate before the first milestone.
    pub lr: f64,
    /// SGD momentum (unused by Adam).
    pub momentum: f64,
    pub weight_decay: f64,
    /// Epochs at which the learning rate is multiplied by `gamma`.
    pub milestones: Vec<usize>,
    pub gamma: f64,
    /// Use only the first N training shapes per epoch (None: all).
    pub train_shapes: Option<usize>,
    /// Validate on N validation shapes (None: all), taken as `val_sample` says.
    pub val_shapes: Option<usize>,
    /// Which `val_shapes` shapes validate. Only validation depends on it: it may change on
    /// resume (the first validation on a new sample then becomes the best, see
    /// [`Validation::beats`]). Runs saved before the field validated on the first ones.
    #[serde(default)]
    pub val_sample: ValSample,
    /// Threads, each working on its own pairs of a batch.
    pub workers: usize,
    /// Save `last.*` every this many batches.
    pub checkpoint_every: usize,
    /// Seed of the initial weights and of the shape order of every epoch.
    pub seed: u64,
    /// Batch-norm statistics of the network at validation. Training normalises each cloud with
    /// its own statistics, so `Cloud` validates the network as it was trained; `Running` is
    /// PyTorch's `eval()` (spec §3). Only validation depends on it: it may change on resume.
    #[serde(default)]
    pub test_statistics: TestStatistics,
    /// The network's matrix products in training and validation: f32, or bf16 where the
    /// processor has AMX or AVX-512 BF16 (weights, optimiser state, reductions and the loss
    /// stay f32). A compute choice, not a setting of the run: it may change on resume.
    #[serde(default, with = "precision_name")]
    pub precision: Precision,
    /// Weights a new run starts from instead of the seeded initialisation (fine-tuning, e.g.
    /// the noise model from the partial one). Only the start: a resumed run loads its own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init: Option<PathBuf>,
}

/// [`Precision`] in `config.json` by name ("f32", "bf16"); absent in runs saved before it.
mod precision_name {
    use rgm_nn::Precision;
    use serde::{de::Error, Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(p: &Precision, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(p.name())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Precision, D::Error> {
        String::deserialize(d)?.parse().map_err(D::Error::custom)
    }
}

impl TrainConfig {
    /// The paper's schedule (spec §3: SGD, momentum 0.9, lr 1e-3, batch 4, 200 epochs, ×0.2 at
    /// 120 and 140) for `setting` with `network`'s sizes, on both cores.
    pub fn paper(setting: Setting, network: Config) -> Self {
        Self {
            setting: setting.name().to_string(),
            unseen: false,
            network,
            match_points: None,
            epochs: 200,
            batch: 4,
            optimizer: OptimizerKind::Sgd,
            lr: 1e-3,
            momentum: 0.9,
            weight_decay: 0.0,
            milestones: vec![120, 140],
            gamma: 0.2,
            train_shapes: None,
            val_shapes: None,
            val_sample: ValSample::Spread,
            workers: 2,
            checkpoint_every: 50,
            seed: 0,
            test_statistics: TestStatistics::Running,
            precision: Precision::F32,
            init: None,
        }
    }

    /// The pair setting, parsed.
    pub fn pair_setting(&self) -> Result<Setting> {
        self.setting.parse().map_err(|_| TrainError::Config {
            why: format!("unknown setting {:?}", self.setting),
        })
    }

    fn validate(&self) -> Result<()> {
        self.pair_setting()?;
        self.network.validate()?;
        let why = if self.epochs == 0 {
            "epochs must be positive"
        } else if self.batch == 0 {
            "batch must be positive"
        } else if self.workers == 0 {
            "workers must be positive"
        } else if self.checkpoint_every == 0 {
            "checkpoint_every must be positive"
        } else if self.match_points.is_some_and(|p| p <= self.network.k) {
            "match_points must exceed the network's K"
        } else {
            return self.validate_numbers();
        };
        Err(TrainError::Config { why: why.into() })
    }

    /// The real-valued settings in their ranges; NaN and infinity are refused by name (a NaN
    /// would be saved in `config.json` as `null`, which no run can resume from).
    fn validate_numbers(&self) -> Result<()> {
        let checks: [(&str, f64, bool, &str); 4] = [
            ("lr", self.lr, self.lr > 0.0, "a positive number"),
            ("gamma", self.gamma, self.gamma > 0.0, "a positive number"),
            (
                "momentum",
                self.momentum,
                (0.0..1.0).contains(&self.momentum),
                "a number from 0 up to 1 (1 excluded)",
            ),
            (
                "weight_decay",
                self.weight_decay,
                self.weight_decay >= 0.0,
                "a number from 0 up",
            ),
        ];
        match checks
            .iter()
            .find(|(_, value, in_range, _)| !(value.is_finite() && *in_range))
        {
            Some((name, value, _, what)) => Err(TrainError::Config {
                why: format!("{name} must be {what}, got {value}"),
            }),
            None => Ok(()),
        }
    }

    /// Whether a run saved with `saved` can go on under `self`: everything equal but the
    /// number of epochs (a run may be extended) and what only validation or speed depends on
    /// (batch-norm statistics at validation, its sample, the products' precision).
    fn same_run(&self, saved: &Self) -> bool {
        Self {
            epochs: saved.epochs,
            test_statistics: saved.test_statistics,
            val_sample: saved.val_sample,
            precision: saved.precision,
            ..self.clone()
        } == *saved
    }
}

/// Which validation shapes a run validates on when it takes fewer than all of them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ValSample {
    /// The first N of the split. The split is ordered by category, so these are a few
    /// categories only (the first 300 of the partial protocol: airplane to bookshelf). What runs
    /// saved before the choice existed did.
    #[default]
    First,
    /// N shapes spread evenly over the split (every category when N ≥ 40).
    Spread,
}

impl ValSample {
    /// The `n` shapes of `shapes` this sample takes (all of them when `n` ≥ their number).
    pub fn take<'a>(self, shapes: &[&'a Shape], n: usize) -> Vec<&'a Shape> {
        let len = shapes.len();
        if n >= len {
            return shapes.to_vec();
        }
        match self {
            ValSample::First => shapes[..n].to_vec(),
            ValSample::Spread => (0..n).map(|j| shapes[j * len / n]).collect(),
        }
    }
}

/// The validation result of one epoch.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Validation {
    pub epoch: usize,
    pub pairs: usize,
    /// The shapes validated on ([`ValSample::First`] in records written before the field).
    #[serde(default)]
    pub sample: ValSample,
    /// Mean BCE per pair (spec §3), network in evaluation mode.
    pub loss: f64,
    /// Fraction of ground-truth matched source points whose largest entry of C̃ is their match.
    pub match_accuracy: f64,
    pub mie_r_deg: f64,
    pub mie_t: f64,
    pub mae_r_deg: f64,
    pub mae_t: f64,
    /// Fraction of pairs registered (spec §5: MAE(R) < 1° and MAE(t) < 0.1).
    pub recall: f64,
    /// Fraction registered once `refined_with` refines the procedure's transform on the full
    /// pair (what `--refine` does); 0 in validations logged before it was measured.
    #[serde(default)]
    pub recall_refined: f64,
    /// The refinement behind `recall_refined`.
    #[serde(default)]
    pub refined_with: Refinement,
    /// Pairs on which the test-time procedure found no correspondences.
    pub failures: usize,
}

/// The refinements `recall_refined` has been measured with, so that logs stay readable after
/// `--refine` changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Refinement {
    /// Point-to-point ICP (0.1, 30 iterations): what logs without the field measured.
    #[default]
    PointToPointIcp,
    /// [`rgm_geom::refine`] before session 6: trimmed point-to-plane ICP, coarse to fine.
    TrimmedPointToPlane,
    /// [`rgm_geom::refine`] since session 6: the same, then point-to-point ICP at 0.05 and 0.03.
    PlaneThenPoint,
}

impl Validation {
    /// Whether `self` beats `other`: higher recall after refinement, then higher recall, then
    /// lower loss; recall after refinement counts only when both were refined alike (a new
    /// refinement must not make a newer checkpoint look better). A validation on another
    /// sample of shapes than `other`'s always beats it: the two are not comparable, and `self`
    /// is on the sample the run validates on now.
    fn beats(&self, other: &Self) -> bool {
        if self.sample != other.sample {
            return true;
        }
        let refined = |v: &Self| {
            if self.refined_with == other.refined_with {
                v.recall_refined
            } else {
                0.0
            }
        };
        (refined(self), self.recall, -self.loss) > (refined(other), other.recall, -other.loss)
    }
}

/// Where a run is; saved as `state.json` with every checkpoint.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// The epoch in progress (from 0).
    pub epoch: usize,
    /// The next batch of that epoch.
    pub batch: usize,
    /// Optimiser steps taken.
    pub steps: u64,
    /// Training pairs processed.
    pub pairs_seen: u64,
    /// Seconds spent training and validating, over all sessions.
    pub seconds: f64,
    /// The best validation so far (its weights are `best.safetensors`).
    pub best: Option<Validation>,
    /// The length of `log.jsonl` at this checkpoint: lines after it were written by a run
    /// killed before its next checkpoint, and are cut on resume (None in runs saved before
    /// the field existed).
    #[serde(default)]
    pub log_bytes: Option<u64>,
}

/// One line of `log.jsonl`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum LogRecord {
    /// Mean training loss over the batches since the previous train record.
    Train {
        epoch: usize,
        batch: usize,
        batches: usize,
        pairs_seen: u64,
        lr: f64,
        loss: f64,
        seconds: f64,
    },
    /// The validation after an epoch.
    Validation {
        #[serde(flatten)]
        result: Validation,
        pairs_seen: u64,
        seconds: f64,
    },
}

/// What [`Trainer::run`] reports as it goes (for progress bars).
#[derive(Clone, Debug)]
pub enum Event {
    /// A batch is done: its mean loss.
    Batch {
        epoch: usize,
        batch: usize,
        batches: usize,
        loss: f64,
    },
    /// Validation is running: pairs done of total.
    Validating { done: usize, total: usize },
    /// A line was appended to the log.
    Logged(LogRecord),
}

enum Optimizer {
    Sgd(Sgd<f32>),
    Adam(Adam<f32>),
}

impl Optimizer {
    fn new(config: &TrainConfig) -> Self {
        match config.optimizer {
            OptimizerKind::Sgd => {
                let mut sgd = Sgd::new(config.lr, config.momentum, config.weight_decay);
                sgd.nesterov = true; // as the reference sets it (spec §3)
                Self::Sgd(sgd)
            }
            OptimizerKind::Adam => Self::Adam(Adam::new(config.lr, config.weight_decay)),
        }
    }

    fn load(kind: OptimizerKind, path: &Path) -> Result<Self> {
        Ok(match kind {
            OptimizerKind::Sgd => Self::Sgd(Sgd::load(path)?),
            OptimizerKind::Adam => Self::Adam(Adam::load(path)?),
        })
    }

    fn set_lr(&mut self, lr: f64) {
        match self {
            Self::Sgd(o) => o.lr = lr,
            Self::Adam(o) => o.lr = lr,
        }
    }

    fn step(&mut self, model: &mut Rgm<f32>) -> Result<()> {
        match self {
            Self::Sgd(o) => o.step(model)?,
            Self::Adam(o) => o.step(model)?,
        }
        Ok(())
    }

    fn save(&self, path: &Path) -> Result<()> {
        match self {
            Self::Sgd(o) => o.save(path)?,
            Self::Adam(o) => o.save(path)?,
        }
        Ok(())
    }
}

/// One worker's network copy and forward/backward buffers.
struct Worker {
    network: Rgm<f32>,
    cache: RgmCache<f32>,
}

/// Whether the refinement (default settings) from `transform` registers `pair` (spec §5's
/// recall).
fn refined_recall(pair: &Pair, transform: &RigidTransform) -> Result<bool> {
    let config = RefineConfig::default();
    let found = refine(&pair.source, &pair.target, transform, &config)?.t_target_source;
    let metrics = PairMetrics::compute(&found, &pair.t_target_source, &pair.source, &pair.target)?;
    Ok(metrics.recall)
}

fn ground_truth(pair: &Pair) -> Result<Correspondences> {
    let c = &pair.correspondence;
    Ok(Correspondences::new(
        c.n_source,
        c.n_target,
        c.pairs.clone(),
    )?)
}

/// One worker's share of a validation: its pairs' records, summed loss, the ground-truth
/// matches of its pairs (`matched`) of which C̃'s row maximum found the partner (`hits`), and
/// the pairs registered after ICP refinement (`refined`).
#[derive(Default)]
struct ValidationPart {
    records: Vec<PairRecord>,
    loss_sum: f64,
    hits: usize,
    matched: usize,
    refined: usize,
}

/// A training run bound to its folder.
pub struct Trainer {
    config: TrainConfig,
    dir: PathBuf,
    network: Rgm<f32>,
    optimizer: Optimizer,
    state: TrainState,
    workers: Vec<Worker>,
    /// The run folder's lock, held as long as the trainer lives.
    _lock: fs::File,
    /// File operations of checkpoints so far, and the one to fail (see
    /// [`Trainer::fail_at_file_operation`]).
    file_operations: usize,
    fail_at: Option<usize>,
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> TrainError + '_ {
    move |source| TrainError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The folder a checkpoint is written into, and its name once committed.
const STAGING: &str = "checkpoint.tmp";
const COMMITTED: &str = "checkpoint";
/// The files of a checkpoint, moved over the run's own in this order once committed.
const CHECKPOINT_FILES: [&str; 4] = [
    "last.safetensors",
    "last.optim.safetensors",
    "best.safetensors",
    "state.json",
];

/// Takes the exclusive lock of the run folder `dir` (created if missing) and writes this
/// process's id into it; fails naming the process that holds it.
fn lock_run(dir: &Path) -> Result<fs::File> {
    fs::create_dir_all(dir).map_err(io_err(dir))?;
    let path = dir.join("lock");
    let mut file = fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(io_err(&path))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(fs::TryLockError::WouldBlock) => {
            let pid = fs::read_to_string(&path).unwrap_or_default();
            return Err(TrainError::Busy {
                dir: dir.to_path_buf(),
                pid: pid.trim().to_string(),
            });
        }
        Err(fs::TryLockError::Error(e)) => return Err(io_err(&path)(e)),
    }
    file.set_len(0).map_err(io_err(&path))?;
    writeln!(file, "{}", std::process::id()).map_err(io_err(&path))?;
    Ok(file)
}

/// Flushes the file or folder at `path` to the disk.
fn sync(path: &Path) -> Result<()> {
    fs::File::open(path)
        .and_then(|f| f.sync_all())
        .map_err(io_err(path))
}

/// Moves the files of a committed checkpoint (`dir/checkpoint/`) over the run's own, then
/// removes the folder; does nothing when there is none. Safe to repeat after an interruption:
/// the files already moved are no longer in the folder. `step` comes before every operation.
fn finish_commit(dir: &Path, step: &mut dyn FnMut() -> Result<()>) -> Result<()> {
    let committed = dir.join(COMMITTED);
    if !committed.exists() {
        return Ok(());
    }
    for name in CHECKPOINT_FILES {
        let from = committed.join(name);
        if from.exists() {
            step()?;
            fs::rename(&from, dir.join(name)).map_err(io_err(&from))?;
        }
    }
    step()?;
    fs::remove_dir_all(&committed).map_err(io_err(&committed))
}

/// Brings the run folder `dir` to its last commit: finishes a commit a kill interrupted,
/// drops an uncommitted checkpoint, and cuts the log's lines written after the commit.
/// Returns the committed state (None for a new run).
fn recover(dir: &Path) -> Result<Option<TrainState>> {
    finish_commit(dir, &mut || Ok(()))?;
    let staging = dir.join(STAGING);
    if staging.exists() {
        fs::remove_dir_all(&staging).map_err(io_err(&staging))?;
    }
    let state_path = dir.join("state.json");
    let log = dir.join("log.jsonl");
    if !state_path.exists() {
        // No commit yet: the log's lines, if any, are of a run killed before its first.
        if log.exists() {
            fs::write(&log, "").map_err(io_err(&log))?;
        }
        return Ok(None);
    }
    let state: TrainState = read_json(&state_path)?;
    if let Some(len) = state.log_bytes {
        let file = fs::OpenOptions::new()
            .write(true)
            .open(&log)
            .map_err(io_err(&log))?;
        if file.metadata().map_err(io_err(&log))?.len() > len {
            file.set_len(len).map_err(io_err(&log))?;
        }
    }
    Ok(Some(state))
}

/// Writes `path` through a temporary file and a rename, so an interruption never
/// leaves a half-written file behind.
fn write_atomic(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let tmp = path.with_extension("tmp");
    write(&tmp)?;
    fs::rename(&tmp, path).map_err(io_err(path))
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    write_atomic(path, |tmp| {
        let text = serde_json::to_string_pretty(value).map_err(|source| TrainError::Json {
            path: tmp.to_path_buf(),
            source,
        })?;
        fs::write(tmp, text).map_err(io_err(tmp))
    })
}

fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text = fs::read_to_string(path).map_err(io_err(path))?;
    serde_json::from_str(&text).map_err(|source| TrainError::Json {
        path: path.to_path_buf(),
        source,
    })
}

impl Trainer {
    /// The run in `dir`: resumed from its last checkpoint when `dir` holds one (its saved
    /// configuration must equal `config` except for the number of epochs), a new run otherwise.
    pub fn open(config: TrainConfig, dir: &Path) -> Result<Self> {
        config.validate()?;
        let lock = lock_run(dir)?;
        let (network, optimizer, state) = if let Some(state) = recover(dir)? {
            let saved: TrainConfig = read_json(&dir.join("config.json"))?;
            if !config.same_run(&saved) {
                return Err(TrainError::Config {
                    why: format!(
                        "{} holds a run with other settings ({}); give the same options (only \
                         --epochs may change) or another --out folder",
                        dir.display(),
                        dir.join("config.json").display()
                    ),
                });
            }
            let network = Rgm::load(config.network.clone(), &dir.join("last.safetensors"))?;
            // A finished run may be committed without its optimiser state (the largest file,
            // needed by no resume until the run is extended): it then goes on with a fresh one.
            let optim = dir.join("last.optim.safetensors");
            let optimizer = if optim.exists() {
                Optimizer::load(config.optimizer, &optim)?
            } else {
                Optimizer::new(&config)
            };
            (network, optimizer, state)
        } else {
            let network = match &config.init {
                Some(init) => Rgm::load(config.network.clone(), init)?,
                None => Rgm::new(config.network.clone(), config.seed)?,
            };
            (network, Optimizer::new(&config), TrainState::default())
        };
        let mut network = network;
        network.set_precision(config.precision); // the workers' copies inherit it
        write_json(&dir.join("config.json"), &config)?;
        let workers = (0..config.workers)
            .map(|_| Worker {
                network: network.clone(),
                cache: RgmCache::default(),
            })
            .collect();
        Ok(Self {
            config,
            dir: dir.to_path_buf(),
            network,
            optimizer,
            state,
            workers,
            _lock: lock,
            file_operations: 0,
            fail_at: None,
        })
    }

    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    pub fn state(&self) -> &TrainState {
        &self.state
    }

    /// The network being trained.
    pub fn network(&self) -> &Rgm<f32> {
        &self.network
    }

    /// The learning rate of `epoch`.
    pub fn lr(&self, epoch: usize) -> f64 {
        MultiStepLr {
            base: self.config.lr,
            milestones: self.config.milestones.clone(),
            gamma: self.config.gamma,
        }
        .lr(epoch)
    }

    /// Trains until the configured number of epochs is done, validating after each epoch and
    /// checkpointing as it goes. `dataset` must be the one the run started on. When `on_event`
    /// answers `Break` to a batch, the run saves a checkpoint there and returns; to an epoch's
    /// validation record, it returns after that epoch's checkpoint (either way a later
    /// [`Trainer::open`] + `run` goes on from it exactly as if never stopped).
    pub fn run(
        &mut self,
        dataset: &ModelNet40,
        on_event: &mut dyn FnMut(Event) -> ControlFlow<()>,
    ) -> Result<()> {
        let setting = self.config.pair_setting()?;
        let generator = PairGenerator::new(setting);
        let mut train = dataset.split(Split::Train, self.config.unseen);
        train.truncate(self.config.train_shapes.unwrap_or(usize::MAX));
        let val = self.config.val_sample.take(
            &dataset.split(Split::Validation, self.config.unseen),
            self.config.val_shapes.unwrap_or(usize::MAX),
        );
        if train.is_empty() || val.is_empty() {
            return Err(TrainError::Config {
                why: format!(
                    "{} training and {} validation shapes: both must be non-empty",
                    train.len(),
                    val.len()
                ),
            });
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(self.config.workers)
            .start_handler(|_| {
                rgm_nn::threads::flush_denormals_to_zero();
            })
            .build()
            .map_err(|e| TrainError::Config {
                why: format!("cannot start {} worker threads: {e}", self.config.workers),
            })?;
        rgm_nn::threads::set_blas_threads(1);
        let batches = train.len().div_ceil(self.config.batch);
        let mut since_log = (0.0, 0usize); // (loss sum, batches)
        while self.state.epoch < self.config.epochs {
            let epoch = self.state.epoch;
            let lr = self.lr(epoch);
            self.optimizer.set_lr(lr);
            let mut order: Vec<usize> = (0..train.len()).collect();
            order.shuffle(&mut StdRng::seed_from_u64(
                self.config.seed ^ train_seed(epoch, 0),
            ));
            let mut clock = Instant::now();
            while self.state.batch < batches {
                let b = self.state.batch;
                let chunk =
                    &order[b * self.config.batch..((b + 1) * self.config.batch).min(order.len())];
                let loss = pool.install(|| self.step(&generator, &train, epoch, chunk))?;
                self.state.batch += 1;
                self.state.steps += 1;
                self.state.pairs_seen += chunk.len() as u64;
                since_log = (since_log.0 + loss, since_log.1 + 1);
                let stop = on_event(Event::Batch {
                    epoch,
                    batch: b + 1,
                    batches,
                    loss,
                })
                .is_break();
                let due = self
                    .state
                    .batch
                    .is_multiple_of(self.config.checkpoint_every);
                if due || stop || self.state.batch == batches {
                    self.state.seconds += clock.elapsed().as_secs_f64();
                    clock = Instant::now();
                    let record = LogRecord::Train {
                        epoch,
                        batch: self.state.batch,
                        batches,
                        pairs_seen: self.state.pairs_seen,
                        lr,
                        loss: since_log.0 / since_log.1 as f64,
                        seconds: self.state.seconds,
                    };
                    since_log = (0.0, 0);
                    self.log(&record)?;
                    let _ = on_event(Event::Logged(record));
                    self.checkpoint(false)?;
                }
                if stop {
                    return Ok(());
                }
            }
            let _ = on_event(Event::Validating {
                done: 0,
                total: val.len(),
            });
            let result = pool.install(|| self.validate(&generator, &val, epoch))?;
            let _ = on_event(Event::Validating {
                done: val.len(),
                total: val.len(),
            });
            self.state.seconds += clock.elapsed().as_secs_f64();
            let new_best = self.state.best.is_none_or(|best| result.beats(&best));
            if new_best {
                self.state.best = Some(result);
            }
            self.state.epoch += 1;
            self.state.batch = 0;
            let record = LogRecord::Validation {
                result,
                pairs_seen: self.state.pairs_seen,
                seconds: self.state.seconds,
            };
            self.log(&record)?;
            self.checkpoint(new_best)?;
            if on_event(Event::Logged(record)).is_break() {
                return Ok(());
            }
        }
        Ok(())
    }

    /// One optimiser step on the training shapes `chunk` of `epoch`; returns the mean loss.
    fn step(
        &mut self,
        generator: &PairGenerator,
        shapes: &[&Shape],
        epoch: usize,
        chunk: &[usize],
    ) -> Result<f64> {
        let workers = self.workers.len();
        let match_points = self.config.match_points;
        let losses: Vec<Result<f64>> = self
            .workers
            .par_iter_mut()
            .enumerate()
            .map(|(w, worker)| {
                worker.network.zero_grad();
                let mut sum = 0.0;
                for &i in chunk.iter().skip(w).step_by(workers) {
                    let mut pair = generator.train_pair(shapes, epoch, i)?;
                    if let Some(points) = match_points {
                        let seed = !train_seed(epoch, i);
                        pair = pair.subsampled(points, &mut StdRng::seed_from_u64(seed));
                    }
                    let gt = ground_truth(&pair)?;
                    let (x, y) = (as_rows(&pair.source), as_rows(&pair.target));
                    let loss = worker.network.forward_backward(
                        x.view(),
                        y.view(),
                        &gt,
                        &mut worker.cache,
                    )?;
                    sum += loss.to_f64();
                }
                Ok(sum)
            })
            .collect();
        let mut total = 0.0;
        for loss in losses {
            total += loss?;
        }
        let scale = 1.0 / chunk.len() as f32;
        self.network.zero_grad();
        for worker in &mut self.workers {
            let mut grads = Vec::new();
            worker
                .network
                .visit_params("", &mut |_, p| grads.push(p.grad.to_owned()));
            let mut grads = grads.into_iter();
            self.network.visit_params("", &mut |_, mut p| {
                let g = grads.next().expect("same network layout");
                p.grad.scaled_add(scale, &g);
            });
        }
        self.average_buffers();
        self.optimizer.step(&mut self.network)?;
        self.broadcast();
        Ok(total / chunk.len() as f64)
    }

    /// Sets the main network's batch-norm running statistics to the workers' mean.
    fn average_buffers(&mut self) {
        let scale = 1.0 / self.workers.len() as f32;
        let mut sums = Vec::new();
        for (k, worker) in self.workers.iter_mut().enumerate() {
            let mut n = 0;
            worker.network.visit_buffers("", &mut |_, b| {
                if k == 0 {
                    sums.push(b.mapv(|v| v * scale));
                } else {
                    sums[n].scaled_add(scale, &b);
                }
                n += 1;
            });
        }
        let mut sums = sums.into_iter();
        self.network.visit_buffers("", &mut |_, mut b| {
            b.assign(&sums.next().expect("same network layout"))
        });
    }

    /// Copies the main network's weights and buffers into every worker.
    fn broadcast(&mut self) {
        for worker in &mut self.workers {
            worker.network.clone_from(&self.network);
        }
    }

    /// Validation of `epoch` on the pairs of `shapes` (seeded like test pairs): loss and
    /// matching accuracy of C̃, and the test-time procedure's metrics.
    fn validate(
        &mut self,
        generator: &PairGenerator,
        shapes: &[&Shape],
        epoch: usize,
    ) -> Result<Validation> {
        let total = shapes.len();
        let workers = self.workers.len();
        let match_points = self.config.match_points;
        let test_statistics = self.config.test_statistics;
        let precision = self.config.precision;
        let parts: Vec<Result<ValidationPart>> = self
            .workers
            .par_iter_mut()
            .enumerate()
            .map(|(w, worker)| {
                worker.network.featurer.test_statistics = test_statistics;
                let mut method = Method::Rgm(Box::new(RgmRegistrar::new(
                    worker.network.clone(),
                    PipelineConfig {
                        precision,
                        ..PipelineConfig::default()
                    },
                )));
                let mut part = ValidationPart::default();
                for i in (w..total).step_by(workers) {
                    let full = generator.test_pair(shapes, i)?;
                    let pair = match match_points {
                        Some(points) => {
                            full.subsampled(points, &mut StdRng::seed_from_u64(!(i as u64)))
                        }
                        None => full.clone(),
                    };
                    let gt = ground_truth(&pair)?;
                    let (x, y) = (as_rows(&pair.source), as_rows(&pair.target));
                    worker
                        .network
                        .forward(x.view(), y.view(), Mode::Eval, &mut worker.cache)?;
                    let c = worker.cache.c_soft();
                    part.loss_sum += bce_forward(c, &gt)?.to_f64();
                    part.hits += gt
                        .pairs()
                        .iter()
                        .filter(|&&(i, j)| {
                            let row = c.row(i);
                            let best = row.iter().enumerate().fold(
                                (0, f32::NEG_INFINITY),
                                |a, (k, &v)| if v > a.1 { (k, v) } else { a },
                            );
                            best.0 == j
                        })
                        .count();
                    part.matched += gt.pairs().len();
                    let record = evaluate_pair(&mut method, i, &pair)?;
                    if record.failure.is_none() {
                        part.refined += refined_recall(&full, &record.transform)? as usize;
                    }
                    part.records.push(record);
                }
                Ok(part)
            })
            .collect();
        let mut all = ValidationPart::default();
        for part in parts {
            let part = part?;
            all.records.extend(part.records);
            all.loss_sum += part.loss_sum;
            all.hits += part.hits;
            all.matched += part.matched;
            all.refined += part.refined;
        }
        let summary = Summary::from_records(&all.records)?;
        let (loss, hits, matched) = (all.loss_sum / total as f64, all.hits, all.matched);
        let m = summary.metrics;
        Ok(Validation {
            epoch,
            pairs: total,
            sample: self.config.val_sample,
            loss,
            match_accuracy: hits as f64 / matched.max(1) as f64,
            mie_r_deg: m.mie_r_deg,
            mie_t: m.mie_t,
            mae_r_deg: m.mae_r_deg,
            mae_t: m.mae_t,
            recall: m.recall,
            recall_refined: all.refined as f64 / total as f64,
            refined_with: Refinement::PlaneThenPoint,
            failures: summary.failures,
        })
    }

    /// Appends `record` to `log.jsonl` (one file operation).
    fn log(&mut self, record: &LogRecord) -> Result<()> {
        let path = self.dir.join("log.jsonl");
        let line = serde_json::to_string(record).map_err(|source| TrainError::Json {
            path: path.clone(),
            source,
        })?;
        self.file_operation()?;
        let mut file = fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(io_err(&path))?;
        writeln!(file, "{line}").map_err(io_err(&path))
    }

    /// Saves the run as one commit (see the module's documentation): weights, optimiser and
    /// state, and the weights as `best.safetensors` when `new_best`.
    fn checkpoint(&mut self, new_best: bool) -> Result<()> {
        let log = self.dir.join("log.jsonl");
        self.state.log_bytes = Some(fs::metadata(&log).map_err(io_err(&log))?.len());
        let staging = self.dir.join(STAGING);
        self.file_operation()?;
        if staging.exists() {
            fs::remove_dir_all(&staging).map_err(io_err(&staging))?;
        }
        fs::create_dir(&staging).map_err(io_err(&staging))?;
        self.file_operation()?;
        rgm_nn::io::save_params(&staging.join("last.safetensors"), &mut self.network)?;
        self.file_operation()?;
        self.optimizer
            .save(&staging.join("last.optim.safetensors"))?;
        if new_best {
            self.file_operation()?;
            rgm_nn::io::save_params(&staging.join("best.safetensors"), &mut self.network)?;
        }
        self.file_operation()?;
        write_json(&staging.join("state.json"), &self.state)?;
        // On disk before the commit, so that it holds after a power cut too, not only a kill.
        for name in CHECKPOINT_FILES {
            let path = staging.join(name);
            if path.exists() {
                sync(&path)?;
            }
        }
        sync(&staging)?;
        // The commit.
        self.file_operation()?;
        let committed = self.dir.join(COMMITTED);
        fs::rename(&staging, &committed).map_err(io_err(&committed))?;
        sync(&self.dir)?;
        let dir = self.dir.clone();
        finish_commit(&dir, &mut || self.file_operation())
    }

    /// Counts one file operation of a checkpoint, failing it when it is the one chosen by
    /// [`Trainer::fail_at_file_operation`].
    fn file_operation(&mut self) -> Result<()> {
        self.file_operations += 1;
        if self.fail_at == Some(self.file_operations) {
            return Err(TrainError::Io {
                path: self.dir.clone(),
                source: std::io::Error::other(format!(
                    "failure injected at file operation {}",
                    self.file_operations
                )),
            });
        }
        Ok(())
    }

    /// Makes the `n`-th file operation (from 1) of this trainer's checkpoints and log fail as
    /// if the process had been killed just before it, for the tests that interrupt a run at
    /// every step of its checkpoints in turn.
    #[doc(hidden)]
    pub fn fail_at_file_operation(&mut self, n: usize) {
        self.fail_at = Some(n);
    }

    /// The file operations of checkpoints and log so far (what
    /// [`Trainer::fail_at_file_operation`] counts).
    #[doc(hidden)]
    pub fn file_operations(&self) -> usize {
        self.file_operations
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_data::Correspondence;
    use rgm_geom::euler::rotation_xyz_intrinsic;
    use rgm_geom::{Point3, PointCloud, Vector3};

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
        assert!(!sharper.beats(&before) && before.beats(&sharper));
        // Alike, the refined recall decides.
        let alike = Validation {
            refined_with: Refinement::TrimmedPointToPlane,
            ..sharper
        };
        assert!(alike.beats(&before));
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
        assert!(spread.beats(&first));
        // On the same sample the numbers decide again.
        let next = Validation {
            epoch: 26,
            recall: 0.28,
            ..spread
        };
        assert!(!next.beats(&spread) && spread.beats(&next));
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
}
