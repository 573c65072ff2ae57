//! A cloud prepared for registration: what the methods search it by (its k-d tree, its normals)
//! made when a stage first needs it and shared by every later stage of the registration, so that
//! a composite of several methods, checks and refinements builds each cloud's tree once.
//!
//! A [`Prepared`] borrows the cloud it is given (or owns one a wrapper made: the pair in another
//! frame, a thinning) and derefs to it, so that a method reads it as a [`PointCloud`].

use std::borrow::Cow;
use std::ops::Deref;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use rayon::prelude::*;
use rgm_geom::cloud::{evenly, median};
use rgm_geom::normals::{estimate_normals, NormalsConfig};
use rgm_geom::{KnnIndex, PointCloud, RigidTransform, Vector3};

use crate::fit::Fit;

/// Points whose neighbours set a cloud's [`Prepared::spacings`].
pub const SPACING_SAMPLE: usize = 2000;

/// The next [`Prepared`]'s id: ids are never reused, so a score kept under one cannot be read
/// back for another cloud that took the first one's place in memory.
static NEXT_ID: AtomicU64 = AtomicU64::new(0);

/// What a pair score is kept under: the other cloud's id, the transform's 12 entries and a
/// length (each as bits: only the same arithmetic's inputs find it).
type ScoreKey = (u64, [u64; 12], u64);

/// A refinement's fit and its (source, target) pairs ([`Prepared::refinement`]).
pub type Refinement = (Fit, Vec<(usize, usize)>);

/// Unit normals of a cloud's points, shared by the stages that ask for them. // (N,)
pub type Normals = Arc<Vec<Vector3<f64>>>;

/// A cloud and what is made of it lazily: its [`KnnIndex`], its normals per
/// [`NormalsConfig`], and scores and refinements of it onto other prepared clouds
/// ([`Prepared::pair_score`], [`Prepared::refinement`]).
#[derive(Debug)]
pub struct Prepared<'a> {
    cloud: Cow<'a, PointCloud>,
    index: OnceLock<KnnIndex>,
    /// The normals made so far, one entry per configuration asked for.
    normals: Mutex<Vec<(NormalsConfig, Normals)>>,
    id: u64,
    /// The pair scores made so far.
    scores: Mutex<Vec<(ScoreKey, f64)>>,
    /// The coincidences made so far, under the key at their near length and their far one.
    coincidences: Mutex<Vec<((ScoreKey, u64), f64)>>,
    /// The refinements made so far, each under its start and under its result.
    refinements: Mutex<Vec<(ScoreKey, Refinement)>>,
    /// [`Prepared::spacings`], once measured.
    spacings: OnceLock<(f64, f64)>,
}

impl<'a> Prepared<'a> {
    /// `cloud`, nothing made of it yet.
    pub fn new(cloud: impl Into<Cow<'a, PointCloud>>) -> Self {
        Self {
            cloud: cloud.into(),
            index: OnceLock::new(),
            normals: Mutex::new(Vec::new()),
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            scores: Mutex::new(Vec::new()),
            coincidences: Mutex::new(Vec::new()),
            refinements: Mutex::new(Vec::new()),
            spacings: OnceLock::new(),
        }
    }

    /// The cloud's k-d tree, built on first use.
    pub fn index(&self) -> &KnnIndex {
        if let Some(index) = self.index.get() {
            return index;
        }
        // Built outside the cell's lock: the build runs on rayon, whose threads may take up
        // another stage that asks for this tree while they wait, and a cell initialised
        // re-entrantly deadlocks. Two stages that race both build it; the first one set is kept.
        let built = KnnIndex::new(&self.cloud.points);
        self.index.get_or_init(|| built)
    }

