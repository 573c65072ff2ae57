//! A 0/1 correspondence matrix stored by its ones: the ground truth and the hard matching.

use crate::error::{MatchError, Result};
use ndarray::Array2;
use rgm_nn::Scalar;

/// An N×M 0/1 matrix given by its ones: distinct (i, j) pairs, kept sorted.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Correspondences {
    n: usize,
    m: usize,
    pairs: Vec<(usize, usize)>,
}

impl Correspondences {
    /// Checks that every pair lies inside N×M and none repeats.
    pub fn new(n: usize, m: usize, mut pairs: Vec<(usize, usize)>) -> Result<Self> {
        const OP: &str = "Correspondences::new";
        if let Some(&(i, j)) = pairs.iter().find(|&&(i, j)| i >= n || j >= m) {
            return Err(MatchError::PairOutOfRange { op: OP, i, j, n, m });
        }
        pairs.sort_unstable();
        if let Some(w) = pairs.windows(2).find(|w| w[0] == w[1]) {
            let (i, j) = w[0];
            return Err(MatchError::DuplicatePair { op: OP, i, j });
        }
        Ok(Self { n, m, pairs })
    }

    /// N, the number of rows (source points).
    pub fn n(&self) -> usize {
        self.n
    }

    /// M, the number of columns (target points).
    pub fn m(&self) -> usize {
        self.m
    }

    /// The (i, j) pairs whose entry is 1, sorted.
    pub fn pairs(&self) -> &[(usize, usize)] {
        &self.pairs
    }

    /// The dense 0/1 matrix.
    pub fn to_dense<T: Scalar>(&self) -> Array2<T> {
        let mut dense = Array2::zeros((self.n, self.m)); // (N, M)
        for &(i, j) in &self.pairs {
            dense[[i, j]] = T::one();
        }
        dense
    }

    /// The M×N transpose: every (i, j) becomes (j, i).
    pub fn transpose(&self) -> Self {
        let mut pairs: Vec<_> = self.pairs.iter().map(|&(i, j)| (j, i)).collect();
        pairs.sort_unstable();
        Self {
            n: self.m,
            m: self.n,
            pairs,
        }
    }

    /// Cycle consistency (spec §4.4): the pairs of `self` (from (X, Y)) also found in `reverse`
    /// (from (Y, X), so M×N) after transposing it.
    pub fn cycle_consistent(&self, reverse: &Self) -> Result<Self> {
        if (reverse.n, reverse.m) != (self.m, self.n) {
            return Err(MatchError::Shape {
                op: "Correspondences::cycle_consistent",
                what: "reverse",
                got: vec![reverse.n, reverse.m],
                expected: vec![self.m, self.n],
            });
        }
        let back = reverse.transpose();
        let pairs = self
            .pairs
            .iter()
            .filter(|p| back.pairs.binary_search(p).is_ok())
            .copied()
            .collect();
        Ok(Self {
            n: self.n,
            m: self.m,
            pairs,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;

    #[test]
    fn new_sorts_and_rejects_bad_pairs() {
        let c = Correspondences::new(2, 3, vec![(1, 2), (0, 0)]).unwrap();
        assert_eq!(c.pairs(), &[(0, 0), (1, 2)]);
        assert_eq!(
            c.to_dense::<f64>(),
            array![[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
        );
        let out = Correspondences::new(2, 3, vec![(0, 3)]);
        assert_eq!(
            out,
            Err(MatchError::PairOutOfRange {
                op: "Correspondences::new",
                i: 0,
                j: 3,
                n: 2,
                m: 3
            })
        );
        let twice = Correspondences::new(2, 3, vec![(1, 1), (0, 2), (1, 1)]);
        assert_eq!(
            twice,
            Err(MatchError::DuplicatePair {
                op: "Correspondences::new",
                i: 1,
                j: 1
            })
        );
    }

    #[test]
    fn cycle_consistency_keeps_pairs_found_both_ways() {
        // Forward (X→Y) 3×4: 0→1, 1→3, 2→0. Reverse (Y→X) 4×3 agrees on 0→1 and 2→0 only.
        let forward = Correspondences::new(3, 4, vec![(0, 1), (1, 3), (2, 0)]).unwrap();
        let reverse = Correspondences::new(4, 3, vec![(1, 0), (3, 2), (0, 2)]).unwrap();
        assert_eq!(reverse.transpose().pairs(), &[(0, 1), (2, 0), (2, 3)]);
        let kept = forward.cycle_consistent(&reverse).unwrap();
        assert_eq!(kept.pairs(), &[(0, 1), (2, 0)]);
        assert_eq!((kept.n(), kept.m()), (3, 4));
        assert!(matches!(
            forward.cycle_consistent(&forward),
            Err(MatchError::Shape { .. })
        ));
    }
}
