//! Whether a result's overlap is one where the clouds coincide, or one where they only lie near
//! each other: a ground-truth-free check that a composite's overlap score cannot make.
//!
//! Under a right transform the overlapping parts of two clouds lie on one surface, so the points
//! near the other cloud are nearly all very near it (within the noise or a point spacing). Under
//! a wrong one that still overlaps — a part of a cloud placed on the wrong part of the whole,
//! clouds that do not overlap at all pressed together, a room slid along its floor — the
//! surfaces cross or graze, and the distances spread evenly up to the loose ones. [`Coincides`]
//! measures that spread: of the points within `far` of the other cloud (both ways), the share
//! within `near`; below `least`, the result is doubted ([`Registration::doubt`]).
//! [`Checked`](crate::compose::Checked) puts a [`Check`] on any registrar. The tuned lengths and
//! shares are configuration, set where methods are composed.

use rgm_geom::cloud::evenly;
use rgm_geom::frame::{FrameRule, NearPair, Normalisation};
use rgm_geom::{KnnIndex, Point3, RigidTransform};

use crate::check::{turned_poses, SelfFit};
use crate::fit::{count_within, NEAREST_BLOCK};
use crate::prepared::{indexed_pair, Prepared};
use crate::registrar::Registration;
use crate::thinning::Density;

/// At most this many points of each cloud are measured: the shares settle long before a dense
/// scan's 300,000 points.
const SAMPLE: usize = 4096;

/// Of at most [`SAMPLE`] of `points` moved by `moved`: how many lie within `near` of `onto`,
/// how many within `far`, and how many were measured.
fn within(
    points: &[Point3<f64>],
    onto: &KnnIndex,
    moved: &RigidTransform,
    near: f64,
    far: f64,
) -> (usize, usize, usize) {
    let sample: Vec<Point3<f64>> = evenly(points, SAMPLE).copied().collect(); // (S,)
    let (within_near, within_far) = count_within(&sample, onto, moved, near, far);
    (within_near, within_far, sample.len())
}

/// Of the points of both clouds that `transform` brings within `far` of the other cloud, the
/// share within `near` (0 when none is within `far`). Measured on at most 4,096 (`SAMPLE`)
/// points of each cloud, against the other whole; once per registration for each transform and
/// lengths ([`Prepared::coincidence`]).
pub fn coincidence(
    source: &Prepared,
    target: &Prepared,
    transform: &RigidTransform,
    near: f64,
    far: f64,
) -> f64 {
    source.coincidence(target, transform, (near, far), || {
        let (there_near, there_far, _) =
            within(&source.points, target.index(), transform, near, far);
        let (back_near, back_far, _) = within(
            &target.points,
            source.index(),
            &transform.inverse(),
            near,
            far,
        );
        let far_total = there_far + back_far;
        if far_total == 0 {
            return 0.0;
        }
        (there_near + back_near) as f64 / far_total as f64
    })
}

/// A ground-truth-free test of a registration, made after it.
pub trait Check {
    /// Why `transform` (a pose of `source` on `target`) is not to be trusted, if it is not.
    fn doubt_of(
        &self,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
    ) -> Option<String>;

    /// Why `found` (the registration of `source` onto `target`) is not to be trusted, if it is
    /// not: its transform's doubt, unless the check weighs more of it (its candidates).
    fn doubt(&self, source: &Prepared, target: &Prepared, found: &Registration) -> Option<String> {
        self.doubt_of(source, target, &found.result.t_target_source)
    }
}

/// Both checks, the first's doubt first.
impl<A: Check, B: Check> Check for (A, B) {
    fn doubt_of(
        &self,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
    ) -> Option<String> {
        self.0
            .doubt_of(source, target, transform)
            .or_else(|| self.1.doubt_of(source, target, transform))
    }

    fn doubt(&self, source: &Prepared, target: &Prepared, found: &Registration) -> Option<String> {
        self.0
            .doubt(source, target, found)
            .or_else(|| self.1.doubt(source, target, found))
    }
}

