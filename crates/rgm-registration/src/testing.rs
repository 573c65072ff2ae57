//! Shapes shared by the tests of several modules.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use nalgebra::{Matrix3, Point3, Vector3};
use rand::{rngs::StdRng, Rng, SeedableRng};
use rgm_geom::frame::FrameRule;
use rgm_geom::testing::room;
use rgm_geom::{GeomError, PointCloud, RigidTransform};

use crate::check::{Coincides, CoincidesAtSpacing, Scoring};
use crate::fit::Fit;
use crate::registrar::{MethodId, Progress, Registrar, Registration};
use crate::thinning::Density;
use crate::Prepared;

/// A scoring for the composites' tests, of the default's values (rgm-model's `policy::TUNED`,
/// above this crate): distances in unit-sphere units.
pub const SCORING: Scoring = Scoring {
    overlap_distance: 0.02,
    min_overlap: 0.1,
    result_distance: 0.02,
    coincides: None,
};

/// A frame rule for the tests, of the default's values (rgm-model's `policy::TUNED.frame`):
/// ModelNet40's pairs are in the unit-sphere frame already.
pub const FRAME: FrameRule = FrameRule {
    far_outlier: 12.0,
    within: 2.0,
    extent: (0.3, 1.7),
};

/// ModelNet40's density: 1,024 points in the unit sphere.
pub const DENSITY: Density = Density {
    points: 1024,
    voxel: 0.035,
};

/// A spacing check for the tests, of the default's values (rgm-model's
/// `policy::TUNED.coincides_at_spacing`, above this crate).
pub const AT_SPACING: CoincidesAtSpacing = CoincidesAtSpacing {
    coincides: Coincides {
        near: 1.5,
        far: 16.0,
        least: 0.5,
    },
    density: DENSITY,
    scan_lines: 5.0,
};

/// A pose far from the identity (a large turn about no axis in particular, a shift of 2.4), for
/// the global estimators' tests.
pub fn far_pose() -> rgm_geom::RigidTransform {
    rgm_geom::RigidTransform::new(
        rgm_geom::euler::rotation_xyz_intrinsic(0.7, -2.1, 2.9),
        nalgebra::Vector3::new(0.4, -1.3, 2.0),
    )
}

/// `register` (a global estimator on a scene pair) on two samplings of [`room`], one moved by
/// [`far_pose`], at their own scale and at 1,024 times it: within 0.3° and 1 cm (scaled) of the
/// pose at both, and the same rotation at both, since every length follows the point spacing. A
/// power of two scales every coordinate exactly, so the two runs match alike (the refinement's
/// sums round apart a little).
pub fn assert_registers_a_room_at_any_scale(register: impl Fn(&PointCloud, &PointCloud) -> Fit) {
    let truth = far_pose();
    let assert_near = |found: &RigidTransform, truth: &RigidTransform, distance: f64| {
        let angle = found.inverse().compose(truth).rotation_angle_deg();
        let shift = (found.translation - truth.translation).norm();
        assert!(angle < 0.3 && shift < distance, "{angle}° {shift} off");
    };
    let source = room(6000, 1);
    let target = room(6000, 2).transformed(&truth);
    let found = register(&source, &target);
    assert_near(&found.t_target_source, &truth, 0.01);
    let scale = |c: &PointCloud| PointCloud::new(c.points.iter().map(|p| p * 1024.0).collect());
    let big = register(&scale(&source), &scale(&target));
    let big_truth = RigidTransform::new(truth.rotation, truth.translation * 1024.0);
    assert_near(&big.t_target_source, &big_truth, 10.24);
    let angle = big
        .t_target_source
        .inverse()
        .compose(&found.t_target_source)
        .rotation_angle_deg();
    assert!(angle < 1e-3, "{angle}° between the scales");
}

/// A method that answers every pair with one transform (a shift along x), unscored, and records
/// the sizes of the pairs it was given and which calls asked for a scored registration.
#[derive(Clone)]
pub struct Fixed {
    pub name: &'static str,
    pub transform: RigidTransform,
    seen: Arc<Mutex<Vec<(usize, usize)>>>,
    scored: Arc<AtomicUsize>,
}

impl Fixed {
    pub fn new(name: &'static str, shift: f64) -> Self {
        Self {
            name,
            transform: RigidTransform::new(Matrix3::identity(), Vector3::new(shift, 0.0, 0.0)),
            seen: Default::default(),
            scored: Default::default(),
        }
    }

    /// How many pairs it registered.
    pub fn calls(&self) -> usize {
        self.seen.lock().unwrap().len()
    }

    /// How many of its calls were [`Registrar::register_prepared`]'s, not
    /// [`Registrar::register_unscored`]'s.
    pub fn scored_calls(&self) -> usize {
        self.scored.load(Ordering::Relaxed)
    }

    /// The (source, target) sizes of the pairs it registered, in order.
    pub fn seen(&self) -> Vec<(usize, usize)> {
        self.seen.lock().unwrap().clone()
    }
}

impl<E: From<GeomError>> Registrar<E> for Fixed {
    fn id(&self) -> MethodId {
        MethodId::plain(self.name)
    }

    fn register_prepared(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        self.scored.fetch_add(1, Ordering::Relaxed);
        self.register_unscored(source, target, progress)
    }

    fn register_unscored(
        &mut self,
        source: &Prepared,
        target: &Prepared,
        _: &mut dyn FnMut(Progress),
    ) -> Result<Registration, E> {
        self.seen.lock().unwrap().push((source.len(), target.len()));
        let result = Fit::unscored(self.transform, 0, true);
        Ok(Registration::single(result, Vec::new(), Instant::now()))
    }
}

/// A square of `per_side` × `per_side` points `side / per_side` apart in z = 0, from `-side / 2`
/// on each axis, and `strays` points uniform in the cube of side `side` around the origin,
/// reproducible from `seed`: a dense scan with a scanner's spurious returns.
pub fn square_with_strays(side: f64, per_side: usize, strays: usize, seed: u64) -> PointCloud {
    let step = side / per_side as f64;
    let half = side / 2.0;
    let mut points: Vec<Point3<f64>> = (0..per_side)
        .flat_map(|i| {
            (0..per_side)
                .map(move |j| Point3::new(-half + step * i as f64, -half + step * j as f64, 0.0))
        })
        .collect();
    let mut rng = StdRng::seed_from_u64(seed);
    points.extend(
        (0..strays).map(|_| Point3::from(Vector3::from_fn(|_, _| rng.gen_range(-half..half)))),
    );
    PointCloud::new(points)
}