    /// The cloud's point spacing: the median distance from a point to its nearest other point
    /// and to its 16th nearest, over at most [`SPACING_SAMPLE`] points spread evenly (both NaN
    /// for a cloud of fewer than 17 points); measured on first use, as every check at the
    /// pair's spacing asks for it (`crate::check::CoincidesAtSpacing`).
    pub fn spacings(&self) -> (f64, f64) {
        if let Some(&spacings) = self.spacings.get() {
            return spacings;
        }
        // Measured side by side outside the cell, for the reason `index` builds outside its
        // cell's.
        let index = self.index();
        let sample: Vec<_> = evenly(&self.cloud.points, SPACING_SAMPLE).collect(); // (S,)
        let (first, sixteenth): (Vec<f64>, Vec<f64>) = sample
            .par_iter()
            .map_init(Vec::new, |near, p| {
                index.k_nearest_squared_into(p, 17, near);
                Some((near.get(1)?.1.sqrt(), near.get(16)?.1.sqrt()))
            })
            .flatten()
            .unzip();
        *self
            .spacings
            .get_or_init(|| (median(first), median(sixteenth)))
    }

    /// The cloud with its tree, as the scoring functions take a searched cloud.
    pub fn indexed(&self) -> (&PointCloud, &KnnIndex) {
        (&self.cloud, self.index())
    }

    /// The cloud's unit normals by [`estimate_normals`] with `config`, estimated on first use
    /// of that configuration. // (N,)
    pub fn normals(&self, config: &NormalsConfig) -> Normals {
        let made = |normals: &[(NormalsConfig, Normals)]| {
            normals
                .iter()
                .find(|(c, _)| c == config)
                .map(|(_, n)| n.clone())
        };
        if let Some(normals) = made(&self.normals.lock().expect("no panic holds the lock")) {
            return normals;
        }
        // Estimated outside the lock, for the reason `index` builds outside its cell's.
        let estimated = Arc::new(estimate_normals(&self.cloud.points, self.index(), config));
        let mut normals = self.normals.lock().expect("no panic holds the lock");
        if let Some(raced) = made(&normals) {
            return raced;
        }
        normals.push((*config, estimated.clone()));
        estimated
    }
}

impl Prepared<'_> {
    /// What a pair's score is kept under.
    fn key(&self, target: &Prepared, transform: &RigidTransform, length: f64) -> ScoreKey {
        let mut entries = [0u64; 12];
        let values = transform
            .rotation
            .iter()
            .chain(transform.translation.iter());
        for (entry, value) in entries.iter_mut().zip(values) {
            *entry = value.to_bits();
        }
        (target.id, entries, length.to_bits())
    }

    /// The score `make` gives this cloud moved by `transform` onto `target` at `length`, made on
    /// the first ask and kept: the composites nested in a registration (a cascade inside a
    /// thinning inside another cascade) judge the same result on the same pair, and on a dense
    /// pair each judgement is a nearest-neighbour search of every point both ways. `make` must be
    /// one function of those three for every caller (the overlap score of
    /// [`crate::check::Judge`]).
    pub fn pair_score(
        &self,
        target: &Prepared,
        transform: &RigidTransform,
        length: f64,
        make: impl FnOnce() -> f64,
    ) -> f64 {
        kept(&self.scores, self.key(target, transform, length), make)
    }

    /// The coincidence `make` gives this cloud moved by `transform` onto `target` at lengths
    /// `near` and `far`, made on the first ask and kept: a cascade's judge, its acceptance and
    /// the checks of the registration's result ask it of the same result. `make` must be one
    /// function of those four for every caller ([`crate::check::coincidence`]).
    pub fn coincidence(
        &self,
        target: &Prepared,
        transform: &RigidTransform,
        (near, far): (f64, f64),
        make: impl FnOnce() -> f64,
    ) -> f64 {
        let key = (self.key(target, transform, near), far.to_bits());
        kept(&self.coincidences, key, make)
    }

    /// The refinement `make` makes of this cloud moved by `initial` onto `target` (its fit
    /// scored at `length`, and the pairs behind it), made on the first ask and kept under
    /// `initial`, and under its own transform with no iteration: a stage refined at the pair's
    /// resolution before a cascade judged it is found there again by the refinement of the
    /// cascade's winner, which then costs nothing. `make` must be one function of those three
    /// for every caller (the refinement at the pair's spacing, `crate::refiner::AtSpacing`); a
    /// failed one is not kept.
    pub fn refinement<E>(
        &self,
        target: &Prepared,
        initial: &RigidTransform,
        length: f64,
        make: impl FnOnce() -> Result<Refinement, E>,
    ) -> Result<Refinement, E> {
        let key = self.key(target, initial, length);
        let refinements = &self.refinements;
        let find = |key: &ScoreKey| {
            let made = refinements.lock().expect("no panic holds the lock");
            made.iter().find(|(k, _)| k == key).map(|m| m.1.clone())
        };
        if let Some(made) = find(&key) {
            return Ok(made);
        }
        let (fit, pairs) = make()?;
        let reached = self.key(target, &fit.t_target_source, length);
        let there = Fit {
            iterations: 0,
            ..fit
        };
        let mut made = refinements.lock().expect("no panic holds the lock");
        for (key, fit) in [(key, fit), (reached, there)] {
            if !made.iter().any(|(k, _)| *k == key) {
                made.push((key, (fit, pairs.clone())));
            }
        }
        Ok((fit, pairs))
    }
}

