//! Methods made of methods, which know nothing of what they wrap: the wrappers ([`Refined`],
//! [`Normalised`], [`AtResolution`], [`RefinedWhereNear`], [`UpTo`], [`OnFirstUse`], [`Checked`]) and the composites,
//! which run candidate methods and keep the result their [`crate::check::Judge`] scores best
//! ([`BestOf`], [`Cascade`], and [`Thinned`] on several thinnings of a dense pair).
//!
//! Bottom first: `wrappers`, `composite` (the [`Composite`] trait, [`BestOf`], [`Cascade`]),
//! `thinned`.

mod composite;
mod thinned;
mod wrappers;

pub use composite::{conclude, BestOf, Cascade, Composite, Outcome};
pub use thinned::Thinned;
pub use wrappers::{
    AtResolution, Checked, Named, Normalised, OnFirstUse, Refined, RefinedWhereNear, UpTo,
};
