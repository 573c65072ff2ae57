//! Ground-truth correspondences of a pair, stored sparsely as one-to-one (source, target) index
//! pairs. Unmatched points are outliers: their row / column of the dense matrix is all zero.

use rgm_geom::{KnnIndex, Point3};

use crate::{DataError, Result};

/// Distance under which steps 1 and 2 of [`Correspondence::rebuild`] match points.
pub const MATCH_RADIUS: f64 = 0.05;
/// Distance under which step 3 of [`Correspondence::rebuild`] matches the remaining points.
pub const RESCUE_RADIUS: f64 = 0.1;

/// One-to-one correspondences between `n_source` source and `n_target` target points.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Correspondence {
    /// N.
    pub n_source: usize,
    /// M.
    pub n_target: usize,
    /// (source index, target index), sorted by source index; each index appears at most once.
    pub pairs: Vec<(usize, usize)>,
}

impl Correspondence {
    /// Correspondences given from outside (e.g. read from JSON), checked: every index in range,
    /// each source and each target index at most once. The pairs are sorted by source index.
    pub fn new(n_source: usize, n_target: usize, mut pairs: Vec<(usize, usize)>) -> Result<Self> {
        let invalid = |why: String| Err(DataError::InvalidCorrespondence { why });
        let mut used_source = vec![false; n_source]; // (N,)
        let mut used_target = vec![false; n_target]; // (M,)
        for &(i, j) in &pairs {
            if i >= n_source || j >= n_target {
                return invalid(format!(
                    "pair ({i}, {j}) is outside {n_source} × {n_target}"
                ));
            }
            if std::mem::replace(&mut used_source[i], true) {
                return invalid(format!("source point {i} is matched twice"));
            }
            if std::mem::replace(&mut used_target[j], true) {
                return invalid(format!("target point {j} is matched twice"));
            }
        }
        pairs.sort_unstable();
        Ok(Self {
            n_source,
            n_target,
            pairs,
        })
    }

    /// The exact correspondence of two reorderings of one cloud: source point `i` is original
    /// point `source_origin[i]`, target point `j` is `target_origin[j]`; points with the same
    /// origin match.
    pub fn from_origins(source_origin: &[usize], target_origin: &[usize]) -> Self {
        let max_origin = source_origin
            .iter()
            .chain(target_origin)
            .max()
            .map_or(0, |&m| m + 1);
        let mut target_of_origin = vec![None; max_origin];
        for (j, &o) in target_origin.iter().enumerate() {
            target_of_origin[o] = Some(j);
        }
        let pairs = source_origin
            .iter()
            .enumerate()
            .filter_map(|(i, &o)| target_of_origin[o].map(|j| (i, j)))
            .collect();
        Self {
            n_source: source_origin.len(),
            n_target: target_origin.len(),
            pairs,
        }
    }

    /// The correspondence rebuilt from distances between `source_moved` (X', the source moved by
    /// the true transform) and `target` (Y), in the reference code's order:
    /// 1. mutual nearest neighbours closer than [`MATCH_RADIUS`];
    /// 2. each unmatched source point, in index order, whose nearest target is unmatched and
    ///    closer than [`MATCH_RADIUS`]; then the same from the target side;
    /// 3. nearest neighbours recomputed among the points still unmatched; mutual pairs closer
    ///    than [`RESCUE_RADIUS`].
    pub fn rebuild(source_moved: &[Point3<f64>], target: &[Point3<f64>]) -> Self {
        let (n, m) = (source_moved.len(), target.len());
        let mut result = Self {
            n_source: n,
            n_target: m,
            pairs: Vec::new(),
        };
        if n == 0 || m == 0 {
            return result;
        }
        let source_nn = nearest_all(source_moved, &KnnIndex::new(target)); // (N,) (target, distance)
        let target_nn = nearest_all(target, &KnnIndex::new(source_moved)); // (M,) (source, distance)
        let mut target_of = vec![None; n]; // (N,)
        let mut source_of = vec![None; m]; // (M,)

        // Step 1: mutual nearest neighbours.
        for (i, &(j, d)) in source_nn.iter().enumerate() {
            if target_nn[j].0 == i && d < MATCH_RADIUS {
                target_of[i] = Some(j);
                source_of[j] = Some(i);
            }
        }
        // Step 2: one-sided nearest neighbours whose partner is still free, source side first.
        for (i, &(j, d)) in source_nn.iter().enumerate() {
            if target_of[i].is_none() && source_of[j].is_none() && d < MATCH_RADIUS {
                target_of[i] = Some(j);
                source_of[j] = Some(i);
            }
        }
        for (j, &(i, d)) in target_nn.iter().enumerate() {
            if source_of[j].is_none() && target_of[i].is_none() && d < MATCH_RADIUS {
                target_of[i] = Some(j);
                source_of[j] = Some(i);
            }
        }
        // Step 3: mutual nearest neighbours among the rest.
        let rest_source: Vec<usize> = (0..n).filter(|&i| target_of[i].is_none()).collect();
        let rest_target: Vec<usize> = (0..m).filter(|&j| source_of[j].is_none()).collect();
        if !rest_source.is_empty() && !rest_target.is_empty() {
            let rest_source_points: Vec<_> = rest_source.iter().map(|&i| source_moved[i]).collect();
            let rest_target_points: Vec<_> = rest_target.iter().map(|&j| target[j]).collect();
            let rest_source_nn =
                nearest_all(&rest_source_points, &KnnIndex::new(&rest_target_points));
            let rest_target_nn =
                nearest_all(&rest_target_points, &KnnIndex::new(&rest_source_points));
            for (a, &(b, d)) in rest_source_nn.iter().enumerate() {
                if rest_target_nn[b].0 == a && d < RESCUE_RADIUS {
                    target_of[rest_source[a]] = Some(rest_target[b]);
                }
            }
        }
        result.pairs = target_of
            .iter()
            .enumerate()
            .filter_map(|(i, j)| j.map(|j| (i, j)))
            .collect();
        result
    }

