//! The crate's one error type.

/// Errors of rgm-match. Each variant names the op and the values that were wrong.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MatchError {
    /// A buffer does not have the shape the op needs.
    #[error("{op}: {what} has shape {got:?}, expected {expected:?}")]
    Shape {
        op: &'static str,
        what: &'static str,
        got: Vec<usize>,
        expected: Vec<usize>,
    },
    /// A ground-truth pair lies outside the N×M matrix.
    #[error("{op}: pair ({i}, {j}) outside a {n}×{m} matrix")]
    PairOutOfRange {
        op: &'static str,
        i: usize,
        j: usize,
        n: usize,
        m: usize,
    },
    /// A ground-truth pair is listed twice.
    #[error("{op}: pair ({i}, {j}) listed twice")]
    DuplicatePair {
        op: &'static str,
        i: usize,
        j: usize,
    },
    /// A setting is outside the values the op accepts.
    #[error("{op}: invalid setting: {why}")]
    Config { op: &'static str, why: &'static str },
    /// An input holds NaN or an infinity.
    #[error("{op}: non-finite value in {what}")]
    NonFinite {
        op: &'static str,
        what: &'static str,
    },
}

/// Result alias of rgm-match.
pub type Result<T> = std::result::Result<T, MatchError>;

/// Checks that `got` equals `expected`, naming the op and the buffer otherwise.
pub(crate) fn check_shape(
    op: &'static str,
    what: &'static str,
    got: &[usize],
    expected: &[usize],
) -> Result<()> {
    if got == expected {
        Ok(())
    } else {
        Err(MatchError::Shape {
            op,
            what,
            got: got.to_vec(),
            expected: expected.to_vec(),
        })
    }
}
