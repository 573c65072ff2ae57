//! Point-cloud files: one module per format, each a [`PointFormat`], and one list of them,
//! [`FORMATS`], that the reader, the writer, the error for an unknown extension, the command
//! line's help and the fuzz tests all read. A new format is one module and one line in the list.
//!
//! Every reader parses bytes it is given (so the tests need no files) and hands its points to
//! [`checked_cloud`], the one place that rejects empty clouds and non-finite coordinates.
//!
//! A name ending in `.gz` (`scan.ply.gz`, `cloud.xyz.gz`, ...) is a gzip-compressed file of the
//! format its inner extension names: real scans are often shipped so. It is decompressed in
//! memory and read as the plain file would be; written, it is compressed.

pub mod las;
pub mod lzf;
pub mod npy;
pub mod off;
pub mod output;
pub mod pcd;
pub mod ply;
pub mod xyz;

use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use rgm_geom::{Point3, PointCloud};

use crate::{DataError, Result};

/// One file format: how its files are named, read and written.
pub trait PointFormat: Sync {
    /// The name errors and help give it (`PLY`).
    fn name(&self) -> &'static str;
    /// Its file extensions, lower case, without the dot.
    fn extensions(&self) -> &'static [&'static str];
    /// What is read and written, for `--help` (`ascii or binary; written binary float32`).
    fn summary(&self) -> &'static str;
    /// The bytes every file of the format starts with: checked before a file is read whole, so
    /// that a large file of another kind is refused unread.
    fn magic(&self) -> Option<&'static [u8]> {
        None
    }
    /// Whether its files are text, one point a line: a point costs more memory (24 bytes) than
    /// the shortest line holding it (`0 0 0`, 6 bytes), which [`check_text_cost`] counts.
    fn is_text(&self) -> bool {
        false
    }
    /// The points in `bytes`, the content of the file `path`; what is odd but readable goes to
    /// `warnings`.
    fn parse(
        &self,
        bytes: &[u8],
        path: &Path,
        warnings: &mut Vec<Warning>,
    ) -> Result<Vec<Point3<f64>>>;
    /// Writes `cloud` in the format.
    fn write(&self, out: &mut dyn Write, cloud: &PointCloud) -> std::io::Result<()>;
}

impl std::fmt::Debug for dyn PointFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Every format rgm reads and writes.
pub static FORMATS: &[&dyn PointFormat] = &[
    &ply::Ply,
    &off::Off,
    &xyz::Xyz,
    &xyz::Csv,
    &npy::Npy,
    &pcd::Pcd,
    &las::Las,
    &las::Laz,
];

/// The format named by `path`'s extension (case-insensitive), the one before `.gz` for a
/// compressed file.
pub fn format_of(path: &Path) -> Result<&'static dyn PointFormat> {
    let inner = if is_gzip(path) {
        Path::new(path.file_stem().unwrap_or_default())
    } else {
        path
    };
    let ext = inner
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    FORMATS
        .iter()
        .copied()
        .find(|f| f.extensions().contains(&ext.as_str()))
        .ok_or_else(|| DataError::UnknownExtension {
            path: path.to_path_buf(),
            expected: extension_list(),
        })
}

/// Every extension of [`FORMATS`] as `.ply, .off, ... or .laz`.
pub fn extension_list() -> String {
    let all: Vec<String> = FORMATS
        .iter()
        .flat_map(|f| f.extensions())
        .map(|e| format!(".{e}"))
        .collect();
    match all.split_last() {
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => String::new(),
    }
}

