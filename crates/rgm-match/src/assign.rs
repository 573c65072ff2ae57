//! Test-time matching (spec §4.2–4.3): inlier selection, then a maximum-score one-to-one
//! assignment on the selected rows and columns.

use crate::correspondences::Correspondences;
use crate::error::{MatchError, Result};
use ndarray::{Array2, ArrayView2, Axis};
use rgm_nn::Scalar;

/// Settings of the hard matching.
#[derive(Clone, Debug, PartialEq)]
pub struct MatchConfig {
    /// A row or column of C̃ is an inlier when its sum exceeds this (spec: 0.5).
    pub inlier_threshold: f64,
}

impl Default for MatchConfig {
    fn default() -> Self {
        Self {
            inlier_threshold: 0.5,
        }
    }
}

/// The indices of the rows and of the columns of `c` whose sums exceed `threshold`.
pub fn select_inliers<T: Scalar>(
    c: ArrayView2<'_, T>, // (N, M)
    threshold: f64,
) -> (Vec<usize>, Vec<usize>) {
    let above = |axis| -> Vec<usize> {
        let sums = c.sum_axis(axis);
        (0..sums.len())
            .filter(|&k| sums[k].to_f64() > threshold)
            .collect()
    };
    (above(Axis(1)), above(Axis(0)))
}

/// Inlier selection, then the assignment maximising the total of C̃ over the selected
/// sub-matrix, as pairs in the original N×M shape. No inlier row or column gives no pairs.
pub fn hard_match<T: Scalar>(
    c: ArrayView2<'_, T>, // (N, M)
    cfg: &MatchConfig,
) -> Result<Correspondences> {
    let (n, m) = c.dim();
    let (rows, cols) = select_inliers(c, cfg.inlier_threshold);
    let sub = Array2::from_shape_fn((rows.len(), cols.len()), |(a, b)| {
        c[[rows[a], cols[b]]].to_f64()
    }); // (N', M')
    let pairs = max_score_assignment(sub.view())?
        .into_iter()
        .map(|(a, b)| (rows[a], cols[b]))
        .collect();
    Correspondences::new(n, m, pairs)
}

/// A one-to-one assignment of min(N, M) pairs (i, j) maximising Σ scores_ij, any shape.
pub fn max_score_assignment(scores: ArrayView2<'_, f64>, // (N, M)
) -> Result<Vec<(usize, usize)>> {
    if scores.iter().any(|v| !v.is_finite()) {
        return Err(MatchError::NonFinite {
            op: "max_score_assignment",
            what: "scores",
        });
    }
    // The solver needs rows ≤ columns and minimises: transpose the tall case, negate the scores.
    let pairs = if scores.nrows() <= scores.ncols() {
        let col_of_row = min_cost_assignment(scores.mapv(|v| -v).view());
        col_of_row.into_iter().enumerate().collect()
    } else {
        let row_of_col = min_cost_assignment(scores.t().mapv(|v| -v).view());
        row_of_col
            .into_iter()
            .enumerate()
            .map(|(j, i)| (i, j))
            .collect()
    };
    Ok(pairs)
}

