//! `rgm render SRC TGT --out fig.png`: a picture of a registration, the clouds before and after.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use rgm_data::read_point_cloud;
use rgm_geom::{Matrix4, RigidTransform};
use rgm_model::render::registration_figure;

use crate::MethodArgs;

/// Options of `rgm render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The cloud that moves (PLY, OFF, XYZ/CSV or .npy).
    source: PathBuf,
    /// The cloud it moves onto.
    target: PathBuf,
    /// The transform target ← source: a file as `rgm register` prints it (4 rows of 4 numbers,
    /// `#` lines ignored) or its `--json` object. Without it, the method below finds one.
    #[arg(long, value_name = "FILE")]
    transform: Option<PathBuf>,
    #[command(flatten)]
    method: MethodArgs,
    /// The PNG to write: source orange, target blue; before (left) and after (right).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    let source = read_point_cloud(&args.source)?;
    let target = read_point_cloud(&args.target)?;
    let transform = match &args.transform {
        Some(path) => read_transform(path)?,
        None => {
            let mut method = args.method.build()?;
            let registration = method.register(&source, &target).with_context(|| {
                format!(
                    "{} failed on {} → {}",
                    method.name(),
                    args.source.display(),
                    args.target.display()
                )
            })?;
            registration.result.t_target_source
        }
    };
    registration_figure(&source, &target, &transform)?.write_png(&args.out)?;
    println!("wrote {}", args.out.display());
    Ok(())
}

/// A 4×4 rigid transform from `rgm register`'s text or JSON output.
fn read_transform(path: &Path) -> Result<RigidTransform> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let numbers: Vec<f64> = if text.trim_start().starts_with('{') {
        let value: serde_json::Value = serde_json::from_str(&text)
            .with_context(|| format!("{} is not JSON", path.display()))?;
        value["transform"]
            .as_array()
            .into_iter()
            .flatten()
            .flat_map(|row| row.as_array().into_iter().flatten())
            .map(|x| x.as_f64().context("a transform entry is not a number"))
            .collect::<Result<_>>()?
    } else {
        text.lines()
            .filter(|l| !l.trim_start().starts_with('#'))
            .flat_map(str::split_whitespace)
            .map(|w| {
                w.parse()
                    .with_context(|| format!("{:?} in {} is not a number", w, path.display()))
            })
            .collect::<Result<_>>()?
    };
    if numbers.len() != 16 {
        bail!(
            "{} holds {} numbers; a 4×4 transform needs 16",
            path.display(),
            numbers.len()
        );
    }
    let m = Matrix4::from_row_slice(&numbers);
    RigidTransform::from_matrix4(&m, 1e-4)
        .with_context(|| format!("{} is not a rigid transform", path.display()))
}
