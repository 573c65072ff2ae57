//! Whether an unrefined result lies where the clouds fit best: a global method's own pose
//! (FGR's, the network's) can coincide well enough to pass the coincidence checks while lying
//! degrees off, so it is refined once, and a pose the refinement moves far is not trusted as
//! it is. The refined pose is not reported: the method's own is, as asked (`--no-refine`).

use rgm_geom::cloud::evenly;
use rgm_geom::{PointCloud, RigidTransform};

use crate::check::{agree, Check};
use crate::methods::refine::{refine, RefineConfig};
use crate::Prepared;

/// A result is doubted when [`refine`] with `refine`, from it, moves it by `within` (degrees,
/// distance) or more. Each cloud is refined on at most `points` of its points, spread evenly:
/// enough to tell degrees, and cheap on a dense scan.
#[derive(Clone, Debug, PartialEq)]
pub struct Precise {
    pub refine: RefineConfig,
    pub within: (f64, f64),
    pub points: usize,
}

impl Check for Precise {
    /// None when the refinement cannot run (too few points): it then says nothing of the pose.
    fn doubt_of(
        &self,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
    ) -> Option<String> {
        let spread = |cloud: &PointCloud| {
            PointCloud::new(evenly(&cloud.points, self.points).copied().collect())
        };
        let refined = refine(&spread(source), &spread(target), transform, &self.refine)
            .ok()?
            .t_target_source;
        (!agree(transform, &refined, self.within)).then(|| {
            format!(
                "the pose is {:.1}° and {:.3} units from where the clouds fit best (refined from \
                 it; at most {}° and {} taken): imprecise, so not trusted unrefined",
                transform.inverse().compose(&refined).rotation_angle_deg(),
                (transform.translation - refined.translation).norm(),
                self.within.0,
                self.within.1
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_geom::testing::airplane;
    use rgm_geom::Vector3;

    #[test]
    fn a_pose_degrees_off_is_doubted_and_a_near_one_is_not() {
        let plane = airplane();
        let check = Precise {
            refine: RefineConfig::default(),
            within: (5.0, 0.05),
            points: 2048,
        };
        let turned = |deg: f64| {
            RigidTransform::new(
                rgm_geom::euler::rotation_xyz_intrinsic(0.0, 0.0, deg.to_radians()),
                Vector3::zeros(),
            )
        };
        let (source, target) = (Prepared::new(&plane), Prepared::new(&plane));
        assert_eq!(check.doubt_of(&source, &target, &turned(1.0)), None);
        let doubt = check
            .doubt_of(&source, &target, &turned(8.0))
            .expect("8° off is doubted");
        assert!(doubt.starts_with("the pose is 8."), "{doubt}");
    }
}
