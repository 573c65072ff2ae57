//! The crate's one error type.

/// Errors of rgm-geom. Each variant says what was wrong with which input.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum GeomError {
    /// An operation needs at least `needed` points and got `got`.
    #[error("{op}: needs at least {needed} point{}, got {got}", if *needed == 1 { "" } else { "s" })]
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_point_is_singular() {
        let err = |needed| GeomError::TooFewPoints {
            op: "kabsch",
            needed,
            got: 0,
        };
        assert_eq!(err(1).to_string(), "kabsch: needs at least 1 point, got 0");
        assert_eq!(err(3).to_string(), "kabsch: needs at least 3 points, got 0");
    }
}
