//! `cargo xtask snapshot-runs`: makes the training runs under `runs/` small enough to commit.
//!
//! A snapshot keeps a run resumable at a quarter to half of its training files' size:
//! - the weights (`last.safetensors`, `best.safetensors`) rounded to bf16 (half the bytes),
//!   except a file whose bytes git already stores (e.g. the built-in model, which is a run's
//!   `best`): it costs nothing and stays as it is;
//! - of the Adam state (`last.optim.safetensors`) only the second moments (`v.*`), one byte
//!   each on a logarithmic scale (`rgm_nn::io::Storage::Log8`, each value within about 6 %):
//!   an eighth of the f32 file; none at all for a run named `--finished` (one that has reached
//!   the last target the queue gives it), which restarts Adam if it is ever extended.
//!
//! A run resumed from a snapshot continues from rounded weights (bf16 keeps 8 bits of mantissa:
//! a relative change of at most 2⁻⁹, below one Adam step at 3e-4 on weights of ≈ 0.05), with
//! the first moments restarted from zero (`rgm_nn::optim::Adam::load`) and the second ones
//! rounded to a few percent (the step size they set, to half that): inexact by design,
//! while the f32 files a run writes while it trains resume bit for bit. A model named in the
//! manifest by a path into a run is the rounded `best`, and is evaluated as such. Files that are
//! already a snapshot are left as they are (rewriting would make new bytes, a new blob in git,
//! for the same values). A run that is training (its folder's lock is held) is left alone and
//! named.

use std::collections::{HashMap, HashSet};
use std::fs;
use std::path::Path;
use std::process::Command;

use anyhow::{bail, Context, Result};
use rgm_data::durable::LockError;
use rgm_nn::io::Storage;

use crate::project_root;

/// Options of `cargo xtask snapshot-runs`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Runs (folder names under runs/) that have reached the last target the queue gives
    /// them: their Adam state is left out of the snapshot.
    #[arg(long, value_name = "RUN", num_args = 1..)]
    finished: Vec<String>,
}

