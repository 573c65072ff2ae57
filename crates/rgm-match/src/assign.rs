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

/// The column assigned to each row in a minimum-cost assignment of a wide matrix (rows ≤ columns).
///
/// Shortest augmenting paths with row and column potentials (the Jonker–Volgenant form of
/// Kuhn–Munkres, as in Crouse 2016 and SciPy's `linear_sum_assignment`): one Dijkstra search per
/// row left free by a greedy warm start, over the reduced costs, scanning only the columns not yet
/// reached and preferring a free column on ties, then one potential update over the reached rows
/// and columns. O(N²·M) worst case.
fn min_cost_assignment(cost: ArrayView2<'_, f64>, // (N, M) with N ≤ M
) -> Vec<usize> {
    let (n, m) = cost.dim();
    debug_assert!(n <= m);
    const FREE: usize = usize::MAX;
    let cost = cost.as_standard_layout(); // rows contiguous
    let mut row_pot = vec![0.0; n]; // (N)
    let mut col_pot = vec![0.0; m]; // (M)
    let mut col_of_row = vec![FREE; n]; // (N)
    let mut row_of_col = vec![FREE; m]; // (M)
    let mut path = vec![0usize; m]; // (M) the row from which each column was reached
    let mut dist = vec![0.0; m]; // (M) shortest reduced path cost to each column
    let mut remaining = Vec::with_capacity(m); // columns not yet reached
    let mut row_seen = vec![false; n]; // (N)
    let mut col_seen = vec![false; m]; // (M)
                                       // Warm start: u_i = min_j cost_ij with v = 0 is dual feasible (and keeps free columns at 0,
                                       // as the rectangular case needs); each row takes its cheapest column if still free (a tight
                                       // edge). Near-permutation scores leave few rows for the searches below.
    for (i, row) in cost.outer_iter().enumerate() {
        let (j, &min) =
            row.iter().enumerate().fold(
                (0, &f64::INFINITY),
                |best, e| if e.1 < best.1 { e } else { best },
            );
        row_pot[i] = min;
        if row_of_col[j] == FREE {
            row_of_col[j] = i;
            col_of_row[i] = j;
        }
    }
    for start in 0..n {
        if col_of_row[start] != FREE {
            continue;
        }
        dist.fill(f64::INFINITY);
        row_seen.fill(false);
        col_seen.fill(false);
        remaining.clear();
        remaining.extend((0..m).rev());
        // Dijkstra from `start` until a free column is reached.
        let (mut i, mut reached) = (start, 0.0);
        let sink = loop {
            row_seen[i] = true;
            let row = cost.row(i);
            let (mut lowest, mut best) = (f64::INFINITY, 0);
            for (k, &j) in remaining.iter().enumerate() {
                let d = reached + row[j] - row_pot[i] - col_pot[j];
                if d < dist[j] {
                    path[j] = i;
                    dist[j] = d;
                }
                if dist[j] < lowest || (dist[j] == lowest && row_of_col[j] == FREE) {
                    lowest = dist[j];
                    best = k;
                }
            }
            reached = lowest;
            let j = remaining.swap_remove(best);
            col_seen[j] = true;
            if row_of_col[j] == FREE {
                break j;
            }
            i = row_of_col[j];
        };
        // Keep every reduced cost ≥ 0 and the path's edges tight.
        row_pot[start] += reached;
        for r in (0..n).filter(|&r| row_seen[r] && r != start) {
            row_pot[r] += reached - dist[col_of_row[r]];
        }
        for j in (0..m).filter(|&j| col_seen[j]) {
            col_pot[j] -= reached - dist[j];
        }
        // Flip the path's assignments back to `start`.
        let mut j = sink;
        loop {
            let r = path[j];
            row_of_col[j] = r;
            let prev = std::mem::replace(&mut col_of_row[r], j);
            if r == start {
                break;
            }
            j = prev;
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