/// The clouds must coincide where they overlap: of the points within `far` of the other cloud,
/// at least `least` within `near` ([`coincidence`]). Lengths in the clouds' units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coincides {
    pub near: f64,
    pub far: f64,
    pub least: f64,
}

impl Coincides {
    /// Whether the clouds coincide under `transform`: its doubt's opposite, unformatted.
    pub fn holds(&self, source: &Prepared, target: &Prepared, transform: &RigidTransform) -> bool {
        self.share_at(source, target, transform, 1.0) >= self.least
    }

    /// [`coincidence`] of `transform` at its lengths scaled by `unit`.
    fn share_at(
        &self,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
        unit: f64,
    ) -> f64 {
        coincidence(source, target, transform, self.near * unit, self.far * unit)
    }

    /// Its doubt of `transform`, lengths scaled by `unit` and named `in_units`.
    fn doubt_at(
        &self,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
        unit: f64,
        in_units: &str,
    ) -> Option<String> {
        let share = self.share_at(source, target, transform, unit);
        (share < self.least).then(|| {
            format!(
                "the clouds lie near each other but do not coincide: of the points within {} \
                 {in_units} of the other cloud, {share:.2} lie within {} (less than {}); the fit \
                 may be wrong (one cloud placed on the wrong part of the other, clouds that do \
                 not overlap, or a slide)",
                self.far, self.near, self.least
            )
        })
    }
}

impl Check for Coincides {
    fn doubt_of(
        &self,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
    ) -> Option<String> {
        self.doubt_at(source, target, transform, 1.0, "units")
    }
}

/// [`Coincides`] with its lengths in point spacings (the larger of the two clouds' median
/// nearest-neighbour distances), on pairs denser than `density` whose points spread over their
/// surfaces only: a sparse pair's noise may exceed its spacing, and a scan-line cloud's (a LiDAR
/// sweep's rings) spacing is the gap along a line, far below the gap between lines that a right
/// fit leaves between two sweeps. On those the spacing says nothing of a fit: the check doubts
/// nothing and takes nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoincidesAtSpacing {
    pub coincides: Coincides,
    pub density: Density,
    /// The least ratio of a cloud's median distance to its 16th nearest neighbour to the median
    /// distance to its nearest that marks scan lines: points spread over a surface reach 16
    /// neighbours within about 4 spacings, points along lines within about 8.
    pub scan_lines: f64,
}

/// `cloud`'s median nearest-neighbour distance ([`Prepared::spacings`]), or `None` when its
/// points lie along scan lines ([`CoincidesAtSpacing::scan_lines`]).
fn surface_spacing(cloud: &Prepared, scan_lines: f64) -> Option<f64> {
    // Both NaN for a cloud of fewer than 17 points, which the comparison then refuses.
    let (spacing, wide) = cloud.spacings();
    (wide < scan_lines * spacing).then_some(spacing)
}

impl CoincidesAtSpacing {
    /// The pair's spacing, when the check applies to it.
    pub fn spacing(&self, source: &Prepared, target: &Prepared) -> Option<f64> {
        if !self.density.is_exceeded_by(source.len(), target.len()) {
            return None;
        }
        let spacing = |cloud| surface_spacing(cloud, self.scan_lines);
        Some(spacing(source)?.max(spacing(target)?))
    }

    /// Whether it takes `transform` as coinciding: never where it does not apply, so that a
    /// cascade it judges runs its later candidates there.
    pub fn takes(&self, source: &Prepared, target: &Prepared, transform: &RigidTransform) -> bool {
        self.spacing(source, target).is_some_and(|spacing| {
            self.coincides.share_at(source, target, transform, spacing) >= self.coincides.least
        })
    }
}

impl Check for CoincidesAtSpacing {
    /// None where it does not apply.
    fn doubt_of(
        &self,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
    ) -> Option<String> {
        let spacing = self.spacing(source, target)?;
        self.coincides
            .doubt_at(source, target, transform, spacing, "point spacings")
    }
}