/// The formats of [`FORMATS`] as the command line's help gives them: one per line,
/// `PLY (.ply): ascii or binary; ...`.
pub fn formats_help() -> String {
    FORMATS
        .iter()
        .map(|f| {
            let exts: Vec<String> = f.extensions().iter().map(|e| format!(".{e}")).collect();
            format!("{} ({}): {}", f.name(), exts.join(", "), f.summary())
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Whether `path` names a gzip-compressed file (its extension is `.gz`, in any case).
pub fn is_gzip(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"))
}

/// Something odd in a file that does not stop it being read (a PLY header line of no keyword
/// the format knows); the caller decides whether to show it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Warning {
    pub path: PathBuf,
    /// Line number, from 1.
    pub line: usize,
    /// The line's text, trimmed.
    pub text: String,
    pub why: String,
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (path, line, why, text) = (self.path.display(), self.line, &self.why, &self.text);
        write!(f, "{path}:{line}: warning: {why}: `{text}`")
    }
}

/// Reads a point cloud, choosing the format by extension; what [`read_point_cloud_warned`]
/// warns of is not shown.
pub fn read_point_cloud(path: impl AsRef<Path>) -> Result<PointCloud> {
    read_point_cloud_warned(path).map(|(cloud, _)| cloud)
}

/// Reads a point cloud, choosing the format by extension (decompressing a `.gz` file first),
/// with the warnings of the reading.
pub fn read_point_cloud_warned(path: impl AsRef<Path>) -> Result<(PointCloud, Vec<Warning>)> {
    let path = path.as_ref();
    let format = format_of(path)?;
    if let Some(magic) = format.magic() {
        if !is_gzip(path) && std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
            // The magic string first: a large file of another kind is refused unread.
            let mut prefix = Vec::with_capacity(magic.len());
            std::fs::File::open(path)
                .and_then(|f| f.take(magic.len() as u64).read_to_end(&mut prefix))
                .map_err(|source| DataError::Io {
                    path: path.to_path_buf(),
                    source,
                })?;
            check_magic(format, &prefix, path)?;
        }
    }
    if format.is_text() && !is_gzip(path) {
        if let Ok(meta) = std::fs::metadata(path) {
            check_text_cost(path, meta.len(), crate::memory::available())?;
        }
    }
    let mut bytes = read_regular_file(path)?;
    if is_gzip(path) {
        // Half of what the process may take: the points read from the content cost about as
        // much again.
        let budget = crate::memory::available().map(|a| a / 2);
        bytes = gunzip(&bytes, path, budget)?;
    }
    let mut warnings = Vec::new();
    let points = format.parse(&bytes, path, &mut warnings)?;
    Ok((checked_cloud(points, path)?, warnings))
}

/// An empty list with room for the `count` points a file at `path` declares, or its refusal
/// ([`check_points_fit`]). For counts the file's size bounds; a count it does not bound (LAZ)
/// is only checked, and the list grows as points are decoded.
pub fn room_for_points(path: &Path, count: u64, decoded: u64) -> Result<Vec<Point3<f64>>> {
    check_points_fit(path, count, decoded)?;
    let mut points = Vec::new();
    usize::try_from(count)
        .ok()
        .and_then(|n| points.try_reserve_exact(n).ok())
        .ok_or_else(|| points_too_large(path, count, decoded, None))?;
    Ok(points)
}

/// Refuses a file at `path` whose `count` points (and `decoded` more bytes the reader must
/// hold, as PCD's decompressed data) need more memory than this process may allocate: a small
/// file may declare billions of points, and Rust aborts on an allocation that fails. Every
/// reader checks its points here before it allocates them.
pub fn check_points_fit(path: &Path, count: u64, decoded: u64) -> Result<()> {
    match crate::memory::available() {
        Some(available) if points_bytes(count, decoded) > available => {
            Err(points_too_large(path, count, decoded, Some(available)))
        }
        _ => Ok(()),
    }
}

fn points_bytes(count: u64, decoded: u64) -> u64 {
    let point = std::mem::size_of::<Point3<f64>>() as u64;
    count.saturating_mul(point).saturating_add(decoded)
}

fn points_too_large(path: &Path, count: u64, decoded: u64, available: Option<u64>) -> DataError {
    DataError::PointsTooLarge {
        path: path.to_path_buf(),
        points: count,
        decoded,
        needs: points_bytes(count, decoded),
        available,
    }
}

/// Bytes of memory a byte of a text file may take to read: itself, and 24 bytes of point for
/// each 6 bytes of the shortest line holding one (`0 0 0`).
const TEXT_COST: u64 = 5;

/// Refuses a text file of `bytes` bytes whose text and points (24 bytes for each 6 bytes of
/// text at most) could take more than `available`: a sparse or huge text file is refused from
/// its size, before it is read.
pub fn check_text_cost(path: &Path, bytes: u64, available: Option<u64>) -> Result<()> {
    let needs = bytes.saturating_mul(TEXT_COST);
    match available {
        Some(available) if needs > available => Err(DataError::TextTooLarge {
            path: path.to_path_buf(),
            bytes,
            needs,
            available,
        }),
        _ => Ok(()),
    }
}

/// Refuses `start`, the first bytes of a file, unless they are `format`'s magic string.
pub fn check_magic(format: &dyn PointFormat, start: &[u8], path: &Path) -> Result<()> {
    match format.magic() {
        Some(magic) if !start.starts_with(magic) => Err(DataError::Format {
            path: path.to_path_buf(),
            format: format.name(),
            why: format!("missing the magic string {}", magic.escape_ascii()),
        }),
        _ => Ok(()),
    }
}

