//! Sinkhorn normalisation with one slack row and one slack column (spec §2.4).
//!
//! The padded (N+1)×(M+1) log matrix starts as S with a zero slack row and column. Each of the
//! `iterations` rounds normalises every real row over all M+1 columns (the slack row untouched),
//! then every real column over all N+1 rows (the slack column untouched). The slack row and column
//! are dropped and the rest exponentiated: C̃ (N×M).
//!
//! Every entry of the padded matrix stays S_ij + α_i + β_j, with one potential per real row (α)
//! and per real column (β) and zero for the slack row and column, so both forms track only the
//! potentials:
//! - log form (the reference): α_i = −LSE_j(S_ij + β_j), β_j = −LSE_i(S_ij + α_i), with the slack
//!   entry's 0 inside each LSE;
//! - scaling form: with K = exp(S), u = exp(α), v = exp(β): u_i = 1/((K·v)_i + 1),
//!   v_j = 1/((Kᵀ·u)_j + 1), and C̃ = K ∘ u·vᵀ — two matrix-vector products per round, no exp or
//!   log in the loop.
//!
//! With the slack, 0 < u, v ≤ 1. The scaling form is used when every |S_ij| ≤ L = ln(T::MAX)/4
//! (22.2 in f32, 177 in f64): then u_i ≥ 1/(M·e^L + 1), v_j ≥ 1/(N·e^L + 1), and K and every
//! product K·u·v ≥ e^{−3L}/(N·M) stay normal numbers (no overflow, no denormals) for N·M up to
//! about 10⁹; otherwise, or if a scaling vector still leaves the normal range, the log form runs
//! instead. [`SinkhornCache::form`] says which one ran.
//!
//! The file is long because its unit tests sit beside the code they check (as everywhere in
//! rgm); the code itself is one job, kept in one place.

use crate::error::{check_shape, MatchError, Result};
use ndarray::linalg::{general_mat_mul, general_mat_vec_mul};
use ndarray::{s, Array1, Array2, ArrayView1, ArrayView2, ArrayViewMut1, ArrayViewMut2, Axis, Zip};
use rgm_nn::lanes::{exp_shifted_sum, sum};
use rgm_nn::Scalar;

/// Which computation [`sinkhorn_forward`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SinkhornForm {
    /// Log-sum-exp on the potentials: safe for any finite S, one exp per entry per half-step.
    Log,
    /// Scaling vectors on exp(S) where that is safe (see the module doc), the log form otherwise.
    Scaling,
}

/// Settings of the Sinkhorn layer.
#[derive(Clone, Debug, PartialEq)]
pub struct SinkhornConfig {
    /// Rounds of row-then-column normalisation (spec: 20).
    pub iterations: usize,
    /// Pad one slack row and column (spec: true). Without it this is plain Sinkhorn: each real
    /// column of C̃ sums to 1 after the last round.
    pub slack: bool,
    /// The requested computation (default: scaling where safe).
    pub form: SinkhornForm,
}

impl Default for SinkhornConfig {
    fn default() -> Self {
        Self {
            iterations: 20,
            slack: true,
            form: SinkhornForm::Scaling,
        }
    }
}

/// What [`sinkhorn_backward`] needs from the forward pass: the potentials of every round, which
/// the backward pass walks in reverse, and exp(S) when the scaling form ran.
#[derive(Clone, Debug)]
pub struct SinkhornCache<T> {
    form: SinkhornForm,
    slack: bool,
    k: Array2<T>,    // (N, M) exp(S); scaling form only
    rows: Array2<T>, // (I, N) after each round's row step: α (log form) or u = exp(α) (scaling form)
    cols: Array2<T>, // (I, M) after each round's column step: β (log form) or v = exp(β) (scaling form)
}

impl<T: Scalar> SinkhornCache<T> {
    /// Buffers for an N×M input and `cfg.iterations` rounds.
    pub fn new(n: usize, m: usize, cfg: &SinkhornConfig) -> Self {
        let rounds = cfg.iterations;
        Self {
            form: cfg.form,
            slack: cfg.slack,
            k: Array2::zeros((n, m)),
            rows: Array2::zeros((rounds, n)),
            cols: Array2::zeros((rounds, m)),
        }
    }

    /// The form that actually ran.
    pub fn form(&self) -> SinkhornForm {
        self.form
    }

