//! A registration method chosen by name and options, as plain data. The `rgm` command and the
//! Python package both take these from their users and build the [`Method`] here, so that the
//! two run the same method with the same defaults: [`MethodOptions::default`] is what
//! `rgm register` runs when given no option.

use std::path::PathBuf;
use std::str::FromStr;

use rgm_geom::refine::RefineConfig;

use rgm_nn::Precision;

use crate::combined::CombinedRegistrar;
use crate::error::MethodError;
use crate::method::Method;
use crate::network::{Config, TestStatistics};

/// The registration methods selectable by name.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MethodName {
    /// Point-to-point ICP from the identity.
    Icp,
    /// Fast Global Registration on FPFH features.
    Fgr,
    /// The RGM network: the built-in model or given weights.
    Rgm,
    /// RGM and FGR, each refined, and the better by a score without ground truth
    /// ([`crate::combined`]).
    #[default]
    Auto,
}

impl MethodName {
    /// Every name, in the order the command line lists them.
    pub const ALL: [Self; 4] = [Self::Icp, Self::Fgr, Self::Rgm, Self::Auto];

    /// The name as users spell it (`rgm`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Icp => "icp",
            Self::Fgr => "fgr",
            Self::Rgm => "rgm",
            Self::Auto => "auto",
        }
    }
}

impl FromStr for MethodName {
    type Err = MethodError;

    fn from_str(s: &str) -> Result<Self, MethodError> {
        Self::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let known: Vec<&str> = Self::ALL.iter().map(|m| m.name()).collect();
                MethodError::InvalidOptions(format!(
                    "unknown method {s:?} (expected one of {})",
                    known.join(", ")
                ))
            })
    }
}

/// Points matched per cloud with given weights unless `match_points` says otherwise: the paper
/// trains on 1,024-point clouds, and the network's memory grows with the square of the points.
pub const WEIGHTS_MATCH_POINTS: usize = 1024;

/// A method and its options; `None` leaves an option at the method's own default.
#[derive(Clone, Debug, PartialEq)]
pub struct MethodOptions {
    /// The method (RGM and FGR combined by default).
    pub method: MethodName,
    /// RGM weights (for `rgm` and `auto`): a safetensors file with the authors' parameter
    /// names; `None`: the model built into rgm ([`crate::weights::builtin_method`]).
    pub weights: Option<PathBuf>,
    /// The network sizes `weights` were trained with ([`Config::preset`]; `paper` when `None`).
    pub preset: Option<String>,
    /// Batch-norm statistics for `weights` (`running` when `None`, as for the authors'
    /// weights; the built-in model has its own).
    pub test_statistics: Option<TestStatistics>,
    /// RGM matches on at most this many random points of each cloud; 0: every point. When
    /// `None`: the built-in model's training size, or [`WEIGHTS_MATCH_POINTS`] with `weights`.
    pub match_points: Option<usize>,
    /// RGM's passes (2 when `None`, as in the paper).
    pub passes: Option<usize>,
    /// RGM's matrix products: f32 (the default), or bf16 where the processor has AMX or
    /// AVX-512 BF16 ([`Precision`]).
    pub precision: Precision,
    /// Refine the transform of RGM or FGR (both, for `auto`) with [`rgm_geom::refine`]
    /// ([`Method::refined`]); on by default, as in `rgm register` (the paper's protocol, and
    /// `rgm eval`, turn it off). ICP is its own refinement and ignores it.
    pub refine: bool,
}

impl Default for MethodOptions {
    /// What `rgm register` runs when given no option.
    fn default() -> Self {
        Self {
            method: MethodName::default(),
            weights: None,
            preset: None,
            test_statistics: None,
            match_points: None,
            passes: None,
            precision: Precision::F32,
            refine: true,
        }
    }
}

impl MethodOptions {
    /// The method with its weights loaded, refined when asked. Errors name the option that
    /// does not fit the method (an RGM option with ICP or FGR, a preset or statistics without
    /// weights, zero passes or points), or the weight file that failed.
    pub fn build(&self) -> Result<Method, MethodError> {
        self.check()?;
        let method = match self.method {
            MethodName::Icp => Method::icp(),
            MethodName::Fgr => Method::fgr(),
            MethodName::Rgm => self.build_rgm()?,
            MethodName::Auto => {
                let Method::Rgm(rgm) = self.build_rgm()? else {
                    unreachable!("build_rgm builds RGM")
                };
                Method::Combined(Box::new(CombinedRegistrar::new(
                    *rgm,
                    rgm_geom::fgr::FgrConfig::default(),
                    None,
                )))
            }
        };
        Ok(if self.refine {
            method.refined(RefineConfig::default())
        } else {
            method
        })
    }

    fn check(&self) -> Result<(), MethodError> {
        let invalid = |why: &str| Err(MethodError::InvalidOptions(why.to_string()));
        let rgm_only = self.weights.is_some()
            || self.preset.is_some()
            || self.test_statistics.is_some()
            || self.match_points.is_some()
            || self.passes.is_some()
            || self.precision != Precision::F32;
        if matches!(self.method, MethodName::Icp | MethodName::Fgr) && rgm_only {
            return invalid("weights, preset, test statistics, match points, passes and precision apply to the rgm and auto methods only");
        }
        if self.weights.is_none() && (self.preset.is_some() || self.test_statistics.is_some()) {
            return invalid("a preset and test statistics describe given weights; the built-in model has its own");
        }
        if self.passes == Some(0) {
            return invalid("passes must be at least 1");
        }
        Ok(())
    }