/// The decompressed content of the gzip data `bytes` (every member of a multi-member file).
/// Inflated no further than `budget` bytes: a small file that inflates to gigabytes (a gzip
/// bomb) is refused once its content passes the budget, not when memory runs out.
fn gunzip(bytes: &[u8], path: &Path, budget: Option<u64>) -> Result<Vec<u8>> {
    let limit = budget.unwrap_or(u64::MAX);
    let mut out = Vec::new();
    flate2::read::MultiGzDecoder::new(bytes)
        .take(limit.saturating_add(1))
        .read_to_end(&mut out)
        .map_err(|e| format_error(path, "gzip", e.to_string()))?;
    if out.len() as u64 > limit {
        return Err(DataError::TooLarge {
            path: path.to_path_buf(),
            bytes: out.len() as u64,
            available: budget,
        });
    }
    Ok(out)
}

/// The bytes of the regular file at `path`, read up to the size it had when opened. Folders,
/// devices, FIFOs and sockets are refused before they are opened: an endless stream such as
/// `/dev/zero` would otherwise be read until memory runs out, and a FIFO would block.
pub fn read_regular_file(path: &Path) -> Result<Vec<u8>> {
    let io_error = |source| DataError::Io {
        path: path.to_path_buf(),
        source,
    };
    let kind = std::fs::metadata(path).map_err(io_error)?.file_type();
    if !kind.is_file() {
        return Err(DataError::NotAFile {
            path: path.to_path_buf(),
            kind: if kind.is_dir() {
                "a folder"
            } else {
                "a device, FIFO or socket"
            },
        });
    }
    let file = std::fs::File::open(path).map_err(io_error)?;
    let len = file.metadata().map_err(io_error)?.len();
    // Sized from the metadata before anything is read: a sparse 40 GB file is refused at once.
    let too_large = |available| DataError::TooLarge {
        path: path.to_path_buf(),
        bytes: len,
        available,
    };
    if let Some(available) = crate::memory::available().filter(|&a| len > a) {
        return Err(too_large(Some(available)));
    }
    let mut bytes = Vec::new();
    usize::try_from(len)
        .ok()
        .and_then(|n| bytes.try_reserve_exact(n).ok())
        .ok_or_else(|| too_large(None))?;
    file.take(len).read_to_end(&mut bytes).map_err(io_error)?;
    Ok(bytes)
}

/// Writes a point cloud, choosing the format by extension (each format's
/// [`PointFormat::summary`] says how it writes); as [`output::write_file`] writes (a failed
/// write leaves the path as it was).
pub fn write_point_cloud(path: impl AsRef<Path>, cloud: &PointCloud) -> Result<()> {
    let path = path.as_ref();
    let format = format_of(path)?;
    let io_error = |source| DataError::Io {
        path: path.to_path_buf(),
        source,
    };
    output::write_file(path, |out| {
        if is_gzip(path) {
            let mut gz = flate2::write::GzEncoder::new(out, flate2::Compression::default());
            format.write(&mut gz, cloud)?;
            gz.finish().map(|_| ())
        } else {
            format.write(out, cloud)
        }
    })
    .map_err(io_error)
}

/// The cloud of `points`, rejecting an empty one and any non-finite coordinate.
pub fn checked_cloud(points: Vec<Point3<f64>>, path: &Path) -> Result<PointCloud> {
    if points.is_empty() {
        return Err(DataError::Empty {
            path: path.to_path_buf(),
        });
    }
    if let Some(index) = points
        .iter()
        .position(|p| !p.coords.iter().all(|v| v.is_finite()))
    {
        let p = points[index];
        return Err(DataError::NonFinite {
            path: path.to_path_buf(),
            index,
            x: p.x,
            y: p.y,
            z: p.z,
        });
    }
    Ok(PointCloud::new(points))
}

/// The error for line `line` (from 1) of a text file; the line and the reason quoted in short
/// ([`excerpt`]), so that the error for a 10 MB line of junk is one line of text.
fn line_error(path: &Path, line: usize, text: &str, why: impl Into<String>) -> DataError {
    DataError::Line {
        path: path.to_path_buf(),
        line,
        text: excerpt(text, 80),
        why: excerpt(&why.into(), 200),
    }
}

/// `text` trimmed, cut after `max` characters with its length said when longer.
fn excerpt(text: &str, max: usize) -> String {
    let text = text.trim();
    match text.char_indices().nth(max) {
        None => text.to_string(),
        Some((cut, _)) => format!("{}… ({} bytes)", &text[..cut], text.len()),
    }
}

/// The error for a malformed binary file or header.
fn format_error(path: &Path, format: &'static str, why: impl Into<String>) -> DataError {
    DataError::Format {
        path: path.to_path_buf(),
        format,
        why: why.into(),
    }
}

