//! `cargo xtask snapshot-runs`: makes the training runs under `runs/` small enough to commit.
//!
//! Each run's Adam state (`last.optim.safetensors`) keeps only its second moments (`v.*`), in
//! bf16: a quarter of the f32 file. The weights stay f32. A run resumed from such a snapshot
//! restarts the first moments from zero (`rgm_nn::optim::Adam::load`) and continues from second
//! moments rounded to 8 bits of mantissa: inexact by design (the f32 files a run writes while
//! it trains resume bit for bit). A state that is already a snapshot is left as it is. A run
//! that is training (its folder's lock is held) is left
//! alone and named.

use std::fs;
use std::path::Path;

use anyhow::{Context, Result};

use crate::project_root;

/// Options of `cargo xtask snapshot-runs`.
#[derive(clap::Args, Debug)]
pub struct Args {}

pub fn run(_: Args) -> Result<()> {
    let runs = project_root().join("runs");
    let mut folders: Vec<_> = fs::read_dir(&runs)
        .with_context(|| format!("reading {}", runs.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("last.optim.safetensors").is_file())
        .collect();
    folders.sort();
    for folder in folders {
        snapshot(&folder)?;
    }
    Ok(())
}

/// Rewrites the run in `folder` for a commit, unless it is training.
fn snapshot(folder: &Path) -> Result<()> {
    let lock = folder.join("lock");
    if lock.exists() {
        let file = fs::File::open(&lock)?;
        if file.try_lock().is_err() {
            println!(
                "{}: training now (its lock is held); stop it first",
                folder.display()
            );
            return Ok(());
        }
    }
    let optim = folder.join("last.optim.safetensors");
    let staged = folder.join("last.optim.safetensors.bf16.tmp");
    let before = fs::metadata(&optim)?.len();
    let (tensors, metadata) = rgm_nn::io::read_tensors::<f32>(&optim)
        .with_context(|| format!("reading {}", optim.display()))?;
    if !tensors.keys().any(|name| name.starts_with("m.")) {
        // Already a snapshot (a training run always writes its first moments): rewriting it
        // would make new bytes, and a new blob in git, for the same state.
        println!("{}: already a snapshot", folder.display());
        return Ok(());
    }
    let mut kept: Vec<_> = tensors
        .iter()
        .filter(|(name, _)| !name.starts_with("m."))
        .map(|(name, t)| (name.clone(), t.view()))
        .collect();
    kept.sort_by(|a, b| a.0.cmp(&b.0));
    rgm_nn::io::write_tensors_with_bf16(&staged, &kept, metadata, &|name| name.starts_with("v."))
        .with_context(|| format!("writing {}", staged.display()))?;
    fs::rename(&staged, &optim)?;
    println!(
        "{}: Adam state as its second moments in bf16 ({:.1} → {:.1} MB)",
        folder.display(),
        before as f64 / 1e6,
        fs::metadata(&optim)?.len() as f64 / 1e6
    );
    Ok(())
}
