//! Reading a pair's files, registering them and writing outputs, with errors that name the
//! files.

use std::path::Path;

use anyhow::Context;
use rgm_model::{Method, Registrar};

use crate::progress;

/// Runs `method` on the clouds read from `source_path` and `target_path`, naming both files and
/// the method when it fails. FGR's steps show as a bar (in percent) on a terminal.
pub fn register_files(
    method: &mut Method,
    (source, target): (&rgm_geom::PointCloud, &rgm_geom::PointCloud),
    (source_path, target_path): (&std::path::Path, &std::path::Path),
) -> anyhow::Result<rgm_model::Registration> {
    let bar = progress(100, &method.name());
    let registration = method
        .register_with_progress(source, target, &mut |p| {
            bar.set_position((100.0 * p.done) as u64);
            bar.set_message(p.step);
        })
        .map_err(|err| method_failure(err, &method.name(), (source_path, target_path)));
    bar.finish_and_clear();
    registration
}

/// `err` of method `name` on the pair of files, named, with a hint where an option helps.
pub fn method_failure(
    err: rgm_model::MethodError,
    name: &str,
    (source_path, target_path): (&Path, &Path),
) -> anyhow::Error {
    let hint = match err {
        rgm_model::MethodError::TooMuchMemory { .. } => {
            " (--match-points N matches on fewer points)"
        }
        _ => "",
    };
    anyhow::Error::new(err).context(format!(
        "{name} failed on {} → {}{hint}",
        source_path.display(),
        target_path.display()
    ))
}

/// The point clouds of a pair, read side by side; the readings' warnings (stray PLY header
/// lines) shown on stderr and a failure returned in the order source, target.
pub fn read_pair(
    source: &Path,
    target: &Path,
) -> anyhow::Result<(rgm_geom::PointCloud, rgm_geom::PointCloud)> {
    let (source, target) = rayon::join(
        || rgm_data::read_point_cloud_warned(source),
        || rgm_data::read_point_cloud_warned(target),
    );
    Ok((warned(source)?, warned(target)?))
}

/// The cloud read, its warnings printed.
fn warned(
    read: rgm_data::Result<(rgm_geom::PointCloud, Vec<rgm_data::io::Warning>)>,
) -> anyhow::Result<rgm_geom::PointCloud> {
    let (cloud, warnings) = read?;
    for warning in warnings {
        eprintln!("rgm: {warning}");
    }
    Ok(cloud)
}

/// The long help of a command's input cloud: `first`, then every format rgm reads, from the
/// one list of them.
pub fn source_help(first: &str) -> String {
    format!(
        "{first} The format by extension, gzip-compressed too (`scan.ply.gz`):\n{}",
        rgm_data::io::formats_help()
    )
}

/// Fails now, before the work, when `path` cannot be written (its folder is missing, it is a
/// folder, permission is denied), so a long command does not lose its result at the end;
/// nothing changes at `path` ([`rgm_data::io::output::check_writable`]).
pub fn check_writable(path: &Path) -> anyhow::Result<()> {
    rgm_data::io::output::check_writable(path)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes `text` to `path` as every output is written ([`rgm_data::io::output::write_file`]:
/// a failed write leaves the path as it was).
pub fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    rgm_data::io::output::write_file(path, |out| out.write_all(text.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))
}