    /// The dropped slack column, P_{i,M} = exp(α_i) for each real row (N); None without slack.
    /// A real row's padded sum is its sum in C̃ plus this entry.
    pub fn slack_column(&self) -> Option<Array1<T>> {
        self.slack.then(|| self.scaling(last(&self.rows)))
    }

    /// The dropped slack row, P_{N,j} = exp(β_j) for each real column (M); None without slack.
    /// A real column's padded sum is its sum in C̃ plus this entry.
    pub fn slack_row(&self) -> Option<Array1<T>> {
        self.slack.then(|| self.scaling(last(&self.cols)))
    }

    /// exp(potentials), whichever form the cache holds.
    fn scaling(&self, held: ArrayView1<'_, T>) -> Array1<T> {
        match self.form {
            SinkhornForm::Log => held.mapv(T::exp),
            SinkhornForm::Scaling => held.to_owned(),
        }
    }
}

/// The last round's row of a (I, ·) history; I ≥ 1 is checked by the forward pass.
fn last<T>(history: &Array2<T>) -> ArrayView1<'_, T> {
    history.row(history.nrows() - 1)
}

/// C̃ = exp(S + α·1ᵀ + 1·βᵀ) after `cfg.iterations` rounds (see the module doc).
///
/// Derivative, walking the rounds in reverse with G = dC̃ ∘ C̃: dS += G, dα = Σ_j G, dβ = Σ_i G;
/// the column step β_j = −LSE_i(S_ij + α_i) with P_ij = exp(S_ij + α_i + β_j) gives
/// dS_ij −= P_ij·dβ_j and dα_i −= Σ_j P_ij·dβ_j; the row step α_i = −LSE_j(S_ij + β'_j) of the
/// previous β' gives dS_ij −= P'_ij·dα_i and dβ'_j = −Σ_i P'_ij·dα_i.
pub fn sinkhorn_forward<T: Scalar>(
    mut c: ArrayViewMut2<'_, T>, // (N, M) out
    s: ArrayView2<'_, T>,        // (N, M)
    cfg: &SinkhornConfig,
    cache: &mut SinkhornCache<T>,
) -> Result<()> {
    const OP: &str = "sinkhorn forward";
    let (n, m) = s.dim();
    check_shape(OP, "c", c.shape(), &[n, m])?;
    check_shape(OP, "cache rows", cache.rows.shape(), &[cfg.iterations, n])?;
    check_shape(OP, "cache cols", cache.cols.shape(), &[cfg.iterations, m])?;
    check_shape(OP, "cache k", cache.k.shape(), &[n, m])?;
    if cfg.iterations == 0 {
        return Err(MatchError::Config {
            op: OP,
            why: "iterations must be at least 1",
        });
    }
    if s.iter().any(|v| !v.is_finite()) {
        return Err(MatchError::NonFinite { op: OP, what: "s" });
    }
    cache.slack = cfg.slack;
    let bound = T::max_value().ln() / T::from_f64(4.0);
    let scaling_safe = cfg.form == SinkhornForm::Scaling && s.iter().all(|v| v.abs() <= bound);
    cache.form = if scaling_safe && scaling_forward(s, cfg, cache) {
        SinkhornForm::Scaling
    } else {
        log_forward(s, cfg, cache);
        SinkhornForm::Log
    };
    let (rows, cols) = (last(&cache.rows), last(&cache.cols));
    match cache.form {
        SinkhornForm::Log => {
            for ((mut c_row, s_row), &a) in c.outer_iter_mut().zip(s.outer_iter()).zip(rows) {
                Zip::from(&mut c_row)
                    .and(&s_row)
                    .and(&cols)
                    .for_each(|c, &s, &b| *c = s + a + b);
                exp_row(c_row);
            }
        }
        SinkhornForm::Scaling => Zip::indexed(&mut c)
            .and(&cache.k)
            .for_each(|(i, j), c, &k| *c = k * rows[i] * cols[j]),
    }
    Ok(())
}

