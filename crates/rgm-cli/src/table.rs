//! What `rgm eval` and `rgm score` print and write: the metrics table (rgm-model's, shared with
//! `cargo xtask reproduce-tables`) and per-pair JSON.

use rgm_model::evaluate::{table_header, table_row};
use rgm_model::{PairRecord, Summary};

/// Prints the table of one evaluation and writes its per-pair JSON when asked.
pub fn report(
    method: &str,
    setting: &str,
    records: &[PairRecord],
    json: Option<&std::path::Path>,
) -> anyhow::Result<Summary> {
    let summary = Summary::from_records(records)?;
    // The file first: output that cannot be printed (a full disk) loses no result.
    if let Some(path) = json {
        let value = serde_json::json!({
            "method": method,
            "setting": setting,
            "pairs": records,
        });
        crate::files::write_text(path, &serde_json::to_string_pretty(&value)?)?;
    }
    rgm_cli::outln!("{}", table_header())?;
    rgm_cli::outln!("{}", table_row(method, setting, &summary))?;
    if summary.failures > 0 {
        rgm_cli::outln!(
            "({} of {} pairs failed and were scored as the identity)",
            summary.failures,
            records.len()
        )?;
    }
    if let Some(path) = json {
        rgm_cli::outln!("wrote per-pair results to {}", path.display())?;
    }
    Ok(summary)
}
