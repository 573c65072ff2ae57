//! What defines a training run: [`TrainConfig`], saved as `config.json` in the run folder.

use std::path::{Path, PathBuf};

use rgm_data::{Setting, Shape};
use rgm_nn::optim::{Adam, Optimizer, Sgd};
use rgm_nn::Precision;
use serde::{Deserialize, Serialize};

use super::{Result, TrainError};
use crate::network::{Config, TestStatistics};

/// The optimiser of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum OptimizerKind {
    /// SGD with Nesterov momentum, as the reference code (spec §3).
    Sgd,
    /// Adam (β 0.9, 0.999).
    Adam,
}

impl OptimizerKind {
    /// A fresh optimiser of this kind with `config`'s hyper-parameters.
    pub(super) fn fresh(self, config: &TrainConfig) -> Box<dyn Optimizer<f32>> {
        match self {
            Self::Sgd => {
                let mut sgd = Sgd::new(config.lr, config.momentum, config.weight_decay);
                sgd.nesterov = true; // as the reference sets it (spec §3)
                Box::new(sgd)
            }
            Self::Adam => Box::new(Adam::new(config.lr, config.weight_decay)),
        }
    }

    /// The optimiser of this kind saved at `path`.
    pub(super) fn load(self, path: &Path) -> Result<Box<dyn Optimizer<f32>>> {
        Ok(match self {
            Self::Sgd => Box::new(Sgd::<f32>::load(path)?),
            Self::Adam => Box::new(Adam::<f32>::load(path)?),
        })
    }
}

/// Everything that defines a training run; saved as `config.json` in the run folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// The pair protocol (spec §1).
    #[serde(with = "crate::by_name")]
    pub setting: Setting,
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
    /// how a [`super::Validation`] beats another). Runs saved before the field validated on
    /// the first ones.
    #[serde(default)]
    pub val_sample: ValSample,
    /// Which validation figure picks the run's best checkpoint. Only which checkpoint is kept
    /// depends on it: it may change on resume. Runs saved before the field picked by
    /// [`BestBy::Refined`].
    #[serde(default)]
    pub best_by: BestBy,
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
    #[serde(default, with = "crate::by_name")]
    pub precision: Precision,
    /// Weights a new run starts from instead of the seeded initialisation (fine-tuning, e.g.
    /// the noise model from the partial one). Only the start: a resumed run loads its own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init: Option<PathBuf>,
}

/// The network sizes `rgm train` trains by default ([`Config::preset`]): the built-in model's.
pub const DEFAULT_PRESET: &str = "fast";

impl Default for TrainConfig {
    /// What `rgm train` runs when given no option, the built-in model's recipe: the paper's
    /// schedule on partial pairs with the [`DEFAULT_PRESET`] sizes, each cloud cut to 384 points
    /// for matching, validated with each cloud's own batch-norm statistics (as it trains).
    fn default() -> Self {
        let network = Config::preset(DEFAULT_PRESET).expect("a known preset");
        Self {
            match_points: Some(384),
            test_statistics: TestStatistics::Cloud,
            ..Self::paper(Setting::Partial, network)
        }
    }
}

impl TrainConfig {
    /// The paper's schedule (spec §3: SGD, momentum 0.9, lr 1e-3, batch 4, 200 epochs, ×0.2 at
    /// 120 and 140) for `setting` with `network`'s sizes, on both cores.
    pub fn paper(setting: Setting, network: Config) -> Self {
        Self {
            setting,
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
            best_by: BestBy::Refined,
            workers: 2,
            checkpoint_every: 50,
            seed: 0,
            test_statistics: TestStatistics::Running,
            precision: Precision::F32,
            init: None,
        }
    }

    pub(super) fn validate(&self) -> Result<()> {
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
    /// number of epochs (a run may be extended) and what only validation, the kept best or
    /// speed depends on (batch-norm statistics at validation, its sample, the figure that picks
    /// the best, the products' precision).
    pub(super) fn same_run(&self, saved: &Self) -> bool {
        Self {
            epochs: saved.epochs,
            test_statistics: saved.test_statistics,
            val_sample: saved.val_sample,
            best_by: saved.best_by,
            precision: saved.precision,
            ..self.clone()
        } == *saved
    }
}

/// Which validation shapes a run validates on when it takes fewer than all of them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
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

/// The validation figure that picks a run's best checkpoint (ties go to the lower loss).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum BestBy {
    /// The recall after refinement, then the network's own: the model a registration refines
    /// (the shipped one's use).
    #[default]
    Refined,
    /// The network's own recall, what the paper's tables score: a checkpoint a few points
    /// better alone may register one pair fewer once refined.
    Alone,
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