/// The log form's rounds: α into `cache.rows`, β into `cache.cols`.
///
/// Each round's row step and column step is cut in two halves (of the rows, of the columns) that
/// two workers run side by side when S is large enough ([`rgm_geom::lockstep`]); every value is
/// computed the same way on one worker or two.
fn log_forward<T: Scalar>(
    s: ArrayView2<'_, T>,
    cfg: &SinkhornConfig,
    cache: &mut SinkhornCache<T>,
) {
    let (n, m) = s.dim();
    // The slack entry's log value 0 joins every LSE; without slack it is −∞ (absent).
    let slack_log = if cfg.slack {
        T::zero()
    } else {
        T::neg_infinity()
    };
    let rounds = cfg.iterations;
    let potentials = Potentials {
        alpha: cache.rows.as_mut_ptr(),
        beta: cache.cols.as_mut_ptr(),
    };
    // Steps 2t and 2t + 1: round t's row step and column step, each cut in two halves.
    rgm_geom::lockstep::two_halves(
        2 * rounds,
        n * m >= PARALLEL_ENTRIES,
        // Per worker: one row's terms, the column maxima and the column sums, (M) each.
        || [vec![T::zero(); m], vec![T::zero(); m], vec![T::zero(); m]],
        |[terms, col_max, col_sum], step, part| {
            let potentials = &potentials; // shared whole: its fields alone are not Sync
            let (t, column_step) = (step / 2, step % 2 == 1);
            // SAFETY: the cache holds (I, N) α and (I, M) β in row order. This half writes only
            // its half of round t's row of one of them, which no other half-step touches, and
            // reads rows that every writer finished before `two_halves` let it start.
            unsafe {
                if column_step {
                    let (c0, c1) = if part == 0 { (0, m / 2) } else { (m / 2, m) };
                    let alpha = std::slice::from_raw_parts(potentials.alpha.add(t * n), n);
                    let beta =
                        std::slice::from_raw_parts_mut(potentials.beta.add(t * m + c0), c1 - c0);
                    log_column_step(
                        s.slice(s![.., c0..c1]),
                        alpha,
                        slack_log,
                        beta,
                        [
                            &mut col_max[c0..c1],
                            &mut col_sum[c0..c1],
                            &mut terms[c0..c1],
                        ],
                    );
                } else {
                    let (r0, r1) = if part == 0 { (0, n / 2) } else { (n / 2, n) };
                    // β = 0 before the first column step.
                    let beta = (t > 0)
                        .then(|| std::slice::from_raw_parts(potentials.beta.add((t - 1) * m), m));
                    let alpha =
                        std::slice::from_raw_parts_mut(potentials.alpha.add(t * n + r0), r1 - r0);
                    log_row_step(s.slice(s![r0..r1, ..]), beta, slack_log, alpha, terms);
                }
            }
        },
    );
}

/// Entries of S from which the log form asks rayon's pool for a second worker.
const PARALLEL_ENTRIES: usize = 128 * 128;

/// The log form's potentials, shared by its workers ([`log_forward`] says who writes what).
struct Potentials<T> {
    alpha: *mut T, // (I, N)
    beta: *mut T,  // (I, M)
}

// SAFETY: the halves of one `log_forward` write disjoint parts, ordered by `two_halves`.
unsafe impl<T: Send> Sync for Potentials<T> {}

/// α_i = −LSE(S_ij + β_j over j, slack) for the rows of `s` (R, M) into `alpha` (R); no `beta`
/// is β = 0. `terms` (M) is scratch.
fn log_row_step<T: Scalar>(
    s: ArrayView2<'_, T>,
    beta: Option<&[T]>,
    slack_log: T,
    alpha: &mut [T],
    terms: &mut [T],
) {
    for (row, a) in s.outer_iter().zip(alpha.iter_mut()) {
        match beta {
            Some(beta) => Zip::from(&mut *terms)
                .and(&row)
                .and(beta)
                .for_each(|x, &v, &b| *x = v + b),
            None => Zip::from(&mut *terms)
                .and(&row)
                .for_each(|x, &v| *x = v + T::zero()),
        }
        let max = rgm_nn::lanes::max(terms, slack_log);
        let sum = (slack_log - max).exp() + exp_shifted_sum(terms, max);
        *a = -(max + sum.ln());
    }
}

