//! `rgm eval`: a method over the ModelNet40 test pairs, scored with the paper's metrics, over
//! real scan pairs (`--scans`), scored by success rates, median errors and time, or over scene
//! pairs (`--scenes`), scored by the 3DMatch criterion.

use std::path::{Path, PathBuf};

use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Result;
use indicatif::ProgressBar;
use rayon::prelude::*;
use rgm_data::scenes::{MAX_ROTATION_ERROR_DEG, MAX_TRANSLATION_ERROR};
use rgm_data::{SceneFolder, Turn};
use rgm_model::evaluate::{
    evaluate_pair, evaluate_scan_pair, evaluate_scene_pair, scan_table_header, scan_table_row,
    scene_table_header, scene_table_row, PairRecord, ScanRecord, SceneRecord,
};
use rgm_model::Method;

use crate::args::{DataArgs, MethodArgs, WorkerArgs};
use crate::{progress, table};

/// Options of `rgm eval`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    method: MethodArgs,
    #[command(flatten)]
    data: DataArgs,
    /// Scenes instead of ModelNet40: folders in the 3DMatch benchmark's layout (the fragments
    /// and a `gt.log` whose blocks `i j n` + 4×4 matrix map fragment j onto fragment i;
    /// fragment k is the file `cloud_bin_k` or `k`, of any format rgm reads), e.g.
    /// ../shared/data/scenes/redkitchen. Scored by the 3DMatch criterion (rotation error < 15°,
    /// translation error < 0.3 m) and median errors; also counted: results the method trusted
    /// (`registered`) that fail it. --every and --limit select among each folder's pairs. The
    /// method defaults to `rgm register`'s (auto, refined), not the paper's.
    #[arg(long, value_name = "DIR", num_args = 1.., conflicts_with = "scans")]
    scenes: Vec<PathBuf>,
    /// With --scenes: register each pair once per turn instead, its source first turned about
    /// its centroid by the known rotation DEG about the z axis (the vertical of LiDAR scans),
    /// or about the axis X,Y,Z: `--turns 0 90 180 90@1,1,1`.
    #[arg(long, value_name = "DEG[@X,Y,Z]", num_args = 1.., requires = "scenes")]
    turns: Vec<Turn>,
    /// Many scans at once instead: folders in the Stanford layout (as --scans), each scan moved
    /// by a random rigid motion (any angle about its centroid, a shift of up to half the
    /// object's diagonal) and the scans shuffled (seed 0), merged as `rgm merge` merges them
    /// (the method defaults to `rgm merge`'s: scene, refined), and each scan scored after the one rigid
    /// motion that best maps the merge's frame onto the `.conf` poses' (Kabsch over the
    /// scans' points): its rotation error and the RMS displacement of its points as a share
    /// of the object's diagonal, counted within 1° and 0.5 %; time. A folder in the 3DMatch
    /// layout (as --scenes: a gt.log) has the fragments its gt.log names merged as they are
    /// (each in its own frame), and each gt.log pair scored by the merge's pose of its source
    /// relative to its target, counted within 15° and 0.3.
    #[arg(long, value_name = "DIR", num_args = 1.., conflicts_with_all = ["scans", "scenes"])]
    multiway: Vec<PathBuf>,
    #[command(flatten)]
    merge: super::merge::MergeArgs,
    /// Also write every pair's transform and metrics to this JSON file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    #[command(flatten)]
    workers: WorkerArgs,
}

pub fn run(args: Args) -> Result<()> {
    if let Some(json) = &args.json {
        crate::files::check_writable(json)?;
    }
    // The paper's protocol is ModelNet40's; on scenes the default is `rgm register`'s, on many
    // scans `rgm merge`'s.
    let defaults = if !args.multiway.is_empty() {
        crate::args::Defaults::Merge
    } else if args.scenes.is_empty() {
        crate::args::Defaults::Paper
    } else {
        crate::args::Defaults::Register
    };
    let method = args.method.build(defaults)?;
    if !args.multiway.is_empty() {
        return super::eval_multiway::run(
            &args.multiway,
            &method,
            &args.merge.config()?,
            args.json.as_deref(),
        );
    }
    if !args.data.scans.is_empty() {
        return run_scans(&args, &method);
    }
    if !args.scenes.is_empty() {
        return run_scenes(&args, &method);
    }
    let (dataset, generator) = args.data.open()?;
    let (shapes, indices) = args.data.shapes(&dataset);
    let bar = progress(indices.len(), &method.name());
    let recalled = AtomicUsize::new(0);
    let pool = args.workers.pool()?;
    let records: Vec<PairRecord> = pool.install(|| {
        indices
            .par_iter()
            .map_init(
                || method.clone(),
                |method, &i| -> Result<PairRecord> {
                    let pair = generator.test_pair(&shapes, i)?;
                    let record = evaluate_pair(method, i, &pair)?;
                    let hits = recalled
                        .fetch_add(record.metrics.recall as usize, Ordering::Relaxed)
                        + record.metrics.recall as usize;
                    bar.inc(1);
                    bar.set_message(format!(
                        "recall {:.1}%",
                        100.0 * hits as f64 / bar.position() as f64
                    ));
                    Ok(record)
                },
            )
            .collect::<Result<_>>()
    })?;
    bar.finish_and_clear();
    table::report(
        &method.name(),
        &args.data.pairs_name(),
        &records,
        args.json.as_deref(),
    )?;
    Ok(())
}

