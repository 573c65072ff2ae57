//! `rgm score`: the paper's metrics for transforms an outside tool found on the pairs that
//! `rgm pairs` wrote, so any method is scored by the same code as rgm's own.
//!
//! The transforms file: `{"method": NAME, "pairs": [{"index": i, "transform": 4×4 rows,
//! "time_ms": t}, …]}`. On a folder of real scan pairs (`rgm pairs --scans`), the scores are
//! those of `rgm eval --scans`.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use rgm_data::{read_point_cloud, Correspondence, Pair, ScanPair};
use rgm_geom::{Matrix4, RigidTransform};
use rgm_model::evaluate::{scan_table_header, scan_table_row};
use rgm_model::{PairRecord, ScanRecord};
use serde::Deserialize;

use crate::table;

/// Options of `rgm score`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The outside tool's transforms (JSON; the format is under `rgm help score`).
    transforms: PathBuf,
    /// The folder written by `rgm pairs`.
    #[arg(long, value_name = "DIR")]
    pairs: PathBuf,
    /// Also write every pair's metrics to this JSON file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
}

#[derive(Deserialize)]
struct Transforms {
    method: String,
    pairs: Vec<Found>,
}

#[derive(Deserialize)]
struct Found {
    index: usize,
    transform: Vec<Vec<f64>>, // (4, 4), checked by `rigid`
    time_ms: f64,
}

#[derive(Deserialize)]
struct Manifest {
    /// ModelNet40 pairs only.
    setting: Option<String>,
    unseen: Option<bool>,
    /// Real scan pairs only: the scan folder's name.
    scans: Option<String>,
    pairs: Vec<Entry>,
}

#[derive(Deserialize)]
struct Entry {
    index: usize,
    /// ModelNet40 pairs only.
    label: Option<usize>,
    source: String,
    target: String,
    t_target_source: [[f64; 4]; 4],
    /// Real scan pairs only.
    #[serde(flatten)]
    scan: Option<ScanEntry>,
}

#[derive(Deserialize)]
struct ScanEntry {
    source_scan: String,
    target_scan: String,
    overlap: f64,
    diagonal: f64,
}

fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T> {
    let bytes = rgm_data::read_regular_file(path)?;
    serde_json::from_slice(&bytes)
        .with_context(|| format!("{} is not the expected JSON", path.display()))
}

/// Checks that `found` holds exactly one transform per pair of the manifest: a tool that
/// skipped hard pairs, or scored one twice, would otherwise score better than it is.
fn check_one_per_pair(found: &Transforms, manifest: &Manifest, args: &Args) -> Result<()> {
    let (file, pairs_json) = (args.transforms.display(), args.pairs.join("pairs.json"));
    let mut seen = BTreeSet::new();
    for f in &found.pairs {
        if !manifest.pairs.iter().any(|e| e.index == f.index) {
            bail!(
                "{file}: pair {} is not in {}",
                f.index,
                pairs_json.display()
            );
        }
        if !seen.insert(f.index) {
            bail!("{file}: pair {} has more than one transform", f.index);
        }
    }
    let missing: Vec<String> = manifest
        .pairs
        .iter()
        .filter(|e| !seen.contains(&e.index))
        .map(|e| e.index.to_string())
        .collect();
    if !missing.is_empty() {
        let shown = if missing.len() > 10 {
            format!("{}, …", missing[..10].join(", "))
        } else {
            missing.join(", ")
        };
        bail!(
            "{file}: {} of the {} pairs of {} have no transform (pairs {shown}); a method is \
             scored on every pair",
            missing.len(),
            manifest.pairs.len(),
            pairs_json.display()
        );
    }
    Ok(())
}

/// The rigid transform of `rows`, which must be 4 rows of 4 numbers; `what` names it in errors.
fn rigid<R: AsRef<[f64]>>(rows: &[R], what: &str) -> Result<RigidTransform> {
    let lengths: Vec<usize> = rows.iter().map(|r| r.as_ref().len()).collect();
    if lengths != [4; 4] {
        bail!("{what} has rows of {lengths:?} numbers; a transform is 4 rows of 4 numbers");
    }
    let m = Matrix4::from_fn(|r, c| rows[r].as_ref()[c]);
    RigidTransform::from_matrix4(&m, 1e-4).map_err(|e| anyhow!("{what}: {e}"))
}