/// β_j = −LSE(S_ij + α_i over i, slack) for the columns of `s` (N, J) into `beta` (J), row by
/// row for contiguous access; `scratch` is three (J) buffers: the column maxima, sums and one
/// row's terms.
fn log_column_step<T: Scalar>(
    s: ArrayView2<'_, T>,
    alpha: &[T],
    slack_log: T,
    beta: &mut [T],
    scratch: [&mut [T]; 3],
) {
    let [col_max, col_sum, terms] = scratch;
    col_max.fill(slack_log);
    for (row, &a) in s.outer_iter().zip(alpha) {
        Zip::from(&mut *col_max)
            .and(&row)
            .for_each(|mx, &v| *mx = mx.max(v + a));
    }
    Zip::from(&mut *col_sum)
        .and(&*col_max)
        .for_each(|sum, &mx| *sum = (slack_log - mx).exp());
    for (row, &a) in s.outer_iter().zip(alpha) {
        Zip::from(&mut *terms)
            .and(&*col_max)
            .and(&row)
            .for_each(|x, &mx, &v| *x = v + a - mx);
        T::exp_in_place(terms);
        Zip::from(&mut *col_sum)
            .and(&*terms)
            .for_each(|sum, &e| *sum += e);
    }
    Zip::from(beta)
        .and(&*col_max)
        .and(&*col_sum)
        .for_each(|b, &mx, &sum| *b = -(mx + sum.ln()));
}

/// The scaling form's rounds: K into `cache.k`, u into `cache.rows`, v into `cache.cols`.
/// False if a scaling vector left the normal range (the log form must run instead).
fn scaling_forward<T: Scalar>(
    s: ArrayView2<'_, T>,
    cfg: &SinkhornConfig,
    cache: &mut SinkhornCache<T>,
) -> bool {
    let slack = if cfg.slack { T::one() } else { T::zero() };
    let (k, u, v) = (&mut cache.k, &mut cache.rows, &mut cache.cols);
    k.assign(&s);
    T::exp_in_place(k.as_slice_mut().expect("the cache's K is standard layout"));
    v.row_mut(0).fill(T::one()); // v before the first column step, overwritten by it
    for t in 0..cfg.iterations {
        // Row step: u_i = 1 / (Σ_j K_ij·v_j + slack)
        let mut u_t = u.row_mut(t);
        general_mat_vec_mul(
            T::one(),
            &*k,
            &v.row(t.saturating_sub(1)),
            T::zero(),
            &mut u_t,
        );
        u_t.mapv_inplace(|kv| T::one() / (kv + slack));
        // Column step: v_j = 1 / (Σ_i K_ij·u_i + slack)
        let mut v_t = v.row_mut(t);
        general_mat_vec_mul(T::one(), &k.t(), &u_t, T::zero(), &mut v_t);
        v_t.mapv_inplace(|ku| T::one() / (ku + slack));
    }
    u.iter().chain(v.iter()).all(|x| x.is_normal())
}

/// Adds the gradient of [`sinkhorn_forward`] into `ds`.
pub fn sinkhorn_backward<T: Scalar>(
    mut ds: ArrayViewMut2<'_, T>, // (N, M)
    dc: ArrayView2<'_, T>,        // (N, M)
    s: ArrayView2<'_, T>,         // (N, M) the forward input
    c: ArrayView2<'_, T>,         // (N, M) the forward output
    cache: &SinkhornCache<T>,
) -> Result<()> {
    const OP: &str = "sinkhorn backward";
    let (n, m) = s.dim();
    check_shape(OP, "dc", dc.shape(), &[n, m])?;
    check_shape(OP, "c", c.shape(), &[n, m])?;
    check_shape(OP, "ds", ds.shape(), &[n, m])?;
    check_shape(OP, "cache rows", &[cache.rows.ncols()], &[n])?;
    check_shape(OP, "cache cols", &[cache.cols.ncols()], &[m])?;
    // C̃ = exp(S + α + β)  →  dS += G, dα = Σ_j G, dβ = Σ_i G with G = dC̃ ∘ C̃
    let g = &dc * &c; // (N, M)
    ds += &g;
    let dalpha = g.sum_axis(Axis(1)); // (N)
    let dbeta = g.sum_axis(Axis(0)); // (M)
    match cache.form {
        SinkhornForm::Log => log_backward(ds, s, &cache.rows, &cache.cols, dalpha, dbeta),
        SinkhornForm::Scaling => {
            scaling_backward(ds, &cache.k, &cache.rows, &cache.cols, dalpha, dbeta)
        }
    }
    Ok(())
}

