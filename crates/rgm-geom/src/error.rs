//! The crate's one error type.

/// Errors of rgm-geom. Each variant says what was wrong with which input.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum GeomError {
    /// An operation needs at least `needed` points and got `got`.
    #[error("{op}: needs at least {needed} points, got {got}")]
    TooFewPoints {
        op: &'static str,
        needed: usize,
        got: usize,
    },
    /// Two inputs that must have equal lengths do not.
    #[error("{op}: length mismatch, {left} vs {right}")]
    LengthMismatch {
        op: &'static str,
        left: usize,
        right: usize,
    },
    /// The problem has no unique solution (e.g. all weights zero, collinear points).
    #[error("{op}: degenerate input: {why}")]
    Degenerate { op: &'static str, why: String },
    /// A 4×4 matrix is not a rigid transform.
    #[error("not a rigid transform: {why}")]
    NotRigid { why: String },
    /// A numeric input is NaN or infinite.
    #[error("{op}: non-finite value in input")]
    NonFinite { op: &'static str },
}

/// Result alias of rgm-geom.
pub type Result<T> = std::result::Result<T, GeomError>;
