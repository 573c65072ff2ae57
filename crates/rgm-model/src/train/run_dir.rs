//! The run folder as a store: one trainer at a time (its lock), checkpoints as atomic commits,
//! and recovery to the last commit after a kill (see the module documentation of
//! [`crate::train`]).

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use rgm_data::durable::{self, LockError};
use serde::{Deserialize, Serialize};

use super::{Result, TrainError, TrainState};

pub(super) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> TrainError + '_ {
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
const LOG: &str = "log.jsonl";

/// A file of a checkpoint: its name and what writes it to a given path.
pub(super) type CheckpointFile<'a> = (&'a str, &'a dyn Fn(&Path) -> Result<()>);

/// A run folder held by this process: its lock lives as long as the value.
pub(super) struct RunDir {
    path: PathBuf,
    _lock: fs::File,
    /// The file operations of checkpoints and log so far, and the one to fail.
    #[cfg(test)]
    pub(super) faults: Faults,
}

/// Failures injected into a run's file operations, for the tests that interrupt a run at every
/// step of its checkpoints in turn.
#[cfg(test)]
#[derive(Default)]
pub(super) struct Faults {
    /// File operations so far.
    pub(super) operations: usize,
    /// The operation (from 1) that fails as if the process had been killed just before it.
    pub(super) fail_at: Option<usize>,
}

impl RunDir {
    /// Takes the exclusive lock of the folder `path` (created if missing), failing with the
    /// process that holds it, and brings the folder to its last commit. Returns the committed
    /// state too (None for a new run).
    pub(super) fn open(path: &Path) -> Result<(Self, Option<TrainState>)> {
        let lock = lock_run(path)?;
        let state = recover(path)?;
        let dir = Self {
            path: path.to_path_buf(),
            _lock: lock,
            #[cfg(test)]
            faults: Faults::default(),
        };
        Ok((dir, state))
    }

    /// The path of the run's file `name`.
    pub(super) fn file(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }

    /// Appends `line` to `log.jsonl` (one file operation).
    pub(super) fn append_log(&mut self, line: &str) -> Result<()> {
        let path = self.file(LOG);
        self.file_operation()?;
        let mut file = fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(io_err(&path))?;
        writeln!(file, "{line}").map_err(io_err(&path))
    }

    /// Saves a checkpoint as one commit: `files` (name, writer) and `state`, with the log's
    /// length recorded in it, written into the staging folder, flushed to the disk, committed
    /// by one rename and moved over the run's own files.
    pub(super) fn checkpoint(
        &mut self,
        state: &mut TrainState,
        files: &[CheckpointFile<'_>],
    ) -> Result<()> {
        let log = self.file(LOG);
        state.log_bytes = Some(fs::metadata(&log).map_err(io_err(&log))?.len());
        let staging = self.file(STAGING);
        self.file_operation()?;
        if staging.exists() {
            fs::remove_dir_all(&staging).map_err(io_err(&staging))?;
        }
        fs::create_dir(&staging).map_err(io_err(&staging))?;
        for (name, write) in files {
            debug_assert!(CHECKPOINT_FILES.contains(name), "{name}");
            self.file_operation()?;
            write(&staging.join(name))?;
        }
        self.file_operation()?;
        write_json(&staging.join("state.json"), state)?;
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
        let committed = self.file(COMMITTED);
        fs::rename(&staging, &committed).map_err(io_err(&committed))?;
        sync(&self.path)?;
        let path = self.path.clone();
        finish_commit(&path, &mut || self.file_operation())
    }

    /// Counts one file operation of a checkpoint or the log; in tests, fails the one chosen
    /// by [`Faults::fail_at`].
    fn file_operation(&mut self) -> Result<()> {
        #[cfg(test)]
        {
            self.faults.operations += 1;
            if self.faults.fail_at == Some(self.faults.operations) {
                return Err(TrainError::Io {
                    path: self.path.clone(),
                    source: std::io::Error::other(format!(
                        "failure injected at file operation {}",
                        self.faults.operations
                    )),
                });
            }
        }
        Ok(())
    }
}

/// Takes the exclusive lock of the run folder `dir` (created if missing) and writes this
/// process's id into it; fails naming the process that holds it.
fn lock_run(dir: &Path) -> Result<fs::File> {
    fs::create_dir_all(dir).map_err(io_err(dir))?;
    let path = dir.join("lock");
    let options = fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .clone();
    let mut file = durable::lock(&path, &options).map_err(|error| match error {
        LockError::Busy => TrainError::Busy {
            dir: dir.to_path_buf(),
            pid: fs::read_to_string(&path)
                .unwrap_or_default()
                .trim()
                .to_string(),
        },
        LockError::Io(error) => io_err(&path)(error),
    })?;
    file.set_len(0).map_err(io_err(&path))?;
    writeln!(file, "{}", std::process::id()).map_err(io_err(&path))?;
    Ok(file)
}

/// Flushes the file or folder at `path` to the disk.
fn sync(path: &Path) -> Result<()> {
    durable::sync(path).map_err(io_err(path))
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
    let log = dir.join(LOG);
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

/// Writes `value` as JSON to `path`, replacing it whole ([`durable::replace`]).
pub(super) fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|source| TrainError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    durable::replace(path, |out| out.write_all(text.as_bytes())).map_err(io_err(path))
}

pub(super) fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let text = fs::read_to_string(path).map_err(io_err(path))?;
    serde_json::from_str(&text).map_err(|source| TrainError::Json {
        path: path.to_path_buf(),
        source,
    })
}