/// The share of the points of each cloud that `transform` brings within `distance` of the
/// other, both ways (0 to 2, as [`crate::check::overlap_score`]), measured on at most
/// 4,096 (`SAMPLE`) points of each cloud.
pub fn sampled_overlap(
    source: &Prepared,
    target: &Prepared,
    transform: &RigidTransform,
    distance: f64,
) -> f64 {
    overlap_reaching(source, target, transform, distance, f64::NEG_INFINITY).unwrap_or(0.0)
}

/// [`sampled_overlap`] where it reaches `least`; `None` as soon as the points left to measure
/// cannot bring it there (most rivals of a pose that tells itself fall short after a few
/// hundred queries of the 8,192).
fn overlap_reaching(
    source: &Prepared,
    target: &Prepared,
    transform: &RigidTransform,
    distance: f64,
    least: f64,
) -> Option<f64> {
    // The share of `points` moved by `moved` within `distance` of `onto`, if it reaches `least`:
    // counted two of `count_within`'s blocks at a time (side by side), and given up after the
    // first round whose misses leave it short (the same answer as point by point, a few queries
    // later).
    let share = |points: &[Point3<f64>], onto: &KnnIndex, moved: &RigidTransform, least: f64| {
        let sample: Vec<Point3<f64>> = evenly(points, SAMPLE).copied().collect(); // (S,)
        let all = sample.len();
        let needed = least * all.max(1) as f64;
        let (mut near, mut seen) = (0usize, 0usize);
        for round in sample.chunks(2 * NEAREST_BLOCK) {
            near += count_within(round, onto, moved, distance, distance).0;
            seen += round.len();
            if ((near + all - seen) as f64) < needed {
                return None;
            }
        }
        Some(near as f64 / all.max(1) as f64)
    };
    let there = share(&source.points, target.index(), transform, least - 1.0)?;
    let back = share(
        &target.points,
        source.index(),
        &transform.inverse(),
        least - there,
    )?;
    Some(there + back)
}

/// No other pose fits nearly as well: a result is doubted when a rival pose overlaps the
/// target at least `share` as much (by [`sampled_overlap`] at `distance`, or by the
/// composite's own scores) and passes `rivals_pass` too. Rivals are the other candidates of a
/// composite more than `apart` (degrees, distance) from the chosen one, and the result turned
/// about the source's axes ([`turned_poses`]). And it is doubted when either cloud fits itself
/// turned ([`SelfFit`]): every pose turned by the symmetry fits exactly as well, whether or not
/// the rival's own overlap, unrefined, clears `rivals_pass` (on a resampled surface it may miss
/// by a little where the result's refined one just cleared it). A symmetric shape, or a part
/// that fits two places of the other cloud, has no one pose that the clouds tell; reporting one
/// as registered would be a guess.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unambiguous<C> {
    pub share: f64,
    pub distance: f64,
    pub apart: (f64, f64),
    pub rivals_pass: C,
    pub self_fit: SelfFit,
}

impl<C: Check> Unambiguous<C> {
    fn rival_doubt(&self, what: &str, ratio: f64) -> String {
        format!(
            "another pose fits nearly as well ({what}, {ratio:.2} of the result's overlap, at \
             least {}): the pose is ambiguous (a symmetric shape, or a part that fits two places)",
            self.share
        )
    }

    fn far_apart(&self, a: &RigidTransform, b: &RigidTransform) -> bool {
        let (degrees, distance) = self.apart;
        a.inverse().compose(b).rotation_angle_deg() > degrees
            || (a.translation - b.translation).norm() > distance
    }
}