/// `bytes` as UTF-8 text without its byte-order mark, or an error naming the first bad byte.
fn text<'a>(bytes: &'a [u8], path: &Path, format: &'static str) -> Result<&'a str> {
    let bytes = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
    std::str::from_utf8(bytes).map_err(|e| {
        format_error(
            path,
            format,
            format!("not UTF-8 text (bad byte at offset {})", e.valid_up_to()),
        )
    })
}

/// Parses the first three of `tokens` as x, y, z, or says which one is wrong.
fn parse_xyz<'a>(
    tokens: impl IntoIterator<Item = &'a str>,
    path: &Path,
    line: usize,
    text: &str,
) -> Result<Point3<f64>> {
    let mut xyz = [0.0; 3];
    let mut tokens = tokens.into_iter();
    for (axis, value) in xyz.iter_mut().enumerate() {
        let token = tokens.next().ok_or_else(|| {
            line_error(
                path,
                line,
                text,
                format!("expected 3 coordinates, found {axis}"),
            )
        })?;
        *value = token.trim().parse().map_err(|_| {
            let hint = if token.contains('\u{2212}') {
                " (U+2212 is a minus sign; write -)"
            } else {
                ""
            };
            line_error(
                path,
                line,
                text,
                format!("`{}` is not a number{hint}", excerpt(token, 80)),
            )
        })?;
    }
    Ok(Point3::new(xyz[0], xyz[1], xyz[2]))
}

