//! `rgm pairs`: write the test pairs so outside tools run on exactly the same data.
//!
//! Layout of the output folder: `NNNN_source.ply`, `NNNN_target.ply` per pair, and
//! `pairs.json` with, per pair, its index, shape, label, file names, the ground-truth 4×4
//! `t_target_source` and the ground-truth correspondences `[source index, target index]`.
//!
//! With `--scans`, one subfolder per scan folder (named as it), each with its pairs' files and
//! a `pairs.json` of `{"scans": NAME, "pairs": [{index, source_scan, target_scan, overlap,
//! diagonal, source, target, t_target_source}, …]}` (`diagonal`: the object's bounding-box
//! diagonal, the unit of translation errors; `rgm score --pairs` reads it).

use std::fs;
use std::path::PathBuf;

use anyhow::{Context, Result};
use rgm_data::write_point_cloud;

use crate::args::DataArgs;
use crate::progress;

/// Options of `rgm pairs`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    data: DataArgs,
    /// The folder to write (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    if !args.data.scans.is_empty() {
        return run_scans(&args);
    }
    let (dataset, generator) = args.data.open()?;
    let (shapes, indices) = args.data.shapes(&dataset);
    fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let bar = progress(indices.len(), "pairs");
    let mut entries = Vec::with_capacity(indices.len());
    for &i in &indices {
        let shape = shapes[i];
        let pair = generator.test_pair(&shapes, i)?;
        let (source, target) = (format!("{i:04}_source.ply"), format!("{i:04}_target.ply"));
        write_point_cloud(args.out.join(&source), &pair.source)?;
        write_point_cloud(args.out.join(&target), &pair.target)?;
        entries.push(serde_json::json!({
            "index": i,
            "shape": shape.name,
            "label": pair.label,
            "source": source,
            "target": target,
            "t_target_source": pair.t_target_source.to_rows(),
            "correspondences": pair.correspondence.pairs,
        }));
        bar.inc(1);
    }
    bar.finish_and_clear();
    let manifest = serde_json::json!({
        "setting": generator.setting.name(),
        "unseen": args.data.unseen,
        "pairs": entries,
    });
    let path = args.out.join("pairs.json");
    crate::files::write_text(&path, &serde_json::to_string(&manifest)?)?;
    rgm_cli::outln!("wrote {} pairs to {}", indices.len(), args.out.display())?;
    Ok(())
}

/// `rgm pairs --scans`: one subfolder of `--out` per scan folder.
fn run_scans(args: &Args) -> Result<()> {
    for (name, pairs) in args.data.scan_pairs()? {
        let out = args.out.join(&name);
        fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
        let mut entries = Vec::with_capacity(pairs.len());
        for pair in &pairs {
            let i = pair.index;
            let (source, target) = (format!("{i:04}_source.ply"), format!("{i:04}_target.ply"));
            write_point_cloud(out.join(&source), &pair.source)?;
            write_point_cloud(out.join(&target), &pair.target)?;
            entries.push(serde_json::json!({
                "index": i,
                "source_scan": pair.source_name,
                "target_scan": pair.target_name,
                "overlap": pair.overlap,
                "diagonal": pair.diagonal,
                "source": source,
                "target": target,
                "t_target_source": pair.t_target_source.to_rows(),
            }));
        }
        let manifest = serde_json::json!({"scans": name, "pairs": entries});
        let path = out.join("pairs.json");
        crate::files::write_text(&path, &serde_json::to_string(&manifest)?)?;
        rgm_cli::outln!("wrote {} pairs to {}", pairs.len(), out.display())?;
    }
    Ok(())
}