impl<C: Check> Check for Unambiguous<C> {
    /// The turned poses of `transform` as its rivals.
    fn doubt_of(
        &self,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
    ) -> Option<String> {
        let own = sampled_overlap(source, target, transform, self.distance);
        if own <= 0.0 {
            return None;
        }
        // A hair below the share, so that rounding never drops a rival that reaches it.
        let least = self.share * own * (1.0 - 1e-9);
        let rival = turned_poses(source, transform).iter().find_map(|turned| {
            let ratio = overlap_reaching(source, target, turned, self.distance, least)? / own;
            (ratio >= self.share && self.rivals_pass.doubt_of(source, target, turned).is_none())
                .then(|| self.rival_doubt("the result turned about an axis of the source", ratio))
        });
        rival.or_else(|| {
            let (which, turn) = [("source", source), ("target", target)]
                .into_iter()
                .find_map(|(which, cloud)| {
                    Some((which, self.self_fit.symmetry(cloud, cloud.index())?))
                })?;
            Some(format!(
                "the {which} fits itself turned by {:.0}°: every pose turned so fits as well, and \
                 the pose is ambiguous (a symmetric shape)",
                turn.rotation_angle_deg()
            ))
        })
    }

    /// The other candidates as rivals too, weighed by the composite's scores.
    fn doubt(&self, source: &Prepared, target: &Prepared, found: &Registration) -> Option<String> {
        let chosen = found.chosen.and_then(|i| found.candidates.get(i));
        let rival = chosen.and_then(|chosen| {
            let score = chosen.score.filter(|&score| score > 0.0)?;
            found.candidates.iter().find_map(|other| {
                let ratio = other.score? / score;
                (!std::ptr::eq(other, chosen)
                    && ratio >= self.share
                    && self.far_apart(&chosen.t_target_source, &other.t_target_source)
                    && self
                        .rivals_pass
                        .doubt_of(source, target, &other.t_target_source)
                        .is_none())
                .then(|| self.rival_doubt(&format!("{}'s", other.method), ratio))
            })
        });
        rival.or_else(|| self.doubt_of(source, target, &found.result.t_target_source))
    }
}

/// `check` measured in the unit-sphere frame `rule` gives the pair ([`Normalisation::of_pair`]),
/// the far outliers left out, while the method it checks runs in the caller's frame: for a
/// method whose start the frame would move (ICP from a given pose), checked with lengths tuned
/// in that frame. A pair in the frame already is measured as it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InFrame<C> {
    pub check: C,
    pub rule: FrameRule,
}

impl<C: Check> InFrame<C> {
    /// `measure` on the pair moved into its frame, given the frame.
    fn measured<T>(
        &self,
        source: &Prepared,
        target: &Prepared,
        measure: impl FnOnce(&Prepared, &Prepared, &Normalisation) -> T,
    ) -> T {
        let near = NearPair::of(source, target, &self.rule);
        if near.frame.is_identity() {
            return measure(source, target, &near.frame);
        }
        let (fs, ft) = near.moved(); // (N', 3), (M', 3)
        let (fs, ft) = (Prepared::new(fs), Prepared::new(ft));
        indexed_pair(&fs, &ft);
        measure(&fs, &ft, &near.frame)
    }
}

impl<C: Check> Check for InFrame<C> {
    fn doubt_of(
        &self,
        source: &Prepared,
        target: &Prepared,
        transform: &RigidTransform,
    ) -> Option<String> {
        self.measured(source, target, |fs, ft, frame| {
            self.check.doubt_of(fs, ft, &frame.redo(transform))
        })
    }

