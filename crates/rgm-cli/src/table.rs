//! What `rgm eval` and `rgm score` print and write: the metrics table and per-pair JSON.

use rgm_model::{PairRecord, Summary};

/// The header and rule of the metrics table (spec §5 columns, paper order).
pub fn header() -> String {
    format!(
        "| {:<12} | {:<8} | {:>5} | {:>8} | {:>8} | {:>8} | {:>8} | {:>8} | {:>7} | {:>9} |\n|{}|",
        "method",
        "setting",
        "pairs",
        "MIE(R)",
        "MIE(t)",
        "MAE(R)",
        "MAE(t)",
        "CCD",
        "recall",
        "ms/pair",
        ["-"; 10].map(|_| "---").join("|")
    )
}

/// One row of the metrics table.
pub fn row(method: &str, setting: &str, s: &Summary) -> String {
    format!(
        "| {:<12} | {:<8} | {:>5} | {:>8.4} | {:>8.5} | {:>8.4} | {:>8.5} | {:>8.5} | {:>6.2}% | {:>9.1} |",
        method,
        setting,
        s.metrics.pairs,
        s.metrics.mie_r_deg,
        s.metrics.mie_t,
        s.metrics.mae_r_deg,
        s.metrics.mae_t,
        s.metrics.ccd,
        100.0 * s.metrics.recall,
        s.time_ms
    )
}

/// One pair's record as JSON (for `--json` files).
pub fn record_json(r: &PairRecord) -> serde_json::Value {
    let m = &r.metrics;
    serde_json::json!({
        "index": r.index,
        "transform": r.transform.to_rows(),
        "ground_truth": r.ground_truth.to_rows(),
        "time_ms": r.time_ms,
        "correspondences": r.correspondences,
        "mie_r_deg": m.mie_r_deg,
        "mie_t": m.mie_t,
        "mae_r_deg": m.mae_r_deg,
        "mae_t": m.mae_t,
        "ccd": m.ccd,
        "chamfer": m.chamfer,
        "recall": m.recall,
        "failure": r.failure,
    })
}

/// Prints the table of one evaluation and writes its per-pair JSON when asked.
pub fn report(
    method: &str,
    setting: &str,
    records: &[PairRecord],
    json: Option<&std::path::Path>,
) -> anyhow::Result<Summary> {
    let summary = Summary::from_records(records)?;
    println!("{}", header());
    println!("{}", row(method, setting, &summary));
    if summary.failures > 0 {
        println!(
            "({} of {} pairs failed and were scored as the identity)",
            summary.failures,
            records.len()
        );
    }
    if let Some(path) = json {
        let value = serde_json::json!({
            "method": method,
            "setting": setting,
            "pairs": records.iter().map(record_json).collect::<Vec<_>>(),
        });
        std::fs::write(path, serde_json::to_string_pretty(&value)?)
            .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
        println!("wrote per-pair results to {}", path.display());
    }
    Ok(summary)
}