/// A scratch file path for tests, unique per process and name.
#[cfg(test)]
pub(crate) fn scratch_path(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("rgm-data-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// `len` seeded pseudo-random bytes, for garbage-input tests.
#[cfg(test)]
pub(crate) fn random_bytes(seed: u64, len: usize) -> Vec<u8> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..len).map(|_| rng.gen()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> PointCloud {
        PointCloud::new(vec![
            Point3::new(0.5, -1.25, 2.0),
            Point3::new(1e-3, 3.0, -0.75),
        ])
    }

    #[test]
    fn every_extension_round_trips_through_a_file() {
        let compressed = ["ply.gz", "off.gz", "xyz.gz", "csv.gz", "npy.GZ"];
        for ext in ["ply", "off", "xyz", "txt", "pts", "csv", "npy", "PLY"]
            .into_iter()
            .chain(compressed)
        {
            let path = scratch_path(&format!("round_trip.{ext}"));
            write_point_cloud(&path, &sample()).unwrap();
            let back = read_point_cloud(&path).unwrap();
            // PLY is written as float32; the others keep f64 exactly.
            let tol = if ext.to_ascii_lowercase().starts_with("ply") {
                1e-7
            } else {
                0.0
            };
            for (a, b) in back.points.iter().zip(&sample().points) {
                assert!((a - b).norm() <= tol, "{ext}: {a} vs {b}");
            }
            assert_eq!(back.len(), 2, "{ext}");
        }
    }

    /// A Stanford scan as shipped: an ASCII PLY with stray header lines, gzip-compressed.
    #[test]
    fn a_compressed_ply_is_read_with_its_warnings() {
        let text = "ply\nformat ascii 1.0\nobj_info scanner\nbye\nelement vertex 2\n\
                    property float x\nproperty float y\nproperty float z\nend_header\n\
                    0.5 1 2\n-3 4 5\n";
        let path = scratch_path("scan.ply.gz");
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        gz.write_all(text.as_bytes()).unwrap();
        std::fs::write(&path, gz.finish().unwrap()).unwrap();
        let (cloud, warnings) = read_point_cloud_warned(&path).unwrap();
        assert_eq!(
            cloud.points,
            vec![Point3::new(0.5, 1.0, 2.0), Point3::new(-3.0, 4.0, 5.0)]
        );
        assert_eq!(warnings.len(), 1);
        assert_eq!(
            warnings[0].to_string(),
            format!(
                "{}:4: warning: `bye` is no PLY header keyword; line skipped: `bye`",
                path.display()
            )
        );
        // Not gzip data behind a `.gz` name: an error naming the file, not a panic.
        let plain = scratch_path("plain.xyz.gz");
        std::fs::write(&plain, "1 2 3\n").unwrap();
        let err = read_point_cloud(&plain).unwrap_err().to_string();
        assert!(
            err.starts_with(&format!("{}: gzip: ", plain.display())),
            "{err}"
        );
        let err = read_point_cloud("cloud.gz").unwrap_err();
        assert!(matches!(err, DataError::UnknownExtension { .. }), "{err}");
    }

    /// Issue 44, D9: a text file is sized by what its points may cost (5 times its bytes), not
    /// by its bytes alone.
    #[test]
    fn a_text_file_is_sized_by_its_points() {
        let path = Path::new("big.xyz");
        assert!(check_text_cost(path, 1_000_000_000, Some(5_000_000_000)).is_ok());
        assert!(check_text_cost(path, 1_000_000_000, None).is_ok());
        let err = check_text_cost(path, 2_000_000_000, Some(6_000_000_000)).unwrap_err();
        assert_eq!(
            err.to_string(),
            "big.xyz: 2.0 GB of text, whose points may take 10.0 GB, more than the 6.0 GB of \
             memory this process may allocate"
        );
        assert!(FORMATS.iter().any(|f| f.is_text()));
        assert!(!npy::Npy.is_text());
    }

    /// Issue 44, D9: a row of junk 1 MB long is quoted in short, in the line and in the reason.
    #[test]
    fn a_long_row_of_junk_is_quoted_in_short() {
        let row = "x".repeat(1_000_000);
        let bytes = format!("1 2 3\n{row}\n");
        let err = xyz::Xyz
            .parse(bytes.as_bytes(), Path::new("junk.xyz"), &mut Vec::new())
            .unwrap_err()
            .to_string();
        assert!(err.len() < 400, "{} bytes", err.len());
        assert!(err.starts_with("junk.xyz:2: `xxx"), "{}", &err[..100]);
        assert_eq!(err.matches("… (1000000 bytes)").count(), 2, "{err}");
        assert_eq!(excerpt("  é1234  ", 3), "é12… (6 bytes)");
        assert_eq!(excerpt("short", 80), "short");
    }

    /// Issue 44, D6: a gzip bomb (10 MB of zeros in a few kB) is refused once its content
    /// passes the budget, naming the file; within the budget it inflates whole.
    #[test]
    fn a_gzip_bomb_is_refused_at_its_budget() {
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        gz.write_all(&vec![b'0'; 10_000_000]).unwrap();
        let bomb = gz.finish().unwrap();
        assert!(bomb.len() < 50_000, "{}", bomb.len());
        let path = Path::new("bomb.xyz.gz");
        let err = gunzip(&bomb, path, Some(1_000_000)).unwrap_err();
        assert!(
            matches!(
                err,
                DataError::TooLarge {
                    bytes: 1_000_001,
                    available: Some(1_000_000),
                    ..
                }
            ),
            "{err:?}"
        );
        assert!(
            err.to_string()
                .starts_with("bomb.xyz.gz: 0.0 GB, more than"),
            "{err}"
        );
        assert_eq!(
            gunzip(&bomb, path, Some(10_000_000)).unwrap().len(),
            10_000_000
        );
    }

    #[test]
    fn unknown_extension_and_missing_file_are_named() {
        let err = read_point_cloud("cloud.obj").unwrap_err().to_string();
        assert!(
            err.contains("cloud.obj") && err.contains("unknown point-cloud extension"),
            "{err}"
        );
        let err = read_point_cloud(scratch_path("does_not_exist.ply"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("does_not_exist.ply"), "{err}");
    }

    #[test]
    fn folders_and_endless_devices_are_refused_before_reading() {
        let err = read_point_cloud("/dev/zero").unwrap_err();
        assert!(matches!(err, DataError::UnknownExtension { .. }), "{err}");
        // A `.ply` name for /dev/zero, as a user could make one.
        let link = scratch_path("zero.ply");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        let err = read_point_cloud(&link).unwrap_err().to_string();
        assert_eq!(
            err,
            format!(
                "{}: is a device, FIFO or socket, not a file",
                link.display()
            )
        );
        let folder = scratch_path("folder.xyz");
        std::fs::create_dir_all(&folder).unwrap();
        let err = read_point_cloud(&folder).unwrap_err().to_string();
        assert_eq!(
            err,
            format!("{}: is a folder, not a file", folder.display())
        );
    }

    #[test]
    fn non_finite_and_empty_clouds_are_rejected() {
        let path = Path::new("c.xyz");
        let points = vec![Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, f64::NAN, 0.0)];
        let err = checked_cloud(points, path).unwrap_err().to_string();
        assert_eq!(
            err,
            "c.xyz: point 1 has a non-finite coordinate (1, NaN, 0)"
        );
        let err = checked_cloud(vec![Point3::new(f64::INFINITY, 0.0, 0.0)], path)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("point 0 has a non-finite coordinate (inf"),
            "{err}"
        );
        assert_eq!(
            checked_cloud(vec![], path).unwrap_err().to_string(),
            "c.xyz: the file holds no point"
        );
    }
}
