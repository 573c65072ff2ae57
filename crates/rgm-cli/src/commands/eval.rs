//! `rgm eval`: a method over the ModelNet40 test pairs, scored with the paper's metrics.

use std::path::PathBuf;

use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Result;
use rayon::prelude::*;
use rgm_model::evaluate::{evaluate_pair, PairRecord};

use crate::{progress, table, DataArgs, MethodArgs};

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
    /// Pairs registered at once, one per worker thread [default: one per core; the
    /// `RAYON_NUM_THREADS` variable sets it too]. Times are each method's own, per pair.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    workers: Option<u16>,
}

pub fn run(args: Args) -> Result<()> {
    if let Some(json) = &args.json {
        crate::check_writable(json)?;
    }
    let (dataset, generator) = args.data.open()?;
    let (shapes, indices) = args.data.shapes(&dataset);
    let method = args.method.build(crate::Defaults::Paper)?;
    let bar = progress(indices.len(), method.name());
    let recalled = AtomicUsize::new(0);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.workers.map_or(0, usize::from))
        .start_handler(|_| {
            rgm_nn::threads::flush_denormals_to_zero();
        })
        .build()?;
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
        method.name(),
        &args.data.pairs_name(),
        &records,
        args.json.as_deref(),
    )?;
    Ok(())
}