/// `rgm eval --scans`: one table row per folder, and one for all when there are several.
fn run_scans(args: &Args, method: &Method) -> Result<()> {
    let folders = args.data.scan_pairs()?;
    let results = evaluate_folders(folders, method, &args.workers, |method, pair, bar| {
        let record = evaluate_scan_pair(method, pair);
        bar.inc(1);
        Ok(record)
    })?;
    let table = Table {
        header: scan_table_header(),
        row: scan_table_row,
        failed: |r: &ScanRecord| r.failure.is_some(),
        kind: "scans",
    };
    table.report(&method.name(), &results, args.json.as_deref())
}

/// `rgm eval --scenes`: one table row per folder (every turn of its pairs), and one for all when
/// there are several.
fn run_scenes(args: &Args, method: &Method) -> Result<()> {
    let names = crate::args::folder_names(&args.scenes, "--scenes")?;
    let folders: Vec<SceneFolder> = args
        .scenes
        .iter()
        .map(SceneFolder::open)
        .collect::<Result<_, _>>()?;
    // Each run: a pair and its turn (`None`: as published).
    let turns: Vec<Option<&Turn>> = if args.turns.is_empty() {
        vec![None]
    } else {
        args.turns.iter().map(Some).collect()
    };
    let runs: Vec<(String, Vec<_>)> = names
        .into_iter()
        .zip(&folders)
        .map(|(name, folder)| {
            let pairs = args.data.select(folder.pairs.iter().collect());
            let runs = pairs
                .into_iter()
                .flat_map(|pair| turns.iter().map(move |&turn| (pair, turn)))
                .collect();
            (name, runs)
        })
        .collect();
    let succeeded = AtomicUsize::new(0);
    let results = evaluate_folders(runs, method, &args.workers, |method, &(pair, turn), bar| {
        let (record, warnings) = evaluate_scene_pair(method, pair, turn);
        for warning in warnings {
            bar.suspend(|| eprintln!("rgm: {warning}"));
        }
        let right = succeeded.fetch_add(record.succeeds() as usize, Ordering::Relaxed)
            + record.succeeds() as usize;
        bar.inc(1);
        bar.set_message(format!(
            "{right} of {} within {}° / {} m",
            bar.position(),
            MAX_ROTATION_ERROR_DEG,
            MAX_TRANSLATION_ERROR
        ));
        Ok(record)
    })?;
    let table = Table {
        header: scene_table_header(),
        row: scene_table_row,
        failed: |r: &SceneRecord| r.failure.is_some(),
        kind: "scenes",
    };
    table.report(&method.name(), &results, args.json.as_deref())
}

/// Each folder's items evaluated side by side on the workers' pool, each worker with its own
/// clone of `method`, under one progress bar that `evaluate` advances.
fn evaluate_folders<P: Sync, R: Send>(
    folders: Vec<(String, Vec<P>)>,
    method: &Method,
    workers: &WorkerArgs,
    evaluate: impl Fn(&mut Method, &P, &ProgressBar) -> Result<R> + Sync,
) -> Result<Vec<(String, Vec<R>)>> {
    let total: usize = folders.iter().map(|(_, items)| items.len()).sum();
    let bar = progress(total, &method.name());
    let pool = workers.pool()?;
    let mut results = Vec::with_capacity(folders.len());
    for (name, items) in folders {
        let records = pool.install(|| {
            items
                .par_iter()
                .map_init(
                    || method.clone(),
                    |method, item| evaluate(method, item, &bar),
                )
                .collect::<Result<Vec<R>>>()
        })?;
        results.push((name, records));
    }
    bar.finish_and_clear();
    Ok(results)
}

/// How the records of real-data pairs are shown: the table's header and rows, which records
/// failed, and the key that names a folder in the JSON.
struct Table<R> {
    header: String,
    row: fn(&str, &str, &[R]) -> Option<String>,
    failed: fn(&R) -> bool,
    kind: &'static str,
}

impl<R: Clone + serde::Serialize> Table<R> {
    /// Prints one row per folder and one for all when there are several, the count of failed
    /// pairs, and writes every record to `json` when asked.
    fn report(
        &self,
        method: &str,
        results: &[(String, Vec<R>)],
        json: Option<&Path>,
    ) -> Result<()> {
        // The file first: output that cannot be printed (a full disk) loses no result.
        if let Some(path) = json {
            let folders: Vec<serde_json::Value> = results
                .iter()
                .map(|(name, records)| serde_json::json!({self.kind: name, "pairs": records}))
                .collect();
            let value = serde_json::json!({"method": method, "folders": folders});
            crate::files::write_text(path, &serde_json::to_string_pretty(&value)?)?;
        }
        rgm_cli::outln!("{}", self.header)?;
        for (name, records) in results {
            if let Some(row) = (self.row)(method, name, records) {
                rgm_cli::outln!("{row}")?;
            }
        }
        if results.len() > 1 {
            let all: Vec<R> = results.iter().flat_map(|(_, r)| r.clone()).collect();
            if let Some(row) = (self.row)(method, "all", &all) {
                rgm_cli::outln!("{row}")?;
            }
        }
        let total: usize = results.iter().map(|(_, r)| r.len()).sum();
        let failures: usize = results
            .iter()
            .map(|(_, r)| r.iter().filter(|r| (self.failed)(r)).count())
            .sum();
        if failures > 0 {
            rgm_cli::outln!(
                "({failures} of {total} pairs failed and were scored as the identity)"
            )?;
        }
        if let Some(path) = json {
            rgm_cli::outln!("wrote per-pair results to {}", path.display())?;
        }
        Ok(())
    }
}
