//! `rgm merge SCAN... --out DIR`: every scan put into one frame
//! ([`rgm_registration::multiway::merge`], the pairs registered by `rgm register`'s method), and
//! the poses and the merged model written. `rgm eval --multiway` runs the same merge
//! ([`merge_scans`]) on scans with known poses.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use rgm_geom::{PointCloud, RigidTransform};
use rgm_model::Method;
use rgm_registration::multiway::{self, EdgeStatus, MultiwayConfig, MultiwayResult, Stage};
use serde_json::{json, Value};

use crate::args::MethodArgs;

/// Options of `rgm merge`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The scans, each in its own frame, in any order (at least 2; the formats of `rgm register`,
    /// gzip-compressed too).
    #[arg(required = true, num_args = 2.., value_name = "SCAN")]
    scans: Vec<PathBuf>,
    /// The folder to write poses.json, poses.conf, model.ply and model.html into (made if
    /// missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// model.ply keeps one point per cube of this side (the scans' units) [default: the largest
    /// component's point spacing, the median distance from a point to its nearest neighbour in
    /// its own scan].
    #[arg(long, value_name = "LENGTH")]
    voxel: Option<f64>,
    #[command(flatten)]
    merge: MergeArgs,
    /// Print the summary (poses.json's content) as one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    method: MethodArgs,
}

/// How a merge runs (`rgm merge`, `rgm eval --multiway`).
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// Rounds of multiway ICP (each scan refined against the union of the others), 0 for the
    /// pose graph's poses.
    #[arg(long, value_name = "N", default_value_t = MultiwayConfig::default().joint.rounds)]
    rounds: usize,
    /// Register the pairs on the scans thinned to one point (the mean) per cube of K times each
    /// scan's point spacing (1: as given); multiway ICP then runs on the scans as given.
    #[arg(long, value_name = "K", default_value_t = MultiwayConfig::default().pair_spacings)]
    pair_spacings: f64,
    /// Register every pair of scans, instead of choosing pairs round by round from the poses
    /// the pairs so far give (a pair those poses show apart skipped).
    #[arg(long)]
    all_pairs: bool,
}

impl MergeArgs {
    pub fn config(&self) -> Result<MultiwayConfig> {
        anyhow::ensure!(
            self.pair_spacings.is_finite() && self.pair_spacings >= 0.0,
            "--pair-spacings {}: give a number ≥ 0",
            self.pair_spacings
        );
        let defaults = MultiwayConfig::default();
        Ok(MultiwayConfig {
            joint: multiway::JointConfig {
                rounds: self.rounds,
                ..defaults.joint
            },
            pair_spacings: self.pair_spacings,
            pairs: match self.all_pairs {
                true => multiway::PairChoice::All,
                false => multiway::PairChoice::default(),
            },
            ..defaults
        })
    }
}

