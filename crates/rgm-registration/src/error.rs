//! The crate's errors: a geometric step's ([`GeomError`]), and every candidate of a composite
//! method failing ([`AllCandidatesFailed`]). Methods are generic over their error type `E`
//! (`E: From<GeomError>`, and `From<AllCandidatesFailed>` for composites), so that a crate
//! above adds its own causes (rgm-model's `MethodError`: the network's); [`RegistrationError`]
//! is the type for composing this crate's methods alone.

use rgm_geom::GeomError;

/// Every candidate of a composite method failed: each one's cause, `method: why; …`.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("every candidate failed ({0})")]
pub struct AllCandidatesFailed(pub String);

/// What this crate's methods and composites fail with, by themselves.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum RegistrationError {
    #[error(transparent)]
    Geom(#[from] GeomError),
    #[error(transparent)]
    AllCandidatesFailed(#[from] AllCandidatesFailed),
}
