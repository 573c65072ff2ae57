//! A registration method of any kind behind one type, as the command line, the Python package
//! and the tables hold it: a boxed [`Registrar`] that reports a transform or a score that is
//! not a finite number as an error, never as a result.

use std::fmt;

use rgm_registration::registrar::{DynRegistrar, MethodId, Progress, Registrar, Registration};
use rgm_registration::Prepared;

use crate::error::MethodError;

/// Any registrar, composed or not (built from names and options by
/// [`crate::options::MethodOptions::build`]).
#[derive(Clone)]
pub struct Method(Box<dyn DynRegistrar<MethodError>>);

impl fmt::Debug for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Method({})", self.id())
    }
}

impl Method {
    /// `registrar` as a method.
    pub fn new(registrar: impl DynRegistrar<MethodError> + 'static) -> Self {
        Self(Box::new(registrar))
    }

    /// The method's name as users spell it (`fgr+refine`).
    pub fn name(&self) -> String {
        self.id().to_string()
    }

    /// Whether the method's transform is refined ([`rgm_registration::refiner`]).
    pub fn is_refined(&self) -> bool {
        self.id().refiner.is_some()
    }
}

impl Registrar<MethodError> for Method {
    fn id(&self) -> MethodId {
        self.0.id()
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, MethodError> {
        // Said as what it is, not as a symmetric shape's ambiguity (which the checks would find).
        for (cloud, prepared) in [("source", source), ("target", target)] {
            let points = &prepared.points;
            if points.len() > 1 && points.iter().all(|p| p == &points[0]) {
                return Err(MethodError::OnePlace {
                    cloud,
                    points: points.len(),
                });
            }
        }
        let found = self.0.register_prepared(source, target, progress)?;
        let result = &found.result;
        let t = &result.t_target_source;
        let values = t.rotation.iter().chain(t.translation.iter());
        if !values
            .chain([&result.fitness, &result.inlier_rmse])
            .all(|v| v.is_finite())
        {
            return Err(MethodError::NotFinite {
                method: self.name(),
                found: format!("{:?}", t.to_rows()),
            });
        }
        Ok(found)
    }
}