pub fn run(args: Args) -> Result<()> {
    if let Some(json) = &args.json {
        crate::files::check_writable(json)?;
    }
    let found: Transforms = read_json(&args.transforms)?;
    let manifest: Manifest = read_json(&args.pairs.join("pairs.json"))?;
    if manifest.pairs.is_empty() {
        bail!(
            "{} lists no pairs: nothing to score",
            args.pairs.join("pairs.json").display()
        );
    }
    check_one_per_pair(&found, &manifest, &args)?;
    if let Some(f) = found
        .pairs
        .iter()
        .find(|f| !(f.time_ms >= 0.0 && f.time_ms.is_finite()))
    {
        bail!(
            "{}: pair {} has time_ms {:e}; a time is a number of milliseconds from 0 up",
            args.transforms.display(),
            f.index,
            f.time_ms
        );
    }
    if let Some(scans) = &manifest.scans {
        return score_scans(&args, &found, &manifest, scans);
    }
    let mut records = Vec::with_capacity(found.pairs.len());
    for (f, entry, transform) in matched(&args, &found, &manifest)? {
        let source = read_point_cloud(args.pairs.join(&entry.source))?;
        let target = read_point_cloud(args.pairs.join(&entry.target))?;
        let pair = Pair {
            correspondence: Correspondence {
                n_source: source.len(),
                n_target: target.len(),
                pairs: Vec::new(),
            },
            source,
            target,
            t_target_source: rigid(
                &entry.t_target_source,
                &format!("ground truth of pair {}", entry.index),
            )?,
            shape_index: entry.index,
            label: entry.label.unwrap_or_default(),
        };
        records.push(PairRecord::score(
            f.index, &pair, transform, f.time_ms, 0, None,
        )?);
    }
    let setting = format!(
        "{}{}",
        manifest.setting.as_deref().unwrap_or("?"),
        if manifest.unseen == Some(true) {
            "-unseen"
        } else {
            ""
        }
    );
    table::report(&found.method, &setting, &records, args.json.as_deref())?;
    Ok(())
}

/// Each found transform, checked as rigid, with its manifest entry ([`check_one_per_pair`]
/// has made sure there is one).
fn matched<'a>(
    args: &Args,
    found: &'a Transforms,
    manifest: &'a Manifest,
) -> Result<Vec<(&'a Found, &'a Entry, RigidTransform)>> {
    found
        .pairs
        .iter()
        .map(|f| {
            let entry = manifest
                .pairs
                .iter()
                .find(|e| e.index == f.index)
                .expect("checked by check_one_per_pair");
            let what = format!(
                "{}: transform of pair {}",
                args.transforms.display(),
                f.index
            );
            Ok((f, entry, rigid(&f.transform, &what)?))
        })
        .collect()
}

/// `rgm score` on real scan pairs: the row `rgm eval --scans` prints.
fn score_scans(args: &Args, found: &Transforms, manifest: &Manifest, scans: &str) -> Result<()> {
    let mut records = Vec::with_capacity(found.pairs.len());
    for (f, entry, transform) in matched(args, found, manifest)? {
        let scan = entry.scan.as_ref().with_context(|| {
            format!(
                "{}: pair {} lacks source_scan, target_scan, overlap or diagonal",
                args.pairs.join("pairs.json").display(),
                entry.index
            )
        })?;
        let pair = ScanPair {
            index: entry.index,
            source_name: scan.source_scan.clone(),
            target_name: scan.target_scan.clone(),
            source: read_point_cloud(args.pairs.join(&entry.source))?,
            target: read_point_cloud(args.pairs.join(&entry.target))?,
            t_target_source: rigid(
                &entry.t_target_source,
                &format!("ground truth of pair {}", entry.index),
            )?,
            overlap: scan.overlap,
            diagonal: scan.diagonal,
        };
        // A tool scored here reports no doubt: each of its results is taken as trusted.
        records.push(ScanRecord::score(&pair, &transform, true, f.time_ms, None));
    }
    // The file first: output that cannot be printed (a full disk) loses no result.
    if let Some(path) = &args.json {
        let value = serde_json::json!({"method": found.method, "scans": scans, "pairs": records});
        crate::files::write_text(path, &serde_json::to_string_pretty(&value)?)?;
    }
    rgm_cli::outln!("{}", scan_table_header())?;
    if let Some(row) = scan_table_row(&found.method, scans, &records) {
        rgm_cli::outln!("{row}")?;
    }
    if let Some(path) = &args.json {
        rgm_cli::outln!("wrote per-pair results to {}", path.display())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_tests::mutation::{corpus, Fuzz};

    /// The transforms file as `run` reads it: JSON, then every transform checked as rigid.
    fn read_transforms(bytes: &[u8]) -> Result<Vec<RigidTransform>> {
        let found: Transforms = serde_json::from_slice(bytes)?;
        found
            .pairs
            .iter()
            .map(|f| rigid(&f.transform, "fuzz"))
            .collect()
    }

    #[test]
    fn the_transforms_file_reads_and_survives_fuzzing() {
        let seeds = corpus(&["transforms.json"]);
        assert_eq!(read_transforms(&seeds[0]).unwrap().len(), 2);
        Fuzz::default().run("score", &seeds, |b| {
            let _ = read_transforms(b);
        });
    }
}
