//! `rgm eval`: a method over the ModelNet40 test pairs, scored with the paper's metrics, or
//! over real scan pairs (`--scans`), scored by success rates, median errors and time.

use std::path::PathBuf;

use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Result;
use rayon::prelude::*;
use rgm_model::evaluate::{
    evaluate_pair, evaluate_scan_pair, scan_table_header, scan_table_row, PairRecord, ScanRecord,
};
use rgm_model::Method;

use crate::{progress, table, DataArgs, MethodArgs, WorkerArgs};

/// Options of `rgm eval`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    method: MethodArgs,
    #[command(flatten)]
    data: DataArgs,
    /// Also write every pair's transform and metrics to this JSON file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    #[command(flatten)]
    workers: WorkerArgs,
}

pub fn run(args: Args) -> Result<()> {
    if let Some(json) = &args.json {
        crate::check_writable(json)?;
    }
    let method = args.method.build(crate::Defaults::Paper)?;
    if !args.data.scans.is_empty() {
        return run_scans(&args, &method);
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
    let total: usize = folders.iter().map(|(_, pairs)| pairs.len()).sum();
    let bar = progress(total, &method.name());
    let pool = args.workers.pool()?;
    let mut results: Vec<(String, Vec<ScanRecord>)> = Vec::new();
    for (name, pairs) in folders {
        let records: Vec<ScanRecord> = pool.install(|| {
            pairs
                .par_iter()
                .map_init(
                    || method.clone(),
                    |method, pair| {
                        let record = evaluate_scan_pair(method, pair);
                        bar.inc(1);
                        record
                    },
                )
                .collect()
        });
        results.push((name, records));
    }
    bar.finish_and_clear();
    println!("{}", scan_table_header());
    for (name, records) in &results {
        if let Some(row) = scan_table_row(&method.name(), name, records) {
            println!("{row}");
        }
    }
    if results.len() > 1 {
        let all: Vec<ScanRecord> = results.iter().flat_map(|(_, r)| r.clone()).collect();
        if let Some(row) = scan_table_row(&method.name(), "all", &all) {
            println!("{row}");
        }
    }
    let failures: usize = results
        .iter()
        .map(|(_, r)| r.iter().filter(|r| r.failure.is_some()).count())
        .sum();
    if failures > 0 {
        println!("({failures} of {total} pairs failed and were scored as the identity)");
    }
    if let Some(path) = &args.json {
        let folders: Vec<serde_json::Value> = results
            .iter()
            .map(|(name, records)| serde_json::json!({"scans": name, "pairs": records}))
            .collect();
        let value = serde_json::json!({"method": method.name(), "folders": folders});
        crate::write_text(path, &serde_json::to_string_pretty(&value)?)?;
        println!("wrote per-pair results to {}", path.display());
    }
    Ok(())
}