/// The rounds in reverse, P recomputed as exp(S + α + β).
fn log_backward<T: Scalar>(
    mut ds: ArrayViewMut2<'_, T>, // (N, M)
    s: ArrayView2<'_, T>,         // (N, M)
    alpha: &Array2<T>,            // (I, N)
    beta: &Array2<T>,             // (I, M)
    mut dalpha: Array1<T>,        // (N) gradient of the last α
    mut dbeta: Array1<T>,         // (M) gradient of the last β
) {
    let m = s.ncols();
    let zeros = Array1::<T>::zeros(m); // (M) β before the first column step
    let mut dbeta_prev = Array1::<T>::zeros(m); // (M)
    let mut p = Array1::<T>::zeros(m); // (M) one row of P, then of P'
    for t in (0..alpha.nrows()).rev() {
        let (a, b) = (alpha.row(t), beta.row(t));
        let b_prev = if t == 0 {
            zeros.view()
        } else {
            beta.row(t - 1)
        };
        dbeta_prev.fill(T::zero());
        for (i, (s_row, mut ds_row)) in s.outer_iter().zip(ds.outer_iter_mut()).enumerate() {
            // β_j = −LSE_i(S_ij + α_i)  →  dS_ij −= P_ij·dβ_j, dα_i −= Σ_j P_ij·dβ_j
            Zip::from(&mut p)
                .and(&s_row)
                .and(&b)
                .for_each(|p, &s, &b| *p = s + a[i] + b);
            exp_row(p.view_mut());
            // p ← P_ij·dβ_j once dS has it, summed in eight running sums (a single running
            // sum is one serial chain of additions).
            Zip::from(&mut ds_row)
                .and(&mut p)
                .and(&dbeta)
                .for_each(|ds, p, &db| {
                    *p *= db;
                    *ds -= *p;
                });
            let da = dalpha[i] - sum(p.as_slice().expect("a new array is contiguous"));
            // α_i = −LSE_j(S_ij + β'_j)  →  dS_ij −= P'_ij·dα_i, dβ'_j −= P'_ij·dα_i
            Zip::from(&mut p)
                .and(&s_row)
                .and(&b_prev)
                .for_each(|p, &s, &b| *p = s + a[i] + b);
            exp_row(p.view_mut());
            Zip::from(&mut ds_row)
                .and(&mut dbeta_prev)
                .and(&p)
                .for_each(|ds, db_prev, &p| {
                    *ds -= p * da;
                    *db_prev -= p * da;
                });
        }
        // α of earlier rounds feeds only its own column step; β' only this row step.
        dalpha.fill(T::zero());
        std::mem::swap(&mut dbeta, &mut dbeta_prev);
    }
}

/// exp of a row in place (strided rows through a contiguous copy).
fn exp_row<T: Scalar>(mut row: ArrayViewMut1<'_, T>) {
    match row.as_slice_mut() {
        Some(xs) => T::exp_in_place(xs),
        None => {
            let mut xs = row.to_vec();
            T::exp_in_place(&mut xs);
            row.assign(&ArrayView1::from(&xs));
        }
    }
}

