//! `rgm eval --multiway DIR...`: each Stanford-layout folder's scans moved and shuffled
//! ([`rgm_data::multiway::moved_and_shuffled`]), merged as `rgm merge` merges them, and each
//! scan's pose scored against the `.conf` ground truth after the best rigid alignment of the
//! two frames ([`rgm_data::multiway::pose_errors`]). A folder in the 3DMatch layout (a `gt.log`,
//! [`rgm_data::SceneFolder`]) has its fragments merged as they are given (each in its own
//! frame already) and each pair of `gt.log` scored by the merge's relative pose of the two.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use rgm_data::multiway::{moved_and_shuffled, pose_errors, PoseError};
use rgm_data::scenes::{transform_errors, MAX_ROTATION_ERROR_DEG, MAX_TRANSLATION_ERROR};
use rgm_data::{ScanFolder, SceneFolder};
use rgm_model::Method;
use rgm_registration::multiway::MultiwayConfig;
use serde_json::json;

use super::merge::merge_scans;

/// The seed of every folder's motions and order.
pub const SEED: u64 = 0;

/// A scan within this rotation error (°) and RMS displacement (share of the object's diagonal)
/// counts as right: the criterion.
const WITHIN: (f64, f64) = (1.0, 0.005);

/// Merges (with `config`) and scores each folder of `dirs`, printing a table per folder and writing every scan's
/// errors to `json` when given.
pub fn run(
    dirs: &[PathBuf],
    method: &Method,
    config: &MultiwayConfig,
    json: Option<&std::path::Path>,
) -> Result<()> {
    let names = crate::args::folder_names(dirs, "--multiway")?;
    let mut records = Vec::new();
    for (dir, name) in dirs.iter().zip(names) {
        if dir.join("gt.log").is_file() {
            scene_folder(dir, &name, method, config, &mut records)?;
            continue;
        }
        rgm_cli::outln!(
            "folder\tscans\tplaced\twithin {}° and {} %\tworst rotation\tmedian rotation\tworst RMS\ttime",
            WITHIN.0,
            100.0 * WITHIN.1
        )?;
        let folder = ScanFolder::open(dir)?;
        for warning in &folder.warnings {
            eprintln!("rgm: {warning}");
        }
        let diagonal = folder.diagonal();
        let scans = moved_and_shuffled(&folder, SEED);
        let clouds: Vec<_> = scans.iter().map(|s| s.cloud.clone()).collect();
        let start = Instant::now();
        let merged = merge_scans(&clouds, method, config)?;
        let seconds = start.elapsed().as_secs_f64();
        let errors = pose_errors(&scans, &merged.poses, &merged.component);
        let placed: Vec<PoseError> = errors.iter().flatten().copied().collect();
        let right = placed
            .iter()
            .filter(|e| e.rotation_deg <= WITHIN.0 && e.rms / diagonal <= WITHIN.1)
            .count();
        let rotations: Vec<f64> = placed.iter().map(|e| e.rotation_deg).collect();
        let worst = rotations.iter().copied().fold(f64::NAN, f64::max);
        let worst_rms = placed.iter().map(|e| e.rms).fold(f64::NAN, f64::max);
        rgm_cli::outln!(
            "{name}\t{}\t{}\t{right}\t{worst:.3}°\t{:.3}°\t{:.3} %\t{seconds:.1} s",
            scans.len(),
            placed.len(),
            rgm_geom::cloud::median(rotations),
            100.0 * worst_rms / diagonal,
        )?;
        for (scan, error) in scans.iter().zip(&errors) {
            let scan_name = &folder.scans[scan.original].name;
            let line = match error {
                Some(e) => format!(
                    "  {scan_name}\t{:.3}°\t{:.3} %",
                    e.rotation_deg,
                    100.0 * e.rms / diagonal
                ),
                None => format!("  {scan_name}\tnot placed"),
            };
            rgm_cli::outln!("{line}")?;
            records.push(json!({
                "folder": name,
                "scan": scan_name,
                "placed": error.is_some(),
                "rotation_deg": error.map(|e| e.rotation_deg),
                "rms_diagonal": error.map(|e| e.rms / diagonal),
            }));
        }
        records.push(json!({"folder": name, "time_s": seconds, "diagonal": diagonal}));
    }
    if let Some(path) = json {
        let value = json!({"method": method.name(), "seed": SEED, "records": records});
        crate::files::write_text(path, &serde_json::to_string_pretty(&value)?)?;
        rgm_cli::outln!("wrote per-scan results to {}", path.display())?;
    }
    Ok(())
}

/// A folder in the 3DMatch layout: its fragments merged as given, and each pair of its `gt.log`
/// scored by the merge's pose of its source relative to its target (`P_target⁻¹ · P_source`,
/// against `gt.log`'s `T`), counted within the 3DMatch criterion; a pair whose fragments are in
/// different components (or unplaced) is not.
fn scene_folder(
    dir: &std::path::Path,
    name: &str,
    method: &Method,
    config: &MultiwayConfig,
    records: &mut Vec<serde_json::Value>,
) -> Result<()> {
    let folder = SceneFolder::open(dir)?;
    let files = folder.fragments();
    let clouds = super::merge::read_scans(&files)?;
    let start = Instant::now();
    let merged = merge_scans(&clouds, method, config)?;
    let seconds = start.elapsed().as_secs_f64();
    let place = |file: &std::path::PathBuf| files.iter().position(|f| f == file).expect("listed");
    // (rotation °, translation) of each pair both of whose fragments one component holds.
    let mut scored = Vec::new();
    let mut lines = Vec::new();
    for pair in &folder.pairs {
        let (s, t) = (place(&pair.source), place(&pair.target));
        let together = merged.component[s].is_some() && merged.component[s] == merged.component[t];
        let errors = match (merged.poses[s], merged.poses[t]) {
            (Some(ps), Some(pt)) if together => Some(transform_errors(
                &pair.t_target_source,
                &pt.inverse().compose(&ps),
            )),
            _ => None,
        };
        let (source, target) = pair.names();
        lines.push(match errors {
            Some((r, t)) => format!("  {source} → {target}\t{r:.3}°\t{t:.4}"),
            None => format!("  {source} → {target}\tnot in one component"),
        });
        records.push(json!({
            "folder": name,
            "source": source,
            "target": target,
            "together": errors.is_some(),
            "rotation_deg": errors.map(|e| e.0),
            "translation": errors.map(|e| e.1),
        }));
        scored.extend(errors);
    }
    let right = scored
        .iter()
        .filter(|(r, t)| *r < MAX_ROTATION_ERROR_DEG && *t < MAX_TRANSLATION_ERROR)
        .count();
    rgm_cli::outln!(
        "folder\tfragments\tplaced\tpairs\tin one component\twithin {MAX_ROTATION_ERROR_DEG}° and \
         {MAX_TRANSLATION_ERROR}\tmedian rotation\tmedian translation\ttime"
    )?;
    rgm_cli::outln!(
        "{name}\t{}\t{}\t{}\t{}\t{right}\t{:.3}°\t{:.4}\t{seconds:.1} s",
        files.len(),
        merged.poses.iter().flatten().count(),
        folder.pairs.len(),
        scored.len(),
        rgm_geom::cloud::median(scored.iter().map(|e| e.0).collect()),
        rgm_geom::cloud::median(scored.iter().map(|e| e.1).collect()),
    )?;
    for line in lines {
        rgm_cli::outln!("{line}")?;
    }
    records.push(json!({"folder": name, "time_s": seconds}));
    Ok(())
}