    /// For each source point, its target, if any. // (N,)
    pub fn source_to_target(&self) -> Vec<Option<usize>> {
        let mut out = vec![None; self.n_source];
        for &(i, j) in &self.pairs {
            out[i] = Some(j);
        }
        out
    }

    /// The dense 0/1 matrix, row-major. // (N, M)
    pub fn to_dense(&self) -> Vec<f32> {
        let mut dense = vec![0.0; self.n_source * self.n_target];
        for &(i, j) in &self.pairs {
            dense[i * self.n_target + j] = 1.0;
        }
        dense
    }

    /// Share of source points that have a match.
    pub fn matched_source_fraction(&self) -> f64 {
        self.pairs.len() as f64 / self.n_source.max(1) as f64
    }
}

/// Nearest neighbour in `index` of each of `queries`: (index, distance). // (len(queries),)
fn nearest_all(queries: &[Point3<f64>], index: &KnnIndex) -> Vec<(usize, f64)> {
    queries.iter().map(|q| index.nearest(q)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on the x axis.
    fn line(xs: &[f64]) -> Vec<Point3<f64>> {
        xs.iter().map(|&x| Point3::new(x, 0.0, 0.0)).collect()
    }

    #[test]
    fn origins_give_the_exact_permutation() {
        // Source holds originals [2, 0, 1, 3], target [3, 1, 0]; original 2 was cropped away.
        let c = Correspondence::from_origins(&[2, 0, 1, 3], &[3, 1, 0]);
        assert_eq!(c.pairs, [(1, 2), (2, 1), (3, 0)]);
        assert_eq!(c.source_to_target(), [None, Some(2), Some(1), Some(0)]);
        assert_eq!(
            c.to_dense(),
            [0., 0., 0., 0., 0., 1., 0., 1., 0., 1., 0., 0.]
        );
    }

    #[test]
    fn step_one_matches_mutual_neighbours_under_the_radius() {
        // s0–t0 mutual at 0.01; s1–t1 mutual at 0.06 (too far for steps 1–2, rescued by step 3).
        let c = Correspondence::rebuild(&line(&[0.0, 1.0]), &line(&[0.01, 1.06]));
        assert_eq!(c.pairs, [(0, 0), (1, 1)]);
        // At 0.2 nothing rescues it.
        let c = Correspondence::rebuild(&line(&[0.0, 1.0]), &line(&[0.01, 1.2]));
        assert_eq!(c.pairs, [(0, 0)]);
    }

    #[test]
    fn step_two_source_side_matches_a_free_nearest_target() {
        // X' = [-0.03, 0.02], Y = [0.0, 0.03]. NN(s0) = t0 but NN(t0) = s1, so not mutual;
        // s1–t1 are mutual (step 1). Step 2: s0's nearest target t0 is free and 0.03 away.
        let c = Correspondence::rebuild(&line(&[-0.03, 0.02]), &line(&[0.0, 0.03]));
        assert_eq!(c.pairs, [(0, 0), (1, 1)]);
    }

    #[test]
    fn step_two_target_side_matches_a_free_nearest_source() {
        // Mirror of the case above: Y = [-0.03, 0.02], X' = [0.0, 0.03]. s1–t1 mutual; s0's
        // nearest target is t1 (taken); t0's nearest source s0 is free and 0.03 away.
        let c = Correspondence::rebuild(&line(&[0.0, 0.03]), &line(&[-0.03, 0.02]));
        assert_eq!(c.pairs, [(0, 0), (1, 1)]);
    }

    #[test]
    fn step_three_rescues_the_remaining_mutual_pairs_under_twice_the_radius() {
        // X' = [0.0, 0.03], Y = [0.035, 0.08]. Step 1: s1–t0 (0.005). s0's nearest is t0 (taken),
        // t1's nearest is s1 (taken). Step 3 among {s0} and {t1}: 0.08 < 0.1.
        let c = Correspondence::rebuild(&line(&[0.0, 0.03]), &line(&[0.035, 0.08]));
        assert_eq!(c.pairs, [(0, 1), (1, 0)]);
        // With t1 at 0.12 the rest are 0.12 apart: no rescue.
        let c = Correspondence::rebuild(&line(&[0.0, 0.03]), &line(&[0.035, 0.12]));
        assert_eq!(c.pairs, [(1, 0)]);
    }

    #[test]
    fn new_checks_range_and_one_to_one() {
        let c = Correspondence::new(3, 2, vec![(2, 0), (0, 1)]).unwrap();
        assert_eq!(c.pairs, [(0, 1), (2, 0)]);
        let err = |pairs| Correspondence::new(3, 2, pairs).unwrap_err().to_string();
        assert_eq!(
            err(vec![(0, 2)]),
            "invalid correspondence: pair (0, 2) is outside 3 × 2"
        );
        assert_eq!(
            err(vec![(1, 0), (1, 1)]),
            "invalid correspondence: source point 1 is matched twice"
        );
        assert_eq!(
            err(vec![(0, 1), (2, 1)]),
            "invalid correspondence: target point 1 is matched twice"
        );
    }

    #[test]
    fn empty_sides_give_no_pairs() {
        let c = Correspondence::rebuild(&[], &line(&[0.0]));
        assert_eq!((c.n_source, c.n_target, c.pairs.len()), (0, 1, 0));
        assert_eq!(
            Correspondence::rebuild(&line(&[0.0]), &[]).source_to_target(),
            [None]
        );
    }
}