pub fn run(args: Args) -> Result<()> {
    if let Some(voxel) = args.voxel {
        anyhow::ensure!(
            voxel > 0.0 && voxel.is_finite(),
            "--voxel {voxel}: give a length > 0"
        );
    }
    let config = args.merge.config()?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot make the folder {}", args.out.display()))?;
    let outputs =
        ["poses.json", "poses.conf", "model.ply", "model.html"].map(|name| args.out.join(name));
    for path in &outputs {
        crate::files::check_writable(path)?;
    }
    let scans = read_scans(&args.scans)?;
    let method = args.method.build(crate::args::Defaults::Merge)?;
    let start = Instant::now();
    let merged = merge_scans(&scans, &method, &config)?;
    let seconds = start.elapsed().as_secs_f64();
    let summary = summary_json(&args.scans, &merged, &method.name(), seconds);
    crate::files::write_text(&outputs[0], &serde_json::to_string_pretty(&summary)?)?;
    crate::files::write_text(&outputs[1], &conf_text(&args.scans, &merged))?;
    // With no component the model is empty, whatever the voxel.
    let voxel = args
        .voxel
        .or(merged.spacing.first().copied())
        .unwrap_or(1.0);
    let (model, labels) = merged.model(&scans, 0, voxel);
    rgm_data::io::output::write_file(&outputs[2], |out| {
        rgm_data::io::ply::write_labelled(out, &model, Some(("scan", &labels)))
    })
    .with_context(|| format!("writing {}", outputs[2].display()))?;
    if !model.is_empty() {
        let page = rgm_viz::model::ModelPage {
            title: format!("{} scans merged", scans.len()),
            scans: args
                .scans
                .iter()
                .map(|p| p.display().to_string())
                .zip(&scans)
                .collect(),
            model: &model,
            labels: &labels,
            point_budget: rgm_viz::html::DEFAULT_POINT_BUDGET,
        };
        crate::files::write_text(&outputs[3], &page.to_html()?)?;
    } else if outputs[3].exists() {
        // No model, so no page of it: an earlier run's would tell of scans this run did not place.
        std::fs::remove_file(&outputs[3])
            .with_context(|| format!("removing the old {}", outputs[3].display()))?;
    }
    anyhow::ensure!(
        !merged.references.is_empty(),
        "no pair of the scans was registered, so none is placed ({} says why each pair was \
         left out)",
        outputs[0].display()
    );
    if args.json {
        return rgm_cli::outln!("{summary}");
    }
    print_table(&args.scans, &merged)?;
    rgm_cli::outln!(
        "# {} of {} scans placed in {} component(s), {:.1} s; wrote {}",
        merged.poses.iter().flatten().count(),
        scans.len(),
        merged.references.len(),
        seconds,
        outputs.map(|p| p.display().to_string()).join(", ")
    )?;
    rgm_cli::outln!(
        "# model.ply: {} points of component 0, one per cube of {voxel:.6}",
        model.len()
    )
}

/// The scans read side by side, each failure naming its file; the readings' warnings on stderr.
pub fn read_scans(paths: &[PathBuf]) -> Result<Vec<PointCloud>> {
    use rayon::prelude::*;
    paths
        .par_iter()
        .map(|path| {
            let (cloud, warnings) = rgm_data::read_point_cloud_warned(path)
                .with_context(|| format!("reading the scan {}", path.display()))?;
            for warning in warnings {
                eprintln!("rgm: {warning}");
            }
            anyhow::ensure!(
                cloud.len() >= 3,
                "the scan {} has {} points; a scan needs 3",
                path.display(),
                cloud.len()
            );
            Ok(cloud)
        })
        .collect()
}

/// [`multiway::merge`] with `method` for the pairs, its progress on stderr (a bar on a terminal).
pub fn merge_scans(
    scans: &[PointCloud],
    method: &Method,
    config: &MultiwayConfig,
) -> Result<MultiwayResult> {
    let pairs = scans.len() * (scans.len() - 1) / 2;
    let bar = crate::progress(pairs, "pairs");
    let start = Instant::now();
    let graph = std::sync::Mutex::new(start);
    let registered = std::sync::atomic::AtomicUsize::new(0);
    let progress = |stage: Stage| match stage {
        Stage::Pairs { done, .. } => {
            registered.fetch_max(done, std::sync::atomic::Ordering::Relaxed);
            bar.set_position(done as u64)
        }
        Stage::PoseGraph => {
            bar.finish_and_clear();
            let registered = registered.load(std::sync::atomic::Ordering::Relaxed);
            let skipped = match pairs - registered {
                0 => String::new(),
                n => format!(" ({n} skipped by what the other pairs show)"),
            };
            eprintln!(
                "rgm: {registered} of {pairs} pairs registered{skipped} in {:.1} s",
                start.elapsed().as_secs_f64()
            );
            *graph.lock().unwrap_or_else(|p| p.into_inner()) = Instant::now();
        }
        Stage::Joint => {
            let graph = graph.lock().unwrap_or_else(|p| p.into_inner());
            eprintln!(
                "rgm: pose graph solved in {:.2} s; multiway ICP",
                graph.elapsed().as_secs_f64()
            );
        }
    };
    // On one of rayon's workers, as `rgm register` runs: the pairs' parallel steps then share
    // the pool with this thread.
    let merged = rayon::scope(|_| multiway::merge(scans, method, config, &progress))?;
    eprintln!("rgm: merged in {:.1} s", start.elapsed().as_secs_f64());
    Ok(merged)
}

/// A pose as 4×4 rows, or null.
fn pose_json(pose: &Option<RigidTransform>) -> Value {
    pose.map_or(Value::Null, |p| json!(p.to_rows()))
}

