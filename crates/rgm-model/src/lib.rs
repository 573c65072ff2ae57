//! rgm-model — RGM put together from the layers below, and every registration method behind one
//! interface: [`method::Method`] runs ICP, FGR, the RGM network ([`pipeline`], spec §4) or RGM
//! and FGR together ([`combined`], `rgm register`'s default) on a pair of clouds; [`options`]
//! builds one from a name and options, with `rgm register`'s defaults; [`evaluate`] runs a
//! method over the benchmark's test pairs and scores it.
//!
//! Layering rule: rgm-model builds on rgm-geom, rgm-nn, rgm-match and rgm-data, and nothing
//! builds on it but the `rgm` command, xtask and the Python package (`python/`). It owns no
//! geometry or tensor op of its own.

pub mod combined;
pub mod error;
pub mod evaluate;
pub mod memory;
pub mod method;
pub mod network;
pub mod options;
pub mod pipeline;
pub mod train;
pub mod weights;

pub use combined::{Candidate, CombinedRegistrar};
pub use error::MethodError;
pub use evaluate::{PairRecord, ScanRecord, Summary};
pub use method::{Method, Registration};
pub use options::{MethodName, MethodOptions};
pub use pipeline::{Normalisation, PipelineConfig, RgmRegistrar, StageTimes};