pub fn run(args: Args) -> Result<()> {
    let runs = project_root().join("runs");
    let mut folders: Vec<_> = fs::read_dir(&runs)
        .with_context(|| format!("reading {}", runs.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("state.json").is_file())
        .collect();
    folders.sort();
    for name in &args.finished {
        if !folders
            .iter()
            .any(|f| f.file_name().is_some_and(|n| n == name.as_str()))
        {
            bail!(
                "--finished {name}: no run folder {}",
                runs.join(name).display()
            );
        }
    }
    let committed = Committed::read()?;
    for folder in folders {
        let finished = args
            .finished
            .iter()
            .any(|n| folder.file_name().is_some_and(|f| f == n.as_str()));
        snapshot(&folder, finished, &committed)?;
    }
    Ok(())
}

/// Rewrites the run in `folder` for a commit, unless it is training.
fn snapshot(folder: &Path, finished: bool, committed: &Committed) -> Result<()> {
    // Held while the run is rewritten, so that no training starts on it meanwhile.
    let lock = folder.join("lock");
    let _held = match rgm_data::durable::lock(&lock, fs::OpenOptions::new().read(true)) {
        Err(LockError::Busy) => {
            println!(
                "{}: training now (its lock is held); stop it first",
                folder.display()
            );
            return Ok(());
        }
        Err(LockError::Io(error)) if error.kind() == std::io::ErrorKind::NotFound => None,
        Err(LockError::Io(error)) => {
            return Err(error).context(format!("locking {}", lock.display()))
        }
        Ok(file) => Some(file),
    };
    let last = folder.join("last.safetensors");
    if !last.is_file() {
        // A retired run whose weights left the tree (the history holds them): its log and
        // state are all there is to commit.
        println!(
            "{}: no weights in the tree, left as it is",
            folder.display()
        );
        return Ok(());
    }
    let best = folder.join("best.safetensors");
    let same = best.is_file() && fs::read(&last)? == fs::read(&best)?;
    round_weights(&last, committed)?;
    if same {
        // One rounding for both, so that git keeps one blob.
        fs::copy(&last, &best)?;
    } else if best.is_file() {
        round_weights(&best, committed)?;
    }
    let optim = folder.join("last.optim.safetensors");
    if finished {
        if optim.exists() {
            fs::remove_file(&optim)?;
            println!("{}: finished, Adam state left out", folder.display());
        }
    } else if optim.exists() {
        keep_second_moments(&optim)?;
    }
    Ok(())
}

/// The blobs the commits of every branch hold: a file with the bytes of one of them costs
/// nothing to commit (a blob that only sits in git's object store, e.g. staged once, is not
/// one of them).
struct Committed(HashSet<String>);

impl Committed {
    fn read() -> Result<Self> {
        let objects = git(&["rev-list".as_ref(), "--objects".as_ref(), "--all".as_ref()])?;
        let ids = objects.lines().filter_map(|l| l.split(' ').next());
        Ok(Self(ids.map(String::from).collect()))
    }

    fn holds(&self, path: &Path) -> Result<bool> {
        let id = git(&["hash-object".as_ref(), "--".as_ref(), path.as_os_str()])?;
        Ok(self.0.contains(id.trim()))
    }
}

/// The output of git with `args`, run in the repository.
fn git(args: &[&std::ffi::OsStr]) -> Result<String> {
    let out = Command::new("git")
        .args(args)
        .current_dir(project_root())
        .output()
        .context("running git")?;
    if !out.status.success() {
        bail!(
            "git {:?} failed: {}",
            args,
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Rounds the weights in `path` to bf16, unless git stores these bytes already or they are
/// rounded already.
fn round_weights(path: &Path, committed: &Committed) -> Result<()> {
    if committed.holds(path)? {
        println!("{}: in git already, left as it is", path.display());
        return Ok(());
    }
    let (tensors, metadata) = read(path)?;
    if tensors
        .values()
        .flatten()
        .all(|v| v.to_bits() & 0xFFFF == 0)
    {
        println!("{}: already a snapshot", path.display());
        return Ok(());
    }
    rewrite(path, &tensors, metadata, &|_| true, &|_| Storage::Bf16)
}

/// Keeps of the Adam state in `optim` only its second moments, in [`Storage::Log8`].
fn keep_second_moments(optim: &Path) -> Result<()> {
    let (tensors, metadata) = read(optim)?;
    if !tensors.keys().any(|name| name.starts_with("m.")) {
        // A training run always writes its first moments: this is a snapshot already.
        println!("{}: already a snapshot", optim.display());
        return Ok(());
    }
    rewrite(
        optim,
        &tensors,
        metadata,
        &|name| !name.starts_with("m."),
        &|name| {
            if name.starts_with("v.") {
                Storage::Log8
            } else {
                Storage::Native
            }
        },
    )
}

type Tensors = rgm_nn::io::Tensors<f32>;

fn read(path: &Path) -> Result<(Tensors, HashMap<String, String>)> {
    rgm_nn::io::read_tensors::<f32>(path).with_context(|| format!("reading {}", path.display()))
}

/// Rewrites the safetensors file `path` (through a staged file and a rename) with the tensors
/// `keep` accepts, each stored as `storage` says.
fn rewrite(
    path: &Path,
    tensors: &Tensors,
    metadata: HashMap<String, String>,
    keep: &dyn Fn(&str) -> bool,
    storage: &dyn Fn(&str) -> Storage,
) -> Result<()> {
    let before = fs::metadata(path)?.len();
    let mut kept: Vec<_> = tensors
        .iter()
        .filter(|(name, _)| keep(name))
        .map(|(name, t)| (name.clone(), t.view()))
        .collect();
    kept.sort_by(|a, b| a.0.cmp(&b.0));
    rgm_data::durable::replace_via(path, |staged| {
        rgm_nn::io::write_tensors_stored(staged, &kept, metadata, storage)
            .with_context(|| format!("writing {}", staged.display()))
    })?;
    println!(
        "{}: rewritten for a snapshot ({:.1} → {:.1} MB)",
        path.display(),
        before as f64 / 1e6,
        fs::metadata(path)?.len() as f64 / 1e6
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::ArrayD;

    fn write(path: &Path, tensors: &[(&str, Vec<f32>)]) {
        let arrays: Vec<(String, ArrayD<f32>)> = tensors
            .iter()
            .map(|(n, v)| {
                (
                    n.to_string(),
                    ArrayD::from_shape_vec(vec![v.len()], v.clone()).unwrap(),
                )
            })
            .collect();
        let views: Vec<_> = arrays.iter().map(|(n, a)| (n.clone(), a.view())).collect();
        rgm_nn::io::write_tensors(path, &views, HashMap::new()).unwrap();
    }

    /// A run folder whose `last` and `best` are the same f32 weights (values between bf16's).
    fn run_folder(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("rgm-snapshot-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        fs::write(dir.join("state.json"), "{}").unwrap();
        let weights = [("w", vec![1.0 + 2f32.powi(-10), -0.3, 1e-3])];
        write(&dir.join("last.safetensors"), &weights);
        write(&dir.join("best.safetensors"), &weights);
        let moments = [
            ("m.w", vec![0.1; 3]),
            ("v.w", vec![0.2 + 2f32.powi(-12); 3]),
        ];
        write(&dir.join("last.optim.safetensors"), &moments);
        dir
    }

    #[test]
    fn a_snapshot_rounds_the_weights_once_and_keeps_the_second_moments() {
        let dir = run_folder("going-on");
        snapshot(&dir, false, &Committed::read().unwrap()).unwrap();
        let (last, _) = read(&dir.join("last.safetensors")).unwrap();
        assert_eq!(
            last["w"].as_slice().unwrap(),
            &[1.0, -0.30078125, 131.0 / 131_072.0] // bf16 of 1e-3: 131 · 2⁻¹⁷
        );
        let bytes = |name: &str| fs::read(dir.join(name)).unwrap();
        assert_eq!(bytes("last.safetensors"), bytes("best.safetensors"));
        let (optim, _) = read(&dir.join("last.optim.safetensors")).unwrap();
        assert_eq!(optim.keys().collect::<Vec<_>>(), ["v.w"]);
        // One value: the log8 range is that value, which comes back exactly.
        assert!((optim["v.w"][0] / (0.2 + 2f32.powi(-12)) - 1.0).abs() < 1e-6);
        // A second snapshot leaves the files byte for byte.
        let before = (bytes("last.safetensors"), bytes("last.optim.safetensors"));
        snapshot(&dir, false, &Committed::read().unwrap()).unwrap();
        assert_eq!(
            before,
            (bytes("last.safetensors"), bytes("last.optim.safetensors"))
        );
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_retired_run_without_weights_is_left_as_it_is() {
        let dir = run_folder("retired");
        for file in ["last.safetensors", "best.safetensors"] {
            fs::remove_file(dir.join(file)).unwrap();
        }
        snapshot(&dir, true, &Committed::read().unwrap()).unwrap();
        assert!(dir.join("last.optim.safetensors").exists());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_finished_run_is_snapshot_without_its_adam_state() {
        let dir = run_folder("finished");
        snapshot(&dir, true, &Committed::read().unwrap()).unwrap();
        assert!(!dir.join("last.optim.safetensors").exists());
        assert!(dir.join("best.safetensors").exists());
        fs::remove_dir_all(&dir).unwrap();
    }
}
