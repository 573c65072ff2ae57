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
//! Pairs are made on the fly ([`rgm_data::PairGenerator::train_pair`], a new random pose, crop and noise
//! every epoch), optionally cut to [`TrainConfig::match_points`] points per cloud. A batch is
//! spread over [`TrainConfig::workers`] threads, each with its own copy of the network; their
//! gradients are summed into the main network, which takes the step and hands its weights back.
//! Batch norm uses each cloud's own statistics (as in a batch of one); the workers' running
//! statistics are averaged after every batch.
//!
//! The module's rooms: [`config`] (what defines a run), `run_dir` (the folder: lock, atomic
//! commit, recovery), `trainer` (the loop: batches, workers, optimiser steps, checkpoints) and
//! [`validation`] (the result of an epoch and how two compare).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::network::NetworkError;

pub mod config;
mod run_dir;
#[cfg(test)]
mod tests;
mod trainer;
pub mod validation;

pub use config::{BestBy, OptimizerKind, TrainConfig, ValSample, DEFAULT_PRESET};
pub use trainer::Trainer;
pub use validation::{Refinement, Validation};

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
