//! `rgm eval`: a method over the ModelNet40 test pairs, scored with the paper's metrics.

use std::path::PathBuf;

use anyhow::Result;
use rgm_model::evaluate::evaluate_pair;

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
}

pub fn run(args: Args) -> Result<()> {
    let (dataset, generator) = args.data.open()?;
    let shapes = args.data.shapes(&dataset);
    let mut method = args.method.build(false)?;
    let bar = progress(shapes.len(), method.name());
    let mut records = Vec::with_capacity(shapes.len());
    let mut recalled = 0usize;
    for i in 0..shapes.len() {
        let pair = generator.test_pair(&shapes, i)?;
        let record = evaluate_pair(&mut method, i, &pair)?;
        recalled += record.metrics.recall as usize;
        records.push(record);
        bar.set_message(format!(
            "recall {:.1}%",
            100.0 * recalled as f64 / records.len() as f64
        ));
        bar.inc(1);
    }
    bar.finish_and_clear();
    table::report(
        method.name(),
        &args.data.pairs_name(),
        &records,
        args.json.as_deref(),
    )?;
    Ok(())
}
