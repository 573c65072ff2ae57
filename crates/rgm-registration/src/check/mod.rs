//! How a result is judged without ground truth: the measures ([`overlap_score`],
//! [`turned_share`], [`agree`]), the checks a result must pass ([`Check`]: [`Coincides`],
//! [`CoincidesAtSpacing`], [`Unambiguous`], [`InFrame`]) and the [`Judge`] a composite scores its
//! candidates with, by the caller's [`Scoring`] and [`Acceptance`].
//!
//! Bottom first: `symmetry` (whether a cloud fits itself turned), `overlap` (the measures), `coincidence` (the checks), `precise` (an unrefined result near where the clouds fit
//! best), `judge` (the judge and
//! its configuration).

mod coincidence;
mod judge;
mod overlap;
mod precise;
mod symmetry;

pub use coincidence::{
    coincidence, sampled_overlap, Check, Coincides, CoincidesAtSpacing, InFrame, Unambiguous,
};
pub use judge::{Acceptance, Judge, Scoring};
pub use overlap::{agree, overlap_score, turned_poses, turned_share, OVERLAP_SAMPLE};
pub use precise::Precise;
pub use symmetry::SelfFit;