/// The column assigned to each row in a minimum-cost assignment of a wide matrix (rows ≤ columns):
/// shortest augmenting paths with row and column potentials (Kuhn–Munkres in the
/// Jonker–Volgenant form), one Dijkstra-like search per row, O(N²·M).
fn min_cost_assignment(cost: ArrayView2<'_, f64>, // (N, M) with N ≤ M
) -> Vec<usize> {
    let (n, m) = cost.dim();
    debug_assert!(n <= m);
    // Column index m is a virtual start column; row_of_col[m] holds the row being inserted.
    const FREE: usize = usize::MAX;
    let mut row_pot = vec![0.0; n]; // (N)
    let mut col_pot = vec![0.0; m + 1]; // (M+1)
    let mut row_of_col = vec![FREE; m + 1]; // (M+1)
    let mut prev_col = vec![m; m + 1]; // (M+1) the path's previous column
    let mut min_slack = vec![0.0; m + 1]; // (M+1) shortest reduced distance to each column
    let mut visited = vec![false; m + 1]; // (M+1)
    for row in 0..n {
        row_of_col[m] = row;
        min_slack.fill(f64::INFINITY);
        visited.fill(false);
        let mut col = m;
        // Grow the tree until it reaches a free column.
        while row_of_col[col] != FREE {
            visited[col] = true;
            let i = row_of_col[col];
            let mut delta = f64::INFINITY;
            let mut next = m;
            for j in 0..m {
                if visited[j] {
                    continue;
                }
                let reduced = cost[[i, j]] - row_pot[i] - col_pot[j];
                if reduced < min_slack[j] {
                    min_slack[j] = reduced;
                    prev_col[j] = col;
                }
                if min_slack[j] < delta {
                    delta = min_slack[j];
                    next = j;
                }
            }
            // Shift the potentials so the tree's edges stay tight and `next` becomes reachable.
            for j in 0..=m {
                if visited[j] {
                    row_pot[row_of_col[j]] += delta;
                    col_pot[j] -= delta;
                } else {
                    min_slack[j] -= delta;
                }
            }
            col = next;
        }
        // Flip the path back to the start column.
        while col != m {
            let back = prev_col[col];
            row_of_col[col] = row_of_col[back];
            col = back;
        }
    }
    let mut col_of_row = vec![0; n]; // (N)
    for (j, &i) in row_of_col[..m].iter().enumerate() {
        if i != FREE {
            col_of_row[i] = j;
        }
    }
    col_of_row
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::array;
    use rand::{rngs::StdRng, Rng, SeedableRng};

    /// The best total over every injection of the smaller side into the larger, by recursion.
    fn brute_force_best(scores: &Array2<f64>) -> f64 {
        fn go(scores: &Array2<f64>, row: usize, used: &mut Vec<bool>) -> f64 {
            if row == scores.nrows() {
                return 0.0;
            }
            let mut best = f64::NEG_INFINITY;
            for j in 0..scores.ncols() {
                if !used[j] {
                    used[j] = true;
                    best = best.max(scores[[row, j]] + go(scores, row + 1, used));
                    used[j] = false;
                }
            }
            best
        }
        let wide = if scores.nrows() <= scores.ncols() {
            scores.clone()
        } else {
            scores.t().to_owned()
        };
        go(&wide, 0, &mut vec![false; wide.ncols()])
    }

    /// Checks that `pairs` is one-to-one, has min(N, M) pairs, and returns its total.
    fn total_of_valid(scores: &Array2<f64>, pairs: &[(usize, usize)]) -> f64 {
        let (n, m) = scores.dim();
        assert_eq!(pairs.len(), n.min(m));
        let mut rows: Vec<_> = pairs.iter().map(|p| p.0).collect();
        let mut cols: Vec<_> = pairs.iter().map(|p| p.1).collect();
        rows.sort_unstable();
        rows.dedup();
        cols.sort_unstable();
        cols.dedup();
        assert_eq!(
            (rows.len(), cols.len()),
            (pairs.len(), pairs.len()),
            "one-to-one: {pairs:?}"
        );
        pairs.iter().map(|&(i, j)| scores[[i, j]]).sum()
    }

    #[test]
    fn optimal_against_brute_force_up_to_seven() {
        let mut rng = StdRng::seed_from_u64(9);
        for n in 1..=7 {
            for m in 1..=7 {
                for _ in 0..4 {
                    let scores = Array2::from_shape_fn((n, m), |_| rng.gen_range(0.0..1.0));
                    let pairs = max_score_assignment(scores.view()).unwrap();
                    let total = total_of_valid(&scores, &pairs);
                    assert!(
                        (total - brute_force_best(&scores)).abs() < 1e-12,
                        "{n}x{m}: {scores}"
                    );
                }
            }
        }
    }

    #[test]
    fn optimal_with_ties() {
        // Integer scores from {0, 1, 2}: many optimal assignments; any one must reach the optimum.
        let mut rng = StdRng::seed_from_u64(10);
        for (n, m) in [(5, 5), (4, 7), (7, 3)] {
            for _ in 0..20 {
                let scores = Array2::from_shape_fn((n, m), |_| rng.gen_range(0..3) as f64);
                let pairs = max_score_assignment(scores.view()).unwrap();
                assert_eq!(
                    total_of_valid(&scores, &pairs),
                    brute_force_best(&scores),
                    "{scores}"
                );
            }
        }
        let flat = Array2::from_elem((3, 3), 0.25);
        assert_eq!(
            total_of_valid(&flat, &max_score_assignment(flat.view()).unwrap()),
            0.75
        );
    }

    #[test]
    fn agrees_with_pathfinding_kuhn_munkres() {
        // Larger sizes than brute force reaches: compare totals with pathfinding's solver on the
        // same scores scaled to integers (which it needs).
        let mut rng = StdRng::seed_from_u64(11);
        for (n, m) in [(40, 40), (30, 50)] {
            let ints = Array2::from_shape_fn((n, m), |_| rng.gen_range(0..1_000_000i64));
            let weights =
                pathfinding::matrix::Matrix::from_vec(n, m, ints.iter().copied().collect())
                    .unwrap();
            let (best, _) = pathfinding::kuhn_munkres::kuhn_munkres(&weights);
            let scores = ints.mapv(|v| v as f64);
            let total = total_of_valid(&scores, &max_score_assignment(scores.view()).unwrap());
            assert_eq!(total, best as f64);
        }
    }

    #[test]
    fn empty_inputs_give_empty_assignments() {
        assert_eq!(
            max_score_assignment(Array2::<f64>::zeros((0, 0)).view()).unwrap(),
            vec![]
        );
        assert_eq!(
            max_score_assignment(Array2::<f64>::zeros((0, 4)).view()).unwrap(),
            vec![]
        );
        assert_eq!(
            max_score_assignment(Array2::<f64>::zeros((3, 0)).view()).unwrap(),
            vec![]
        );
        let nan = array![[1.0, f64::NAN]];
        assert!(matches!(
            max_score_assignment(nan.view()),
            Err(MatchError::NonFinite { .. })
        ));
    }

    #[test]
    fn hard_match_selects_inliers_then_assigns() {
        // Row 1 and column 2 sum to ≤ 0.5 and are dropped; on the rest the best total is
        // 0.6 + 0.7 (rows 0, 2 to columns 1, 0), beating 0.5 + 0.45 along the diagonal.
        let c = array![[0.5, 0.6, 0.05], [0.1, 0.1, 0.1], [0.7, 0.45, 0.0]];
        assert_eq!(select_inliers(c.view(), 0.5), (vec![0, 2], vec![0, 1]));
        let hard = hard_match(c.view(), &MatchConfig::default()).unwrap();
        assert_eq!(hard.pairs(), &[(0, 1), (2, 0)]);
        assert_eq!((hard.n(), hard.m()), (3, 3));
    }

    #[test]
    fn hard_match_without_inliers_is_empty() {
        let c = Array2::from_elem((3, 4), 0.1f32); // every row sums to 0.4, every column to 0.3
        let hard = hard_match(c.view(), &MatchConfig::default()).unwrap();
        assert!(hard.pairs().is_empty());
        assert_eq!(hard.to_dense::<f32>(), Array2::<f32>::zeros((3, 4)));
        // Inlier rows but no inlier column: still empty.
        let rows_only = Array2::from_elem((2, 4), 0.2f32);
        assert!(hard_match(rows_only.view(), &MatchConfig::default())
            .unwrap()
            .pairs()
            .is_empty());
    }
}