/// What `poses.json` holds: per scan (in the order given) its path, pose `model ← scan`
/// (`null` when unplaced), whether it was placed, its component, residual and whether one of
/// its pairs lies on a loop of pairs; each
/// component's reference and spacing; every pair's edge and why it was left out.
pub fn summary_json(
    paths: &[PathBuf],
    merged: &MultiwayResult,
    method: &str,
    seconds: f64,
) -> Value {
    let edges: Vec<Value> = merged
        .edges
        .iter()
        .map(|e| {
            let (status, reason) = match &e.status {
                EdgeStatus::Used => ("used", None),
                EdgeStatus::Failed(why) => ("failed", Some(why)),
                EdgeStatus::Doubted(why) => ("doubted", Some(why)),
                EdgeStatus::Inconsistent(why) => ("inconsistent", Some(why)),
                EdgeStatus::Outlier(why) => ("outlier", Some(why)),
                EdgeStatus::Skipped(why) => ("skipped", Some(why)),
            };
            json!({
                "target": e.target,
                "source": e.source,
                "status": status,
                "reason": reason,
                "weight": e.weight,
                "t_target_source": e.t_target_source.to_rows(),
            })
        })
        .collect();
    json!({
        "scans": paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "poses": merged.poses.iter().map(pose_json).collect::<Vec<_>>(),
        "registered": merged.poses.iter().map(Option::is_some).collect::<Vec<_>>(),
        "component": merged.component,
        "residual": merged.residual,
        "on_loop": merged.on_loop,
        "references": merged.references,
        "spacing": merged.spacing,
        "method": method,
        "time_s": seconds,
        "edges": edges,
    })
}

/// The name a scan has in `poses.conf`: its file name without `.gz` (Stanford's `.conf` names
/// `bun000.ply` for `bun000.ply.gz`, and rgm reads either).
fn conf_name(path: &Path) -> String {
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    name.strip_suffix(".gz").map(str::to_string).unwrap_or(name)
}

/// `poses.conf`: the scans of component 0 (the largest) in Stanford's `bmesh` lines, the model
/// frame as the world; every other scan named on a comment line (a `.conf` reader skips them).
fn conf_text(paths: &[PathBuf], merged: &MultiwayResult) -> String {
    let names: Vec<String> = paths.iter().map(|p| conf_name(p)).collect();
    let mut text =
        String::from("# rgm merge: model ← scan of component 0 (p_model = R(q)ᵀ·p + t)\n");
    let placed: Vec<(&str, &RigidTransform)> = (0..paths.len())
        .filter(|&s| merged.component[s] == Some(0))
        .filter_map(|s| Some((names[s].as_str(), merged.poses[s].as_ref()?)))
        .collect();
    text.push_str(&rgm_data::scans::conf_text(placed));
    for (s, name) in names.iter().enumerate() {
        match merged.component[s] {
            Some(0) => {}
            Some(c) => text.push_str(&format!("# {name}: component {c}, in another frame\n")),
            None => text.push_str(&format!("# {name}: not placed\n")),
        }
    }
    text
}

/// One line per scan: its component, residual and where it went.
fn print_table(paths: &[PathBuf], merged: &MultiwayResult) -> Result<()> {
    rgm_cli::outln!("scan\tcomponent\tresidual\tmodel ← scan (rotation °, translation)")?;
    for (s, path) in paths.iter().enumerate() {
        let name = path.display();
        match (merged.poses[s], merged.component[s]) {
            (Some(pose), Some(c)) => {
                let residual = merged.residual[s].map_or("-".into(), |r| format!("{r:.3e}"));
                let t = pose.translation;
                let unchecked = match merged.on_loop[s] {
                    true => "",
                    false => "\tunchecked: none of its pairs lies on a loop of pairs",
                };
                rgm_cli::outln!(
                    "{name}\t{c}\t{residual}\t{:.3}°, ({:.6}, {:.6}, {:.6}){unchecked}",
                    pose.rotation_angle_deg(),
                    t.x,
                    t.y,
                    t.z
                )?;
            }
            _ => rgm_cli::outln!("{name}\t-\t-\tnot placed: no pair with it was trusted")?,
        }
    }
    Ok(())
}
