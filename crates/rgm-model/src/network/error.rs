//! The network's error type: its own failures and those of the layers below.

/// Errors of the RGM network. Each names the step and the values that were wrong.
#[derive(Debug, thiserror::Error)]
pub enum NetworkError {
    /// A configuration that cannot build a network.
    #[error("rgm config: {why}")]
    Config { why: String },
    /// A cloud handed to the network is not an (N, 3) matrix of finite coordinates.
    #[error("rgm forward: {what} has shape {got:?}, expected (rows, 3)")]
    InputShape { what: &'static str, got: Vec<usize> },
    /// `backward` got a cache that no forward filled, or a gradient of the wrong shape.
    #[error("rgm backward: {why}")]
    Backward { why: String },
    /// A weight tensor the network needs is missing.
    #[error("weights: tensor {name:?} is missing")]
    MissingTensor { name: String },
    /// A weight tensor has another shape than the network's.
    #[error("weights: tensor {name:?} has shape {got:?}, expected {expected:?}")]
    TensorShape {
        name: String,
        expected: Vec<usize>,
        got: Vec<usize>,
    },
    /// A tensor op failed (rgm-nn).
    #[error(transparent)]
    Nn(#[from] rgm_nn::NnError),
    /// A matching op failed (rgm-match).
    #[error(transparent)]
    Match(#[from] rgm_match::MatchError),
    /// The neighbour graph could not be built (rgm-geom).
    #[error(transparent)]
    Geom(#[from] rgm_geom::GeomError),
}

/// Result alias of the network.
pub type Result<T> = std::result::Result<T, NetworkError>;
