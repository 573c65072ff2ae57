//! The crate's one error type.

use std::path::PathBuf;

/// Errors of rgm-nn. Each variant names the op (or file) and the offending values.
#[derive(Debug, thiserror::Error)]
pub enum NnError {
    /// A buffer handed to an op has the wrong shape.
    #[error("{op}: {what} has shape {got:?}, expected {expected:?}")]
    Shape {
        op: &'static str,
        what: &'static str,
        expected: Vec<usize>,
        got: Vec<usize>,
    },
    /// An index (a neighbour index, ...) points outside the rows it indexes.
    #[error("{op}: index {index} out of range for {len} rows")]
    IndexOutOfRange {
        op: &'static str,
        index: usize,
        len: usize,
    },
    /// A size or hyper-parameter is not valid for the op.
    #[error("{op}: invalid argument: {why}")]
    InvalidArgument { op: &'static str, why: String },
    /// A tensor a layer needs is missing from a weight file.
    #[error("{path}: tensor {name:?} is missing")]
    MissingTensor { path: PathBuf, name: String },
    /// A tensor in a weight file has another shape than the layer's.
    #[error("{path}: tensor {name:?} has shape {got:?}, expected {expected:?}")]
    TensorShape {
        path: PathBuf,
        name: String,
        expected: Vec<usize>,
        got: Vec<usize>,
    },
    /// A tensor in a weight file holds NaN or an infinity: the weights are broken (a training
    /// run that diverged, a damaged file), whatever clouds they are run on.
    #[error(
        "{path}: tensor {name:?} holds a non-finite value ({value} at element {index}): these \
         weights are broken (a diverged training run or a damaged file), not the clouds"
    )]
    NonFiniteWeight {
        path: PathBuf,
        name: String,
        index: usize,
        value: f64,
    },
    /// A tensor in a weight file has an element type other than f32, f64 or bf16.
    #[error("{path}: tensor {name:?} has dtype {dtype}, expected F32, F64 or BF16")]
    TensorDtype {
        path: PathBuf,
        name: String,
        dtype: String,
    },
    /// A file read as weights is not safetensors (or is damaged); `why` says what is wrong in
    /// words, not in the library's variant names.
    #[error("{path}: not a safetensors weight file: {why}")]
    NotSafetensors { path: PathBuf, why: String },
    /// The path names a folder, device, FIFO or socket.
    #[error("{path}: is {kind}, not a file")]
    NotAFile { path: PathBuf, kind: &'static str },
    /// Writing a safetensors file failed.
    #[error("{path}: {source}")]
    Safetensors {
        path: PathBuf,
        source: safetensors::SafeTensorError,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Result alias of rgm-nn.
pub type Result<T> = std::result::Result<T, NnError>;

/// Checks that every named buffer in `buffers` has the shape `expected`.
pub fn check_shapes(
    op: &'static str,
    expected: &[usize],
    buffers: &[(&'static str, &[usize])],
) -> Result<()> {
    buffers
        .iter()
        .try_for_each(|(what, got)| check_shape(op, what, got, expected))
}

/// Checks that `got` equals `expected`, naming the op and the buffer otherwise.
pub fn check_shape(
    op: &'static str,
    what: &'static str,
    got: &[usize],
    expected: &[usize],
) -> Result<()> {
    if got == expected {
        Ok(())
    } else {
        Err(NnError::Shape {
            op,
            what,
            expected: expected.to_vec(),
            got: got.to_vec(),
        })
    }
}
