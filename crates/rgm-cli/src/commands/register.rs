//! `rgm register SRC TGT`: the transform that maps SRC onto TGT; `--pairs LIST` runs many
//! pairs ([`super::pair_list`], which does not depend on this module).

use std::path::PathBuf;

use anyhow::Result;
use rgm_data::write_point_cloud;
use rgm_viz::html::ResultNotes;

use crate::args::MethodArgs;

/// Options of `rgm register`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The cloud to move; the format by extension (the list: `rgm_data::io::FORMATS`).
    #[arg(
        required_unless_present = "pairs",
        conflicts_with = "pairs",
        long_help = crate::files::source_help("The cloud to move.")
    )]
    source: Option<PathBuf>,
    /// The cloud to move it onto.
    #[arg(required_unless_present = "pairs", conflicts_with = "pairs")]
    target: Option<PathBuf>,
    #[command(flatten)]
    method: MethodArgs,
    /// Write the source moved by the found transform to this file (format by extension).
    #[arg(long, value_name = "FILE", conflicts_with = "pairs")]
    out: Option<PathBuf>,
    /// Print one JSON object instead of text (--pairs always writes JSON).
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    page: super::page::HtmlArgs,
    #[command(flatten)]
    pair_list: super::pair_list::PairListArgs,
}

pub fn run(args: Args) -> Result<()> {
    let (Some(source_path), Some(target_path)) = (&args.source, &args.target) else {
        if args.page.html.is_some() {
            anyhow::bail!("--html writes the page of one pair (SOURCE TARGET), not of --pairs");
        }
        return super::pair_list::run(&args.pair_list, &args.method);
    };
    args.pair_list.refuse_without_pairs()?;
    args.page.check()?;
    if let Some(out) = &args.out {
        rgm_data::io::format_of(out)?;
        crate::files::check_writable(out)?;
    }
    let (source, target) = crate::files::read_pair(source_path, target_path)?;
    let mut method = args.method.build(crate::args::Defaults::Register)?;
    let registration =
        crate::files::register_files(&mut method, (&source, &target), (source_path, target_path))?;
    let result = &registration.result;
    let refined = method.is_refined();
    let doubt = registration.doubt.as_deref();
    if let (Some(out), None) = (&args.out, doubt) {
        write_point_cloud(out, &source.transformed(&result.t_target_source))?;
    }
    args.page.write(
        (&source, &target),
        (source_path, target_path),
        result.t_target_source,
        ResultNotes::of_registration(&method.name(), &registration),
    )?;
    let rows = result.t_target_source.to_rows();
    if args.json {
        let value = rgm_model::many_pairs::result_json(
            &method,
            &registration,
            (source.len(), target.len()),
        );
        rgm_cli::outln!("{value}")?;
        return not_registered(doubt);
    }
    not_registered(doubt)?;
    rgm_cli::outln!(
        "# transform target ← source ({}), y = R x + t",
        method.name()
    )?;
    for row in rows {
        rgm_cli::outln!(
            "{:>12.8} {:>12.8} {:>12.8} {:>12.8}",
            row[0],
            row[1],
            row[2],
            row[3]
        )?;
    }
    rgm_cli::outln!(
        "# fitness {:.4}, inlier RMSE {:.6}, correspondences {}, iterations {}{}{}, time {:.1} ms",
        result.fitness,
        result.inlier_rmse,
        result.inlier_count,
        result.iterations,
        if refined { " (refined with ICP)" } else { "" },
        if result.converged {
            ""
        } else {
            " (not converged)"
        },
        registration.time_ms
    )?;
    for (k, c) in registration.candidates.iter().enumerate() {
        let mark = if Some(k) == registration.chosen {
            " (chosen)"
        } else {
            ""
        };
        match (c.score, &c.failure) {
            (Some(score), _) => {
                rgm_cli::outln!("# candidate {}: overlap score {score:.4}{mark}", c.method)?
            }
            (None, Some(why)) => rgm_cli::outln!("# candidate {}: failed: {why}", c.method)?,
            (None, None) => rgm_cli::outln!("# candidate {}: no score", c.method)?,
        }
    }
    if let Some(out) = &args.out {
        rgm_cli::outln!("# wrote the moved source to {}", out.display())?;
    }
    Ok(())
}

/// The error of a result that is not credible ([`rgm_model::Registration::doubt`]): the pair is
/// reported as not registered, with the reason, and rgm exits with a failure.
fn not_registered(doubt: Option<&str>) -> Result<()> {
    match doubt {
        Some(why) => anyhow::bail!("not registered: {why}"),
        None => Ok(()),
    }
}