    fn build_rgm(&self) -> Result<Method, MethodError> {
        let mut method = match &self.weights {
            Some(weights) => {
                let config = Config::preset(self.preset.as_deref().unwrap_or("paper"))?;
                Method::rgm(config, weights)?
            }
            None => crate::weights::builtin_method()?,
        };
        if let Method::Rgm(registrar) = &mut method {
            if self.weights.is_some() {
                registrar.network.featurer.test_statistics =
                    self.test_statistics.unwrap_or_default();
            }
            if self.weights.is_some() {
                registrar.config.match_points = Some(WEIGHTS_MATCH_POINTS);
            }
            if let Some(points) = self.match_points {
                registrar.config.match_points = (points > 0).then_some(points);
            }
            if let Some(passes) = self.passes {
                registrar.config.passes = passes;
            }
            registrar.config.precision = self.precision;
        }
        Ok(method)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_is_the_built_in_rgm_and_fgr_refined() {
        let method = MethodOptions::default().build().unwrap();
        assert_eq!(method.name(), "auto+icp");
        let Method::Combined(combined) = method else {
            panic!("the combined method")
        };
        assert_eq!(combined.refine, Some(RefineConfig::default()));
        assert_eq!(combined.fgr, rgm_geom::fgr::FgrConfig::default());
        // RGM inside is the built-in model, unrefined (the combined method refines).
        let registrar = combined.rgm;
        assert!(registrar.config.refine.is_none());
        let Method::Rgm(builtin) = crate::weights::builtin_method().unwrap() else {
            panic!("an RGM method")
        };
        assert_eq!(registrar.network.config(), builtin.network.config());
        assert_eq!(registrar.config.match_points, builtin.config.match_points);
        assert_eq!(
            registrar.network.featurer.test_statistics,
            builtin.network.featurer.test_statistics
        );
    }

    #[test]
    fn options_reach_the_method() {
        let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/rgm_tiny_state_dict.safetensors");
        let options = MethodOptions {
            method: MethodName::Rgm,
            weights: Some(weights),
            preset: Some("tiny".into()),
            test_statistics: Some(TestStatistics::Cloud),
            match_points: Some(30),
            passes: Some(3),
            refine: false,
            ..MethodOptions::default()
        };
        let Method::Rgm(registrar) = options.build().unwrap() else {
            panic!("an RGM method")
        };
        assert_eq!(registrar.network.config(), &Config::tiny());
        assert_eq!(
            registrar.network.featurer.test_statistics,
            TestStatistics::Cloud
        );
        assert_eq!(
            (registrar.config.match_points, registrar.config.passes),
            (Some(30), 3)
        );
        assert!(registrar.config.refine.is_none());
        // Given weights without statistics use the running ones (the authors' weights).
        let options = MethodOptions {
            test_statistics: None,
            ..options
        };
        let Method::Rgm(registrar) = options.build().unwrap() else {
            panic!("an RGM method")
        };
        assert_eq!(
            registrar.network.featurer.test_statistics,
            TestStatistics::Running
        );
        for (name, options, expected) in [
            ("fgr", MethodOptions::default(), "fgr+icp"),
            (
                "fgr",
                MethodOptions {
                    refine: false,
                    ..Default::default()
                },
                "fgr",
            ),
            ("icp", MethodOptions::default(), "icp"),
        ] {
            let options = MethodOptions {
                method: name.parse().unwrap(),
                ..options
            };
            assert_eq!(options.build().unwrap().name(), expected);
        }
    }

    #[test]
    fn options_that_do_not_fit_the_method_are_named() {
        let fgr = MethodOptions {
            method: MethodName::Fgr,
            ..Default::default()
        };
        for (options, says) in [
            (
                MethodOptions {
                    passes: Some(1),
                    ..fgr.clone()
                },
                "apply to the rgm and auto methods only",
            ),
            (
                MethodOptions {
                    preset: Some("tiny".into()),
                    ..Default::default()
                },
                "the built-in model has its own",
            ),
            (
                MethodOptions {
                    passes: Some(0),
                    ..Default::default()
                },
                "must be at least 1",
            ),
            (
                MethodOptions {
                    weights: Some("/no/such/file.safetensors".into()),
                    ..Default::default()
                },
                "/no/such/file.safetensors",
            ),
            (
                MethodOptions {
                    weights: Some("w".into()),
                    preset: Some("huge".into()),
                    ..Default::default()
                },
                "unknown preset \"huge\"",
            ),
        ] {
            let err = options.build().unwrap_err().to_string();
            assert!(err.contains(says), "{options:?}: {err}");
        }
        let err = "gicp".parse::<MethodName>().unwrap_err().to_string();
        assert_eq!(
            err,
            "unknown method \"gicp\" (expected one of icp, fgr, rgm, auto)"
        );
    }
}