    /// `found` with its result's and candidates' transforms moved into the frame.
    fn doubt(&self, source: &Prepared, target: &Prepared, found: &Registration) -> Option<String> {
        self.measured(source, target, |fs, ft, frame| {
            let mut in_frame = found.clone();
            in_frame.result.t_target_source = frame.redo(&found.result.t_target_source);
            for candidate in &mut in_frame.candidates {
                candidate.t_target_source = frame.redo(&candidate.t_target_source);
            }
            self.check.doubt(fs, ft, &in_frame)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compose::Checked;
    use crate::registrar::Registrar;
    use crate::testing::{Fixed, AT_SPACING};
    use rgm_geom::testing::airplane;
    use std::time::Instant;

    use rgm_geom::{Matrix3, Point3, PointCloud, Vector3};

    /// The rival check of the default's values (rgm-model's `policy::TUNED.unambiguous`) but for
    /// the coincidence a rival must reach (`least`) and the share of a cloud's points that must
    /// fit it turned (`self_share`).
    fn unambiguous(least: f64, self_share: f64) -> Unambiguous<Coincides> {
        Unambiguous {
            share: 0.75,
            distance: 0.02,
            apart: (5.0, 0.05),
            rivals_pass: Coincides {
                near: 0.02,
                far: 0.08,
                least,
            },
            self_fit: SelfFit {
                within: 1.0,
                share: self_share,
                near_equal: 0.8,
                flat: 0.1,
            },
        }
    }

    /// A cloud coincides with itself; shifted by a little less than `far` it lies near itself
    /// everywhere and coincides nowhere.
    #[test]
    fn a_copy_coincides_and_a_shifted_copy_does_not() {
        let shape = airplane();
        let s = Prepared::new(&shape);
        let same = coincidence(&s, &s, &RigidTransform::identity(), 0.02, 0.08);
        assert_eq!(same, 1.0);
        let shift =
            RigidTransform::new(rgm_geom::Matrix3::identity(), Vector3::new(0.05, 0.0, 0.0));
        let shifted = coincidence(&s, &s, &shift, 0.02, 0.08);
        assert!(shifted < 0.3, "{shifted}");
        let far = RigidTransform::new(rgm_geom::Matrix3::identity(), Vector3::new(5.0, 0.0, 0.0));
        assert_eq!(coincidence(&s, &s, &far, 0.02, 0.08), 0.0);
    }

    /// A dense plane grid, and the same grid slid by 3.3 spacings along itself and lifted by 3
    /// spacings off it: the slid copy coincides (it lies on the same surface), the lifted one
    /// does not, in spacings whatever the units.
    #[test]
    fn at_spacing_tells_a_lifted_surface_from_a_slid_one_at_any_scale() {
        for unit in [1e-3, 1.0, 1e3] {
            let points: Vec<_> = (0..60)
                .flat_map(|i| (0..60).map(move |j| (i, j)))
                .map(|(i, j)| rgm_geom::Point3::new(i as f64 * unit, j as f64 * unit, 0.0))
                .collect();
            let plane = PointCloud::new(points);
            let p = Prepared::new(&plane);
            let check = AT_SPACING;
            let found = |t: Vector3<f64>| {
                let transform = RigidTransform::new(rgm_geom::Matrix3::identity(), t * unit);
                let unscored = crate::fit::Score {
                    inlier_count: 0,
                    fitness: 0.0,
                    inlier_rmse: 0.0,
                };
                let result = crate::Fit::scored(transform, 0, true, unscored);
                Registration::single(result, Vec::new(), Instant::now())
            };
            let slid = found(Vector3::new(3.3, 0.0, 0.0));
            assert_eq!(check.doubt(&p, &p, &slid), None, "unit {unit}");
            let lifted = found(Vector3::new(0.0, 0.0, 3.0));
            assert!(check.doubt(&p, &p, &lifted).is_some(), "unit {unit}");
        }
    }

    /// Issue 44, D1: a part of a dense bumpy sheet, given back on its place, is not doubted;
    /// turned a quarter and put on another part of the sheet, where it lies near the surface
    /// everywhere, it is, as it is far off the sheet.
    #[test]
    fn a_part_put_on_the_wrong_part_of_the_whole_is_doubted() {
        let sheet = PointCloud::new(
            (0..120)
                .flat_map(|i| (0..120).map(move |j| (i, j)))
                .map(|(i, j)| {
                    let (x, y) = (i as f64 / 60.0 - 1.0, j as f64 / 60.0 - 1.0);
                    Point3::new(x, y, 0.1 * (3.0 * x).sin() * (2.0 * y).cos())
                })
                .collect(),
        );
        let centre = Point3::new(0.2, -0.1, 0.0);
        let part: Vec<usize> = (0..sheet.len())
            .filter(|&i| (sheet.points[i].xy() - centre.xy()).norm() < 0.45)
            .collect();
        let pose = RigidTransform::new(
            rgm_geom::euler::rotation_xyz_intrinsic(0.3, -0.2, 0.5),
            Vector3::new(0.4, 0.1, -0.2),
        );
        let source = sheet.select(&part).transformed(&pose); // (N', 3), a sixth of the sheet
        let right = pose.inverse();
        let quarter = RigidTransform::new(
            nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2)
                .into_inner(),
            Vector3::new(-0.5, 0.3, 0.0),
        );
        let check = AT_SPACING;
        let checked = |transform: RigidTransform| {
            let mut fixed = Fixed::new("fixed", 0.0);
            fixed.transform = transform;
            let mut method = Checked {
                inner: fixed,
                check,
            };
            Registrar::<rgm_geom::GeomError>::register(&mut method, &source, &sheet)
                .unwrap()
                .doubt
        };
        assert_eq!(checked(right), None);
        let doubt = checked(quarter.compose(&right)).expect("a wrong place is doubted");
        assert!(doubt.starts_with("the clouds lie near each other but do not coincide"));
        let off = RigidTransform::new(Matrix3::identity(), Vector3::new(0.0, 0.0, 5.0));
        assert!(checked(off.compose(&right)).is_some());
    }

    /// A grid over a plane has a surface spacing; lines of points 0.001 apart, 0.05 from each
    /// other, as a LiDAR sweep's rings, have none: the check neither doubts nor takes there.
    #[test]
    fn points_along_scan_lines_have_no_surface_spacing() {
        let grid = |step: (f64, f64), n: (usize, usize)| {
            PointCloud::new(
                (0..n.0)
                    .flat_map(|i| (0..n.1).map(move |j| (i, j)))
                    .map(|(i, j)| Point3::new(i as f64 * step.0, j as f64 * step.1, 0.0))
                    .collect(),
            )
        };
        let surface = grid((0.01, 0.01), (60, 60));
        let s = Prepared::new(&surface);
        let spacing = surface_spacing(&s, 5.0).expect("a surface");
        assert!((spacing - 0.01).abs() < 1e-9, "{spacing}");
        let lines = grid((0.05, 0.001), (20, 200));
        let l = Prepared::new(&lines);
        assert_eq!(surface_spacing(&l, 5.0), None);
        let check = AT_SPACING;
        let same = RigidTransform::identity();
        assert!(check.takes(&s, &s, &same));
        assert!(!check.takes(&l, &l, &same));
        assert_eq!(check.doubt_of(&l, &l, &same), None);
    }

    /// Issue 44, D1 (`--method icp`): the airplane jittered by 0.01 coincides with itself in
    /// the unit frame; at 200 times the size, 1,000 units off the origin, it coincides by lengths
    /// in units nowhere, and measured in its frame as it does at 1. A shifted copy is doubted
    /// at either size.
    #[test]
    fn in_frame_measures_a_pair_of_any_size_as_in_the_unit_frame() {
        let plane = airplane();
        let mut rng = <rand::rngs::StdRng as rand::SeedableRng>::seed_from_u64(44);
        let jittered = PointCloud::new(
            plane
                .points
                .iter()
                .map(|p| {
                    let jitter: [f64; 3] =
                        std::array::from_fn(|_| rand::Rng::gen_range(&mut rng, -0.01..0.01));
                    p + Vector3::from(jitter)
                })
                .collect(),
        );
        let check = Coincides {
            near: 0.02,
            far: 0.08,
            least: 0.35,
        };
        let in_frame = InFrame {
            check,
            rule: crate::testing::FRAME,
        };
        let shift = Vector3::new(0.05, 0.0, 0.0);
        for (size, offset) in [(1.0, 0.0), (200.0, 1000.0)] {
            let place = |cloud: &PointCloud| {
                PointCloud::new(
                    cloud
                        .points
                        .iter()
                        .map(|p| Point3::from(p.coords * size).map(|v| v + offset))
                        .collect(),
                )
            };
            let (source, target) = (place(&jittered), place(&plane));
            let s = Prepared::new(&source);
            let t = Prepared::new(&target);
            let same = RigidTransform::identity();
            let shifted = RigidTransform::new(Matrix3::identity(), shift * size);
            assert_eq!(in_frame.doubt_of(&s, &t, &same), None, "size {size}");
            assert!(in_frame.doubt_of(&s, &t, &shifted).is_some());
            if size > 1.0 {
                assert!(check.doubt_of(&s, &t, &same).is_some());
            }
        }
    }

    /// Issue 44, D1: a box's surface fits itself as well turned half about an axis, so its
    /// pose is doubted as ambiguous; the airplane is not. A composite's rival candidate far from
    /// the chosen one doubts it when it scores nearly as well and coincides, not when it scores
    /// little or lies within `apart`.
    #[test]
    fn a_pose_that_a_rival_fits_as_well_is_doubted() {
        // The self-fit out of reach: this test is of the rivals.
        let check = unambiguous(0.35, 1.1);
        let same = RigidTransform::identity();
        let boxed = rgm_geom::testing::box_surface(20_000, 7); // dense: a turned copy lies on it
        let b = Prepared::new(&boxed);
        let doubt = check.doubt_of(&b, &b, &same).expect("a box is ambiguous");
        assert!(
            doubt.starts_with("another pose fits nearly as well"),
            "{doubt}"
        );
        let plane = airplane();
        let a = Prepared::new(&plane);
        assert_eq!(check.doubt_of(&a, &a, &same), None);

        let turn = |deg: f64| {
            RigidTransform::new(
                rgm_geom::euler::rotation_xyz_intrinsic(0.0, 0.0, deg.to_radians()),
                Vector3::zeros(),
            )
        };
        let found = |rival: RigidTransform, rival_score: f64| {
            let unscored = crate::fit::Score {
                inlier_count: 0,
                fitness: 0.0,
                inlier_rmse: 0.0,
            };
            let result = crate::Fit::scored(same, 0, true, unscored);
            let mut found = Registration::single(result, Vec::new(), Instant::now());
            let candidate = |method: &str, t_target_source, score| crate::registrar::Candidate {
                method: method.to_string(),
                t_target_source,
                score: Some(score),
                failure: None,
                time_ms: 0.0,
            };
            found.candidates = vec![
                candidate("a", same, 2.0),
                candidate("b", rival, rival_score),
            ];
            found.chosen = Some(0);
            found
        };
        // A rival half a turn away coincides on the box and not on the airplane.
        let on_box = |rival, score| check.doubt(&b, &b, &found(rival, score));
        let half = turn(180.0);
        assert!(on_box(half, 1.9).unwrap().contains("b's"));
        assert!(on_box(turn(3.0), 1.9).is_none_or(|d| !d.contains("b's")));
        assert!(on_box(half, 1.0).is_none_or(|d| !d.contains("b's")));
        let on_plane = |rival, score| check.doubt(&a, &a, &found(rival, score));
        assert_eq!(on_plane(half, 1.9), None);
        assert_eq!(on_plane(turn(3.0), 1.9), None);
    }

    /// Issue 59, E4: two samplings of a cube (24 symmetries, its covariance's axes arbitrary)
    /// at the right pose are doubted as a symmetric shape even where no turned rival clears
    /// `rivals_pass`; two samplings of the airplane are not.
    #[test]
    fn a_cloud_that_fits_itself_turned_is_ambiguous() {
        // No rival passes this.
        let check = unambiguous(1.1, 0.9);
        let same = RigidTransform::identity();
        let cube = |seed| rgm_geom::testing::box_surface_of([0.5, 0.5, 0.5], 2048, seed);
        let (source, target) = (cube(1), cube(2));
        let s = Prepared::new(&source);
        let t = Prepared::new(&target);
        let doubt = check.doubt_of(&s, &t, &same).expect("a cube is ambiguous");
        assert!(
            doubt.starts_with("the source fits itself turned by"),
            "{doubt}"
        );
        let plane = airplane();
        let a = Prepared::new(&plane);
        assert_eq!(check.doubt_of(&a, &a, &same), None);
    }
}
