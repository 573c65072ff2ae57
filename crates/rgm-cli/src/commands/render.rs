//! `rgm render SRC TGT --out fig.png`: a picture of a registration, the clouds before and after;
//! with `--matrix` and `--truth`, also RGM's hard correspondences coloured correct or wrong;
//! with `--html page.html`, a page that turns in a browser ([`super::page`]).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use rgm_data::Correspondence;
use rgm_geom::{Matrix4, RigidTransform};
use rgm_viz::html::ResultNotes;
use rgm_viz::{correct_fraction, correspondence_figure, registration_figure};

use crate::args::MethodArgs;

/// Blocks per side of the correspondence picture (the paper's Figure 5 uses 36).
const MATRIX_BLOCKS: usize = 36;

/// Options of `rgm render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The cloud that moves; the format by extension (the list: `rgm_data::io::FORMATS`).
    #[arg(long_help = crate::files::source_help("The cloud that moves."))]
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
    /// Needed unless --html is given.
    #[arg(long, value_name = "FILE", required_unless_present = "html")]
    out: Option<PathBuf>,
    /// Also write the correspondence matrix of the found transform as a PNG (as the paper's
    /// Figure 5: black correct, red wrong, grey missed), judged against --truth: the network's
    /// hard matches with `--method rgm --no-refine`, otherwise the source points the transform
    /// brings within the method's scoring distance of a target point.
    #[arg(long, value_name = "FILE", requires = "truth")]
    matrix: Option<PathBuf>,
    /// The true transform target ← source (formats as --transform): the correct
    /// correspondences are rebuilt from it as the benchmark does (spec §1).
    #[arg(long, value_name = "FILE")]
    truth: Option<PathBuf>,
    #[command(flatten)]
    page: super::page::HtmlArgs,
}

/// Refuses `path` unless it is a writable `.png` file, before any work.
fn check_png(path: &Path, option: &str) -> Result<()> {
    let png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !png {
        bail!(
            "{option} {}: rgm render writes PNG images; give the file a .png name",
            path.display()
        );
    }
    crate::files::check_writable(path)
}

pub fn run(args: Args) -> Result<()> {
    if let Some(out) = &args.out {
        check_png(out, "--out")?;
    }
    args.page.check()?;
    if let Some(matrix) = &args.matrix {
        check_png(matrix, "--matrix")?;
    }
    let (source, target) = crate::files::read_pair(&args.source, &args.target)?;
    let given = args
        .transform
        .as_deref()
        .map(|path| read_transform(path).map(|t| (path, t)))
        .transpose()?;
    let found = match (&given, &args.matrix) {
        (Some(_), None) => None, // nothing to find
        _ => {
            let mut method = args.method.build(crate::args::Defaults::Register)?;
            let registration = crate::files::register_files(
                &mut method,
                (&source, &target),
                (&args.source, &args.target),
            )?;
            Some((method.name(), registration))
        }
    };
    let (transform, notes) = match (given, &found) {
        (Some((path, transform)), _) => (
            transform,
            ResultNotes {
                method: format!("the transform of {}", path.display()),
                correspondences_note: "none: no method ran".to_string(),
                ..ResultNotes::default()
            },
        ),
        (None, Some((name, found))) => (
            found.result.t_target_source,
            ResultNotes::of_registration(name, found),
        ),
        (None, None) => bail!("no transform given or found"),
    };
    if let Some(out) = &args.out {
        registration_figure(&source, &target, &transform)?.write_png(out)?;
        rgm_cli::outln!("wrote {}", out.display())?;
    }
    args.page.write(
        (&source, &target),
        (&args.source, &args.target),
        transform,
        notes,
    )?;
    if let (Some(path), Some(truth), Some((_, found))) = (&args.matrix, &args.truth, &found) {
        let moved = source.transformed(&read_transform(truth)?);
        let correct = Correspondence::rebuild(&moved.points, &target.points);
        let pairs = &found.correspondences;
        correspondence_figure(&correct, pairs, MATRIX_BLOCKS)?.write_png(path)?;
        rgm_cli::outln!(
            "wrote {}: {} correspondences, {:.1} % correct",
            path.display(),
            pairs.len(),
            100.0 * correct_fraction(&correct, pairs)
        )?;
    }
    Ok(())
}

/// A 4×4 rigid transform from a file of `rgm register`'s text or JSON output.
fn read_transform(path: &Path) -> Result<RigidTransform> {
    parse_transform(&rgm_data::read_regular_file(path)?, path)
}

/// A 4×4 rigid transform from the bytes of `rgm register`'s text or JSON output; `path` names
/// them in errors.
fn parse_transform(bytes: &[u8], path: &Path) -> Result<RigidTransform> {
    let text =
        std::str::from_utf8(bytes).with_context(|| format!("{} is not text", path.display()))?;
    let numbers: Vec<f64> = if text.trim_start().starts_with('{') {
        let value: serde_json::Value = serde_json::from_str(text)
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

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_tests::mutation::{corpus, Fuzz};

    #[test]
    fn both_transform_formats_read_and_survive_fuzzing() {
        let seeds = corpus(&["transform.txt", "register.json"]);
        assert_eq!(seeds.len(), 2);
        for seed in &seeds {
            let t = parse_transform(seed, Path::new("seed")).unwrap();
            assert!((t.translation.z - 0.3).abs() < 1e-12, "{t:?}");
        }
        // Memory is not counted here (the allocator is the system's): no panic, no hang.
        Fuzz::default().run("transform", &seeds, |b| {
            let _ = parse_transform(b, Path::new("f.txt"));
        });
    }
}
