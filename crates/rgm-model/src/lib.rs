//! rgm-model — RGM put together from the layers below: the network ([`network`]), its
//! test-time procedure as a [`rgm_registration::Registrar`] ([`procedure`], spec §4), training
//! ([`train`]) and checkpoints ([`weights`]). [`options`] composes every method users can name
//! (ICP, FGR, RGM, and `rgm register`'s default, FGR and RGM as a cascade) from the
//! registrars and wrappers of rgm-registration and this crate, into one [`method::Method`];
//! [`evaluate`] runs a method over the benchmark's test pairs and scores it, resumably for long
//! runs (per-pair record files); [`many_pairs`] registers lists of pairs into a resumable JSON
//! Lines file, for the `rgm` command and the Python package alike.
//!
//! Layering rule: rgm-model builds on rgm-geom, rgm-registration, rgm-nn, rgm-match and
//! rgm-data, and nothing builds on it but the `rgm` command, xtask, the cross-crate tests and
//! the Python package (`python/`). It owns no geometry, registration method or tensor op of its
//! own: it keeps the network and composes the named methods.

mod by_name;
pub mod error;
pub mod evaluate;
pub mod many_pairs;
pub mod memory;
pub mod method;
pub mod network;
pub mod options;
pub mod policy;
pub mod procedure;
pub mod progress;
pub mod train;
pub mod weights;

pub use error::MethodError;
pub use evaluate::{PairRecord, ScanRecord, SceneRecord, Summary};
pub use method::Method;
pub use options::{MethodName, MethodOptions};
pub use procedure::{ProcedureConfig, RgmRegistrar, StageTimes};
pub use rgm_registration::registrar::{Candidate, Registrar, Registration};