/// The rounds in reverse with P = K ∘ u·vᵀ: two matrix-vector products per round, and the
/// rank-2I sum of every round's dS term applied at the end as one matrix product.
fn scaling_backward<T: Scalar>(
    mut ds: ArrayViewMut2<'_, T>, // (N, M)
    k: &Array2<T>,                // (N, M)
    u: &Array2<T>,                // (I, N)
    v: &Array2<T>,                // (I, M)
    mut dalpha: Array1<T>,        // (N)
    mut dbeta: Array1<T>,         // (M)
) {
    let (n, m) = k.dim();
    let rounds = u.nrows();
    // dS −= K ∘ (Σ_t u^t·(v^t∘dβ^t)ᵀ + (u^t∘dα^t)·v^{t−1}ᵀ) = K ∘ (left · rightᵀ)
    let mut left = Array2::<T>::zeros((n, 2 * rounds)); // (N, 2I)
    let mut right = Array2::<T>::zeros((m, 2 * rounds)); // (M, 2I)
    let mut v_db = Array1::<T>::zeros(m); // (M) v^t ∘ dβ^t
    let mut k_vdb = Array1::<T>::zeros(n); // (N) K · (v^t ∘ dβ^t)
    let mut u_da = Array1::<T>::zeros(n); // (N) u^t ∘ dα^t
    for t in (0..rounds).rev() {
        let (u_t, v_t) = (u.row(t), v.row(t));
        // Column step: dα_i −= u_i·Σ_j K_ij·v_j·dβ_j
        Zip::from(&mut v_db)
            .and(&v_t)
            .and(&dbeta)
            .for_each(|x, &v, &db| *x = v * db);
        general_mat_vec_mul(T::one(), k, &v_db, T::zero(), &mut k_vdb);
        Zip::from(&mut u_da)
            .and(&u_t)
            .and(&dalpha)
            .and(&k_vdb)
            .for_each(|x, &u, &da, &kv| *x = u * (da - u * kv));
        left.column_mut(2 * t).assign(&u_t);
        right.column_mut(2 * t).assign(&v_db);
        // Row step: dβ'_j = −v'_j·Σ_i K_ij·u_i·dα_i, with v' = 1 in the first round
        general_mat_vec_mul(-T::one(), &k.t(), &u_da, T::zero(), &mut dbeta);
        left.column_mut(2 * t + 1).assign(&u_da);
        if t > 0 {
            let v_prev = v.row(t - 1);
            dbeta *= &v_prev;
            right.column_mut(2 * t + 1).assign(&v_prev);
        } else {
            right.column_mut(2 * t + 1).fill(T::one());
        }
        // α of earlier rounds feeds only its own column step.
        dalpha.fill(T::zero());
    }
    let mut r = Array2::<T>::zeros((n, m)); // (N, M)
    general_mat_mul(T::one(), &left, &right.t(), T::zero(), &mut r);
    rgm_nn::gemm::count_multiply_adds(n, left.ncols(), m);
    Zip::from(&mut ds)
        .and(k)
        .and(&r)
        .for_each(|ds, &k, &r| *ds -= k * r);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference;
    use ndarray::{array, ArrayD};
    use rgm_nn::gradcheck::{assert_gradients, ix2, uniform};

    fn config(form: SinkhornForm, slack: bool) -> SinkhornConfig {
        SinkhornConfig {
            form,
            slack,
            ..SinkhornConfig::default()
        }
    }

    /// C̃ and the cache for `s` under `cfg`.
    fn run<T: Scalar>(s: &Array2<T>, cfg: &SinkhornConfig) -> (Array2<T>, SinkhornCache<T>) {
        let (n, m) = s.dim();
        let mut cache = SinkhornCache::new(n, m, cfg);
        let mut c = Array2::zeros((n, m));
        sinkhorn_forward(c.view_mut(), s.view(), cfg, &mut cache).unwrap();
        (c, cache)
    }

    const BOTH: [SinkhornForm; 2] = [SinkhornForm::Log, SinkhornForm::Scaling];

    #[test]
    fn matches_reference_with_slack() {
        let (slack_column, slack_row) = reference::slack_column_and_row();
        for form in BOTH {
            let (c, cache) = run(&reference::s(), &config(form, true));
            assert_eq!(cache.form(), form);
            assert!(
                c.abs_diff_eq(&reference::sinkhorn_slack(), 1e-14),
                "{form:?}: {c}"
            );
            assert!(
                cache
                    .slack_column()
                    .unwrap()
                    .abs_diff_eq(&slack_column, 1e-14),
                "{form:?}"
            );
            assert!(
                cache.slack_row().unwrap().abs_diff_eq(&slack_row, 1e-14),
                "{form:?}"
            );
        }
    }

    #[test]
    fn matches_reference_without_slack() {
        for form in BOTH {
            let (c, cache) = run(&reference::s(), &config(form, false));
            assert!(
                c.abs_diff_eq(&reference::sinkhorn_plain(), 1e-14),
                "{form:?}: {c}"
            );
            assert_eq!(cache.slack_row(), None);
        }
    }

    #[test]
    fn forms_agree_in_f32_and_f64() {
        let s = ix2(&uniform(&[30, 45], 7)) * 6.0; // entries in ±6, an instance-normalised range
        let (log64, _) = run(&s, &config(SinkhornForm::Log, true));
        let (fast64, cache) = run(&s, &config(SinkhornForm::Scaling, true));
        assert_eq!(cache.form(), SinkhornForm::Scaling);
        assert!(fast64.abs_diff_eq(&log64, 1e-13));
        let s32 = s.mapv(|v| v as f32);
        let (log32, _) = run(&s32, &config(SinkhornForm::Log, true));
        let (fast32, _) = run(&s32, &config(SinkhornForm::Scaling, true));
        let worst = |c: &Array2<f32>| {
            c.iter()
                .zip(&log64)
                .map(|(&a, &b)| (a as f64 - b).abs())
                .fold(0.0, f64::max)
        };
        // Both f32 forms stay within a few ulps of 1 of the f64 result.
        assert!(worst(&log32) < 2e-6, "log f32 error {}", worst(&log32));
        assert!(
            worst(&fast32) < 2e-6,
            "scaling f32 error {}",
            worst(&fast32)
        );
    }

    #[test]
    fn log_form_gives_the_same_bits_on_one_worker_and_two() {
        // Large enough for two workers, odd sizes so that the halves differ; S beyond the
        // scaling form's range so that the log form runs.
        let s = (ix2(&uniform(&[131, 157], 21)) * 40.0).mapv(|v| v as f32);
        let cfg = SinkhornConfig::default();
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| run(&s, &cfg))
        };
        let (one, cache) = on(1);
        assert_eq!(cache.form(), SinkhornForm::Log);
        for threads in [2, 3] {
            let (c, other) = on(threads);
            assert_eq!(c, one, "{threads} threads");
            assert_eq!(other.rows, cache.rows);
            assert_eq!(other.cols, cache.cols);
        }
        // And it is Sinkhorn: with the slack, every real row sums to at most 1.
        assert!(one.rows().into_iter().all(|r| r.sum() <= 1.0 + 1e-5));
        // S in any memory layout: a transposed view gives what its standard copy gives.
        let st = s.t();
        let mut c = Array2::zeros(st.dim());
        let mut cache = SinkhornCache::new(st.nrows(), st.ncols(), &cfg);
        sinkhorn_forward(c.view_mut(), st, &cfg, &mut cache).unwrap();
        assert_eq!(c, run(&st.to_owned(), &cfg).0);
    }

    #[test]
    fn f32_backward_of_both_forms_tracks_f64() {
        // The model trains in f32: both backward passes stay close to the f64 gradient.
        let (s, dc) = (
            ix2(&uniform(&[30, 45], 12)) * 6.0,
            ix2(&uniform(&[30, 45], 13)),
        );
        let grad = |s: &Array2<f64>, form| {
            let (c, cache) = run(s, &config(form, true));
            let mut ds = Array2::zeros(s.dim());
            sinkhorn_backward(ds.view_mut(), dc.view(), s.view(), c.view(), &cache).unwrap();
            ds
        };
        let grad32 = |form| {
            let (s, dc) = (s.mapv(|v| v as f32), dc.mapv(|v| v as f32));
            let (c, cache) = run(&s, &config(form, true));
            let mut ds = Array2::zeros(s.dim());
            sinkhorn_backward(ds.view_mut(), dc.view(), s.view(), c.view(), &cache).unwrap();
            ds.mapv(f64::from)
        };
        let exact = grad(&s, SinkhornForm::Log);
        let scale = exact.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for form in BOTH {
            let worst = (&grad32(form) - &exact)
                .iter()
                .fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(worst < 1e-5 * scale, "{form:?}: {worst:e} vs {scale:e}");
        }
    }

    #[test]
    fn scaling_form_stays_normal_at_the_bound() {
        // |S| ≤ 22 < ln(f32::MAX)/4: every entry of C̃ is ≥ e^{−3·22}/(N·M), a normal f32.
        let s = ix2(&uniform(&[40, 60], 8)) * 22.0;
        let (fast, cache) = run(&s.mapv(|v| v as f32), &config(SinkhornForm::Scaling, true));
        assert_eq!(cache.form(), SinkhornForm::Scaling);
        assert!(
            fast.iter().all(|v| v.is_normal()),
            "no zero, subnormal or infinite entry"
        );
        let (exact, _) = run(&s, &config(SinkhornForm::Log, true));
        let worst = fast
            .iter()
            .zip(&exact)
            .map(|(&a, &b)| (f64::from(a) - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{worst}");
    }

    #[test]
    fn scaling_falls_back_to_log_beyond_the_safe_range() {
        // exp(100) overflows f32: the scaling form must not run, and the log form stays exact.
        let mut s = ix2(&uniform(&[4, 5], 3)).mapv(|v| v as f32);
        s[[1, 2]] = 100.0;
        let (fast, cache) = run(&s, &config(SinkhornForm::Scaling, true));
        assert_eq!(cache.form(), SinkhornForm::Log);
        let (log, _) = run(&s, &config(SinkhornForm::Log, true));
        assert_eq!(fast, log);
        // S + α + β cancels values near 100, so f32 keeps about ulp(100) ≈ 8e-6 of the f64 result.
        let (exact, _) = run(&s.mapv(f64::from), &config(SinkhornForm::Log, true));
        let worst = fast
            .iter()
            .zip(&exact)
            .map(|(&a, &b)| (f64::from(a) - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 3e-5, "{worst}");
        assert!(
            exact[[1, 2]] > 0.9,
            "the dominant entry takes most of its row and column"
        );
    }

    /// With slack, after the last column step each real column of the padded matrix sums to 1
    /// up to rounding; each real row only approaches 1 (the slack column takes up the deficit
    /// slowly: on 20×30 entries in ±3 every row sum lies in [1 − 1e-4, 1] after 20 rounds;
    /// larger inputs stay further from 1, docs/match.md).
    #[test]
    fn padded_marginals_with_slack() {
        let s = ix2(&uniform(&[20, 30], 4)) * 3.0;
        for form in BOTH {
            let (c, cache) = run(&s, &config(form, true));
            let cols = c.sum_axis(Axis(0)) + cache.slack_row().unwrap(); // (M)
            let rows = c.sum_axis(Axis(1)) + cache.slack_column().unwrap(); // (N)
            assert!(
                cols.iter().all(|&v| (v - 1.0).abs() < 1e-13),
                "{form:?} columns {cols}"
            );
            assert!(
                rows.iter().all(|&v| v > 1.0 - 1e-4 && v <= 1.0 + 1e-13),
                "{form:?} rows {rows}"
            );
            assert!(
                rows.iter().any(|&v| v < 1.0 - 1e-6),
                "the row sums are not yet exactly 1"
            );
        }
    }

    #[test]
    fn row_shift_invariance_only_without_slack() {
        // Without slack a row's constant cancels in its first normalisation; with slack the
        // constant moves mass between that row and the slack column.
        let s = ix2(&uniform(&[5, 7], 6)) * 2.0;
        let mut shifted = s.clone();
        shifted.row_mut(2).mapv_inplace(|v| v + 1.5);
        for form in BOTH {
            let plain = |s: &Array2<f64>| run(s, &config(form, false)).0;
            assert!(plain(&s).abs_diff_eq(&plain(&shifted), 1e-13), "{form:?}");
            let padded = |s: &Array2<f64>| run(s, &config(form, true)).0;
            let moved = (padded(&s) - padded(&shifted)).mapv(f64::abs).sum();
            assert!(moved > 0.1, "{form:?}: slack result moved by only {moved}");
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        let cfg = SinkhornConfig::default();
        let mut c = Array2::<f64>::zeros((2, 2));
        let nan = array![[0.0, f64::NAN], [1.0, 2.0]];
        let err = sinkhorn_forward(
            c.view_mut(),
            nan.view(),
            &cfg,
            &mut SinkhornCache::new(2, 2, &cfg),
        );
        assert_eq!(
            err,
            Err(MatchError::NonFinite {
                op: "sinkhorn forward",
                what: "s"
            })
        );
        let none = SinkhornConfig {
            iterations: 0,
            ..cfg.clone()
        };
        let err = sinkhorn_forward(
            c.view_mut(),
            Array2::zeros((2, 2)).view(),
            &none,
            &mut SinkhornCache::new(2, 2, &none),
        );
        assert!(matches!(err, Err(MatchError::Config { .. })));
        let err = sinkhorn_forward(
            c.view_mut(),
            Array2::zeros((2, 3)).view(),
            &cfg,
            &mut SinkhornCache::new(2, 3, &cfg),
        );
        assert!(matches!(err, Err(MatchError::Shape { what: "c", .. })));
    }

    #[test]
    fn backward_matches_finite_differences() {
        // 19 columns: rows of two rounds of the backward's eight running sums and a remainder.
        for (n, m) in [(4, 6), (6, 4), (3, 19)] {
            for slack in [true, false] {
                for form in BOTH {
                    let cfg = config(form, slack);
                    let inputs = [uniform(&[n, m], 11) * 2.0];
                    let fwd = |i: &[ArrayD<f64>]| run(&ix2(&i[0]), &cfg);
                    let what = format!("sinkhorn {n}x{m} slack={slack} {form:?}");
                    assert_gradients(
                        &what,
                        1e-6,
                        &inputs,
                        &mut |i| fwd(i).0.into_dyn(),
                        &mut |i, dc| {
                            let (c, cache) = fwd(i);
                            assert_eq!(cache.form(), form);
                            let mut ds = Array2::zeros((n, m));
                            sinkhorn_backward(
                                ds.view_mut(),
                                ix2(dc).view(),
                                ix2(&i[0]).view(),
                                c.view(),
                                &cache,
                            )
                            .unwrap();
                            vec![ds.into_dyn()]
                        },
                    );
                }
            }
        }
    }
}