/// The value kept in `made` under `key`, or `make`'s, then kept. Made outside the lock, for the
/// reason [`Prepared::index`] builds outside its cell's.
fn kept<K: PartialEq, T: Clone>(made: &Mutex<Vec<(K, T)>>, key: K, make: impl FnOnce() -> T) -> T {
    let find = |made: &[(K, T)]| made.iter().find(|(k, _)| *k == key).map(|m| m.1.clone());
    if let Some(value) = find(&made.lock().expect("no panic holds the lock")) {
        return value;
    }
    let value = make();
    let mut made = made.lock().expect("no panic holds the lock");
    match find(&made) {
        Some(raced) => raced,
        None => {
            made.push((key, value.clone()));
            value
        }
    }
}

/// Both clouds with their trees, the trees not yet built built side by side (when there are
/// cores to spare).
pub fn indexed_pair<'p>(
    source: &'p Prepared,
    target: &'p Prepared,
) -> (
    (&'p PointCloud, &'p KnnIndex),
    (&'p PointCloud, &'p KnnIndex),
) {
    rayon::join(|| source.indexed(), || target.indexed())
}

impl Deref for Prepared<'_> {
    type Target = PointCloud;

    fn deref(&self) -> &PointCloud {
        &self.cloud
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rgm_geom::testing::airplane;

    #[test]
    fn the_tree_and_normals_are_made_once_and_are_what_the_bare_functions_make() {
        let cloud = airplane();
        let prepared = Prepared::new(&cloud);
        let index = prepared.index();
        assert!(std::ptr::eq(index, prepared.index()));
        let direct = KnnIndex::new(&cloud.points);
        let p = cloud.points[7];
        assert_eq!(index.k_nearest(&p, 5), direct.k_nearest(&p, 5));
        let config = NormalsConfig::default();
        let normals = prepared.normals(&config);
        assert!(Arc::ptr_eq(&normals, &prepared.normals(&config)));
        assert_eq!(*normals, estimate_normals(&cloud.points, &direct, &config));
        // Another configuration is another entry.
        let wide = NormalsConfig {
            radius: 0.4,
            ..config
        };
        assert!(!Arc::ptr_eq(&normals, &prepared.normals(&wide)));
        assert_eq!(prepared.normals.lock().unwrap().len(), 2);
    }

    #[test]
    fn the_spacings_are_the_medians_of_the_first_and_sixteenth_neighbours() {
        // A 50 × 50 grid 0.01 apart: every point's nearest other point is 0.01 away, its 16th
        // within 0.01·√5 (the ring at √5 is where the 13th to 20th lie), 2·√2 spacings at most.
        let grid = PointCloud::new(
            (0..2500)
                .map(|k| rgm_geom::Point3::new((k / 50) as f64 * 0.01, (k % 50) as f64 * 0.01, 0.0))
                .collect(),
        );
        let prepared = Prepared::new(&grid);
        let (nearest, sixteenth) = prepared.spacings();
        assert!((nearest - 0.01).abs() < 1e-12, "{nearest}");
        assert!(
            (sixteenth - 0.01 * 5f64.sqrt()).abs() < 1e-12,
            "{sixteenth}"
        );
        // Fewer than 17 points have no 16th neighbour.
        let few = PointCloud::new(grid.points[..10].to_vec());
        assert!(Prepared::new(&few).spacings().1.is_nan());
    }

    #[test]
    fn a_refinement_is_made_once_and_found_again_under_its_result_with_no_iteration() {
        let cloud = airplane();
        let (source, target) = (Prepared::new(&cloud), Prepared::new(&cloud));
        let start = RigidTransform::new(rgm_geom::Matrix3::identity(), Vector3::new(0.1, 0.0, 0.0));
        let reached =
            RigidTransform::new(rgm_geom::Matrix3::identity(), Vector3::new(0.001, 0.0, 0.0));
        let made = std::cell::Cell::new(0);
        let refine = |from: &RigidTransform, fails: bool| {
            source.refinement(&target, from, 0.5, || {
                made.set(made.get() + 1);
                if fails {
                    return Err("failed");
                }
                Ok((Fit::unscored(reached, 7, true), vec![(1, 2)]))
            })
        };
        // A failed refinement is not kept.
        assert_eq!(refine(&start, true), Err("failed"));
        let (fit, pairs) = refine(&start, false).unwrap();
        assert_eq!(
            (fit.t_target_source, fit.iterations, pairs),
            (reached, 7, vec![(1, 2)])
        );
        assert_eq!(refine(&start, false).unwrap().0.iterations, 7);
        let (again, pairs) = refine(&reached, false).unwrap();
        assert_eq!((again.t_target_source, again.iterations), (reached, 0));
        assert_eq!(pairs, vec![(1, 2)]);
        assert_eq!(made.get(), 2);
        // At another length it is another refinement.
        source
            .refinement(&target, &start, 0.25, || {
                made.set(made.get() + 1);
                Ok::<_, ()>((Fit::unscored(start, 0, true), Vec::new()))
            })
            .unwrap();
        assert_eq!(made.get(), 3);
    }

    #[test]
    fn a_pair_score_is_made_once_per_target_transform_and_length() {
        let cloud = airplane();
        let (source, target, other) = (
            Prepared::new(&cloud),
            Prepared::new(&cloud),
            Prepared::new(&cloud),
        );
        let shift = RigidTransform::new(rgm_geom::Matrix3::identity(), Vector3::new(0.1, 0.0, 0.0));
        let made = std::cell::Cell::new(0);
        let score = |target: &Prepared, t: &RigidTransform, length: f64| {
            source.pair_score(target, t, length, || {
                made.set(made.get() + 1);
                length + t.translation.x
            })
        };
        assert_eq!(score(&target, &shift, 0.5), 0.6);
        assert_eq!(score(&target, &shift, 0.5), 0.6);
        assert_eq!(made.get(), 1);
        // Another target (a cloud of the same points), transform or length is another score.
        score(&other, &shift, 0.5);
        score(&target, &RigidTransform::identity(), 0.5);
        score(&target, &shift, 0.25);
        assert_eq!(made.get(), 4);
    }

    #[test]
    fn a_coincidence_is_made_once_per_target_transform_and_lengths() {
        let cloud = airplane();
        let (source, target) = (Prepared::new(&cloud), Prepared::new(&cloud));
        let made = std::cell::Cell::new(0);
        let coincidence = |t: &RigidTransform, lengths: (f64, f64)| {
            source.coincidence(&target, t, lengths, || {
                made.set(made.get() + 1);
                lengths.0 / lengths.1
            })
        };
        let identity = RigidTransform::identity();
        assert_eq!(coincidence(&identity, (0.02, 0.08)), 0.25);
        assert_eq!(coincidence(&identity, (0.02, 0.08)), 0.25);
        assert_eq!(made.get(), 1);
        // Another far length, or a pair score at the near one, is another value.
        assert_eq!(coincidence(&identity, (0.02, 0.04)), 0.5);
        assert_eq!(source.pair_score(&target, &identity, 0.02, || 7.0), 7.0);
        assert_eq!(made.get(), 2);
    }
}
