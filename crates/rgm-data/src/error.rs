//! The crate's one error type.

use std::path::PathBuf;

/// Errors of rgm-data. Each variant names the file (or operation) and what is wrong with it.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// The operating system refused a read or write.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The path names a folder, device, FIFO or socket (`/dev/zero` would never end).
    #[error("{}: is {kind}, not a file", path.display())]
    NotAFile { path: PathBuf, kind: &'static str },
    /// A file larger than the memory this process may take (`None`: the allocation failed).
    #[error(
        "{}: {:.1} GB, more than the {} this process may allocate",
        path.display(),
        *bytes as f64 / 1e9,
        available.map_or("memory".to_string(), |a| format!("{:.1} GB of memory", a as f64 / 1e9))
    )]
    TooLarge {
        path: PathBuf,
        bytes: u64,
        available: Option<u64>,
    },
    /// A file that declares more points than the memory this process may allocate holds
    /// (`None`: the allocation failed): refused before anything is allocated for them.
    #[error(
        "{}: {points} points (and {:.1} GB of data to decode) need {:.1} GB, more than the {} this process may allocate",
        path.display(),
        *decoded as f64 / 1e9,
        *needs as f64 / 1e9,
        available.map_or("memory".to_string(), |a| format!("{:.1} GB of memory", a as f64 / 1e9))
    )]
    PointsTooLarge {
        path: PathBuf,
        points: u64,
        decoded: u64,
        needs: u64,
        available: Option<u64>,
    },
    /// A text file whose points could take more memory than the process may allocate.
    #[error(
        "{}: {:.1} GB of text, whose points may take {:.1} GB, more than the {:.1} GB of memory this process may allocate",
        path.display(),
        *bytes as f64 / 1e9,
        *needs as f64 / 1e9,
        *available as f64 / 1e9
    )]
    TextTooLarge {
        path: PathBuf,
        bytes: u64,
        needs: u64,
        available: u64,
    },
    /// A line of a text file (XYZ/CSV, OFF, ASCII PLY) could not be read.
    #[error("{}:{line}: {why}: `{text}`", path.display())]
    Line {
        path: PathBuf,
        line: usize,
        text: String,
        why: String,
    },
    /// A binary file or a file header is malformed (PLY header, truncated data, `.npy` header).
    #[error("{}: {format}: {why}", path.display())]
    Format {
        path: PathBuf,
        format: &'static str,
        why: String,
    },
    /// A point has a NaN or infinite coordinate.
    #[error("{}: point {index} has a non-finite coordinate ({x}, {y}, {z})", path.display())]
    NonFinite {
        path: PathBuf,
        index: usize,
        x: f64,
        y: f64,
        z: f64,
    },
    /// The file holds no point.
    #[error("{}: the file holds no point", path.display())]
    Empty { path: PathBuf },
    /// The file name does not say which format it is.
    #[error("{}: unknown point-cloud extension (expected {expected})", path.display())]
    UnknownExtension {
        path: PathBuf,
        /// The extensions known, as `.ply, .off, ... or .laz` (`io::extension_list`).
        expected: String,
    },
    /// A dataset folder or file does not have the expected layout or contents.
    #[error("{}: {why}", path.display())]
    Dataset { path: PathBuf, why: String },
    /// A pair setting name is not one of clean, noise, partial.
    #[error("unknown setting `{name}` (expected clean, noise or partial)")]
    UnknownSetting { name: String },
    /// A pair-generator setting is out of its range.
    #[error("pair config: {field} = {value} is out of range")]
    InvalidConfig { field: &'static str, value: f64 },
    /// Correspondences that are out of range or not one-to-one.
    #[error("invalid correspondence: {why}")]
    InvalidCorrespondence { why: String },
    /// An index is outside a collection.
    #[error("{op}: index {index} out of range for length {len}")]
    IndexOutOfRange {
        op: &'static str,
        index: usize,
        len: usize,
    },
    /// Shapes that the training-data pack cannot hold, or a pack that does not decode to them
    /// ([`crate::pack`]).
    #[error("pack: {why}")]
    Pack { why: String },
    /// A geometry operation failed.
    #[error(transparent)]
    Geom(#[from] rgm_geom::GeomError),
}

/// Result alias of rgm-data.
pub type Result<T> = std::result::Result<T, DataError>;
