//! One matching block (spec §2.2–2.5): edge generator → soft adjacency → intra-graph
//! convolution → scoring (AIS or Var1) → Sinkhorn → cross-graph convolution (block L − 2 only).

use super::config::{Config, Edges, Scoring};
use super::transformer::{EdgeTransformer, EdgeTransformerCache};
use super::{both, shaped, zeroed, Element, Result};
use ndarray::{s, Array2, ArrayView2, ArrayViewMut2};
use rgm_match::{
    sinkhorn_backward, sinkhorn_forward, var1_backward, var1_forward, Affinity, AffinityCache,
    AffinityConfig, InstNorm, InstNormCache, InstNormConfig, SinkhornCache, SinkhornConfig,
    Var1Config,
};
use rgm_nn::gemm::{mat_mul, mat_mul_then};
use rgm_nn::init::Init;
use rgm_nn::param::{join_name, ParamView, ParamViewMut};
use rgm_nn::scalar::Then;
use rgm_nn::{
    l1_normalize_columns_backward, l1_normalize_columns_forward, matmul_backward, matmul_forward,
    relu_backward, softmax_rows_backward, softmax_rows_forward, Compute, L1NormalizeCache, Linear,
    Parameters,
};

/// The learned scoring of a block.
// One per block: the size difference of the variants costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Scorer<T: Element> {
    /// `affinity_{b}.A` and `InstNorm_layer_{b}`.
    Ais {
        affinity: Affinity<T>,
        inst_norm: InstNorm<T>,
    },
    /// No parameters: S = exp(0.5 − D).
    Var1,
}

/// Block b's layers, under the authors' names.
#[derive(Clone, Debug)]
pub struct Block<T: Element> {
    pub index: usize,                            // b
    pub transformer: Option<EdgeTransformer<T>>, // `gmattend{b}.model`; None for Var2
    pub a_fc: Linear<T>,                         // `gnn_layer_{b}.gconv.a_fc`: C → Q
    pub u_fc: Linear<T>,                         // `gnn_layer_{b}.gconv.u_fc`: C → Q
    pub scorer: Scorer<T>,
    pub cross: Option<Linear<T>>, // `cross_graph_{b}`: 2Q → Q, block L − 2 only
    sinkhorn: SinkhornConfig,
}

/// One cloud's side of a block pass (rows R = N for X, M for Y). The cross convolution's and
/// the backward's buffers are empty until a pass needs them, so that a test-time pass does not
/// touch their memory.
#[derive(Clone, Debug, Default)]
struct Side<T> {
    scores: Array2<T>,   // (R, R) T Tᵀ / √C
    adj: Array2<T>,      // (R, R) E = softmax_rows(scores)
    adj_norm: Array2<T>, // (R, R) Ê, columns summing to 1
    l1: L1NormalizeCache<T>,
    a_adj: Array2<T>,     // (R, Q) ReLU(f_adj(F))
    a_self: Array2<T>,    // (R, Q) ReLU(f_self(F))
    fp: Array2<T>,        // (R, Q) F' = Ê·ReLU(f_adj(F)) + ReLU(f_self(F))
    cat: Array2<T>,       // (R, 2Q) F' ⊕ C̃F'_other (cross blocks)
    next: Array2<T>,      // (R, Q) cross_graph(cat) (cross blocks)
    dt: Array2<T>,        // (R, C)
    dscores: Array2<T>,   // (R, R)
    dadj: Array2<T>,      // (R, R)
    dadj_norm: Array2<T>, // (R, R)
    dh: Array2<T>,        // (R, Q)
    dfp: Array2<T>,       // (R, Q)
    dcat: Array2<T>,      // (R, 2Q)
}

impl<T: Element> Side<T> {
    fn new(r: usize, q: usize) -> Self {
        let z = |rows, cols| Array2::zeros((rows, cols));
        Self {
            scores: z(r, r),
            adj: z(r, r),
            adj_norm: z(r, r),
            a_adj: z(r, q),
            a_self: z(r, q),
            fp: z(r, q),
            ..Default::default()
        }
    }
}

/// A block pass for one (N, M) pair: what the backward needs and its scratch.
#[derive(Clone, Debug)]
pub struct BlockCache<T> {
    dims: (usize, usize), // (N, M)
    transformer: EdgeTransformerCache<T>,
    x: Side<T>,
    y: Side<T>,
    s: Array2<T>,      // (N, M) affinity (AIS)
    s_norm: Array2<T>, // (N, M) Sinkhorn's log-domain input: instance-normalised affinity (AIS) or 0.5 − D² (Var1)
    affinity: AffinityCache<T>,
    inst_norm: InstNormCache<T>,
    sinkhorn: SinkhornCache<T>,
    /// (N, M) the block's soft correspondence C̃.
    pub c_soft: Array2<T>,
    dc: Array2<T>,      // (N, M), empty until a backward
    ds_norm: Array2<T>, // (N, M), empty until a backward
    ds: Array2<T>,      // (N, M), empty until a backward
}

impl<T: Element> BlockCache<T> {
    /// Buffers for a block of `config` on N source and M target points.
    pub fn new(config: &Config, n: usize, m: usize) -> Self {
        let q = config.q;
        let sinkhorn = sinkhorn_config(config);
        Self {
            dims: (n, m),
            transformer: EdgeTransformerCache::default(),
            x: Side::new(n, q),
            y: Side::new(m, q),
            s: Array2::zeros((n, m)),
            s_norm: Array2::zeros((n, m)),
            affinity: AffinityCache::new(n, q),
            inst_norm: InstNormCache::default(),
            sinkhorn: SinkhornCache::new(n, m, &sinkhorn),
            c_soft: Array2::zeros((n, m)),
            dc: Array2::default((0, 0)),
            ds_norm: Array2::default((0, 0)),
            ds: Array2::default((0, 0)),
        }
    }

    /// (N, M) this cache is sized for.
    pub fn dims(&self) -> (usize, usize) {
        self.dims
    }

    /// The block's output features for X (N, Q) and Y (M, Q): the cross-graph convolution's
    /// when the block has one, F' otherwise.
    pub fn outputs(&self, cross: bool) -> (ArrayView2<'_, T>, ArrayView2<'_, T>) {
        if cross {
            (self.x.next.view(), self.y.next.view())
        } else {
            (self.x.fp.view(), self.y.fp.view())
        }
    }
}

/// Var2's adjacency (spec §2.7): the fully connected graph without self-loops, A = 1 − I, its
/// columns normalised: 1/(R − 1) off the diagonal, 0 on it. `adj` is (R, R), R > 1.
fn full_adjacency<T: Element>(adj: &mut Array2<T>) {
    let r = adj.nrows();
    adj.fill(T::one() / T::from_f64((r - 1) as f64));
    adj.diag_mut().fill(T::zero());
}

fn sinkhorn_config(config: &Config) -> SinkhornConfig {
    SinkhornConfig {
        iterations: config.sinkhorn_iters,
        ..SinkhornConfig::default()
    }
}

/// Ê = column-L1-normalised softmax_rows(T Tᵀ / √C). `t`: (R, C).
fn edges_forward<T: Element>(
    side: &mut Side<T>,
    t: ArrayView2<'_, T>,
    compute: Compute,
) -> Result<()> {
    let scale = T::one() / T::from_f64(t.ncols() as f64).sqrt();
    mat_mul(scale, &t, &t.t(), T::zero(), &mut side.scores, compute);
    softmax_rows_forward(side.adj.view_mut(), side.scores.view())?;
    l1_normalize_columns_forward(side.adj_norm.view_mut(), side.adj.view(), &mut side.l1)?;
    Ok(())
}

/// Adds into `side.dt` the gradient of [`edges_forward`] given `side.dadj_norm`:
/// Z = T Tᵀ / √C  →  dT = (dZ + dZᵀ) T / √C.
fn edges_backward<T: Element>(
    side: &mut Side<T>,
    t: ArrayView2<'_, T>,
    compute: Compute,
) -> Result<()> {
    zeroed(&mut side.dadj, side.adj.dim());
    zeroed(&mut side.dscores, side.adj.dim());
    l1_normalize_columns_backward(
        side.dadj.view_mut(),
        side.dadj_norm.view(),
        side.adj.view(),
        side.adj_norm.view(),
        &side.l1,
    )?;
    softmax_rows_backward(side.dscores.view_mut(), side.dadj.view(), side.adj.view())?;
    // dZ + dZᵀ into the spent dadj buffer, so one product serves both factors of T Tᵀ.
    side.dadj.assign(&side.dscores.t());
    side.dadj += &side.dscores;
    let scale = T::one() / T::from_f64(t.ncols() as f64).sqrt();
    mat_mul(scale, &side.dadj, &t, T::one(), &mut side.dt, compute);
    Ok(())
}

impl<T: Element> Block<T> {
    /// Block `b` of `config`, PyTorch-initialised from `rng`.
    pub fn new(config: &Config, b: usize, init: &mut impl Init) -> Result<Self> {
        let (c, q) = (config.block_width(b), config.q);
        let transformer = match config.edges {
            Edges::Transformer => Some(EdgeTransformer::new(c, config.heads, config.ff, init)?),
            Edges::Full => None,
        };
        let a_fc = Linear::new(c, q, true, init);
        let u_fc = Linear::new(c, q, true, init);
        let scorer = match config.scoring {
            Scoring::Ais => Scorer::Ais {
                affinity: Affinity::new(&AffinityConfig { width: q }, init),
                inst_norm: InstNorm::new(&InstNormConfig::default()),
            },
            Scoring::Var1 => Scorer::Var1,
        };
        let cross = config
            .has_cross(b)
            .then(|| Linear::new(2 * q, q, true, init));
        Ok(Self {
            index: b,
            transformer,
            a_fc,
            u_fc,
            scorer,
            cross,
            sinkhorn: sinkhorn_config(config),
        })
    }

    /// F' = Ê·ReLU(f_adj(F)) + ReLU(f_self(F)) for one side. `f`: (R, C).
    fn gconv_forward(
        &self,
        side: &mut Side<T>,
        f: ArrayView2<'_, T>,
        compute: Compute,
    ) -> Result<()> {
        // The ReLUs in the products' write-backs: the backward reads their outputs only.
        self.a_fc.forward_relu(side.a_adj.view_mut(), f, compute)?;
        self.u_fc.forward_relu(side.a_self.view_mut(), f, compute)?;
        matmul_forward(
            side.fp.view_mut(),
            side.adj_norm.view(),
            side.a_adj.view(),
            compute,
        )?;
        side.fp += &side.a_self;
        Ok(())
    }

    /// Adds into `df` (R, C) the gradient of [`Self::gconv_forward`] given `side.dfp`, and
    /// writes Ê's into `side.dadj_norm`, in reverse: the Ê product, ReLU, f_adj; then ReLU,
    /// f_self.
    fn gconv_backward(
        &mut self,
        mut df: ArrayViewMut2<'_, T>,
        side: &mut Side<T>,
        f: ArrayView2<'_, T>,
        compute: Compute,
    ) -> Result<()> {
        // F'_adj = Ê A, A = ReLU(H)  →  dÊ = dF' Aᵀ, dH = (Êᵀ dF') ⊙ [A > 0] (ReLU's backward in
        // the product's write-back)
        shaped(&mut side.dadj_norm, side.adj.dim());
        shaped(&mut side.dh, side.a_adj.dim());
        let dfp = side.dfp.view();
        mat_mul(
            T::one(),
            &dfp,
            &side.a_adj.t(),
            T::zero(),
            &mut side.dadj_norm,
            compute,
        );
        let relu_grad = Then::ReluGrad(side.a_adj.view());
        mat_mul_then(&side.adj_norm.t(), &dfp, relu_grad, &mut side.dh, compute);
        self.a_fc
            .backward(df.view_mut(), side.dh.view(), f, compute)?;
        side.dh.fill(T::zero());
        relu_backward(side.dh.view_mut(), side.dfp.view(), side.a_self.view())?;
        self.u_fc.backward(df, side.dh.view(), f, compute)?;
        Ok(())
    }

    /// Runs the block on F_X (N, C), F_Y (M, C) into `cache` (C̃ and the output features).
    /// At `test_time` (no backward follows) the two clouds' edges and graph convolutions run
    /// side by side on rayon's pool.
    pub fn forward(
        &self,
        fx: ArrayView2<'_, T>,
        fy: ArrayView2<'_, T>,
        cache: &mut BlockCache<T>,
        test_time: bool,
        compute: Compute,
    ) -> Result<()> {
        self.graph_forward(fx, fy, cache, test_time, compute)?;
        self.match_forward(cache, test_time, compute)
    }

    /// Takes into `cache` (sized (M, N)) the graph features of the block's pass on (X, Y) in
    /// `swapped`, for a pass on (Y, X): after it, [`Block::match_forward`] gives what
    /// `forward(fy, fx, cache)` gives, bit for bit, without recomputing the edges and the graph
    /// convolutions. They see one cloud and the other's encoding through the same weights in
    /// both directions, so the (Y, X) pass's F'_Y, F'_X are the (X, Y) pass's; the scoring,
    /// Sinkhorn and cross convolution run anew (Sinkhorn normalises rows first, so its result
    /// on Sᵀ is not the transpose of its result on S). No backward follows.
    pub fn graph_from_swapped(
        &self,
        swapped: &BlockCache<T>,
        cache: &mut BlockCache<T>,
    ) -> Result<()> {
        let (n, m) = swapped.dims;
        if cache.dims != (m, n) {
            return Err(rgm_nn::NnError::Shape {
                op: "rgm block graph_from_swapped",
                what: "cache",
                expected: vec![m, n],
                got: vec![cache.dims.0, cache.dims.1],
            }
            .into());
        }
        cache.x.fp.assign(&swapped.y.fp);
        cache.y.fp.assign(&swapped.x.fp);
        Ok(())
    }

    /// Edges and intra-graph convolutions: F'_X (N, Q), F'_Y (M, Q) into `cache`; at
    /// `test_time` (no backward follows) the two sides side by side on rayon's pool.
    pub fn graph_forward(
        &self,
        fx: ArrayView2<'_, T>,
        fy: ArrayView2<'_, T>,
        cache: &mut BlockCache<T>,
        test_time: bool,
        compute: Compute,
    ) -> Result<()> {
        let edges = match &self.transformer {
            Some(tf) => {
                tf.forward(fx, fy, &mut cache.transformer, test_time, compute)?;
                Some((cache.transformer.tx().view(), cache.transformer.ty().view()))
            }
            None => None,
        };
        // One side: its edges (the transformer's T, or all of them), then its convolution.
        let side = |side: &mut Side<T>, f: ArrayView2<'_, T>, t: Option<ArrayView2<'_, T>>| {
            match t {
                Some(t) => edges_forward(side, t, compute)?,
                None => full_adjacency(&mut side.adj_norm),
            }
            self.gconv_forward(side, f, compute)
        };
        let (x, y) = (&mut cache.x, &mut cache.y);
        let (a, b) = both(
            test_time,
            || side(x, fx, edges.map(|(tx, _)| tx)),
            || side(y, fy, edges.map(|(_, ty)| ty)),
        );
        a.and(b)
    }

    /// Scoring of F'_X, F'_Y (AIS or Var1), Sinkhorn → C̃, and the cross-graph convolution
    /// when the block has one, all in `cache`; at `test_time` (no backward follows) the
    /// convolution's two sides side by side on rayon's pool.
    pub fn match_forward(
        &self,
        cache: &mut BlockCache<T>,
        test_time: bool,
        compute: Compute,
    ) -> Result<()> {
        let (x, y) = (&mut cache.x, &mut cache.y);
        match &self.scorer {
            Scorer::Ais {
                affinity,
                inst_norm,
            } => {
                affinity.forward(
                    cache.s.view_mut(),
                    x.fp.view(),
                    y.fp.view(),
                    &mut cache.affinity,
                    compute,
                )?;
                inst_norm.forward(
                    cache.s_norm.view_mut(),
                    cache.s.view(),
                    &mut cache.inst_norm,
                )?;
            }
            Scorer::Var1 => var1_forward(
                cache.s_norm.view_mut(),
                x.fp.view(),
                y.fp.view(),
                &Var1Config::default(),
            )?,
        }
        sinkhorn_forward(
            cache.c_soft.view_mut(),
            cache.s_norm.view(),
            &self.sinkhorn,
            &mut cache.sinkhorn,
        )?;
        if let Some(cross) = &self.cross {
            // next_X = cross(F'_X ⊕ C̃ F'_Y), next_Y = cross(F'_Y ⊕ C̃ᵀ F'_X)
            let q = x.fp.ncols();
            for side in [&mut *x, &mut *y] {
                shaped(&mut side.cat, (side.fp.nrows(), 2 * q));
                shaped(&mut side.next, side.fp.dim());
            }
            // One side: [own | C̃ (or C̃ᵀ) · other] (rows, 2Q) into `cat`, the layer into `next`.
            let side = |cat: &mut Array2<T>,
                        next: &mut Array2<T>,
                        own: ArrayView2<'_, T>,
                        c: ArrayView2<'_, T>,
                        other: ArrayView2<'_, T>| {
                cat.slice_mut(s![.., ..q]).assign(&own);
                matmul_forward(cat.slice_mut(s![.., q..]), c, other, compute)?;
                cross.forward(next.view_mut(), cat.view(), compute)
            };
            let c_soft = cache.c_soft.view();
            let (fpx, fpy) = (x.fp.view(), y.fp.view());
            let (a, b) = both(
                test_time,
                || side(&mut x.cat, &mut x.next, fpx, c_soft, fpy),
                || side(&mut y.cat, &mut y.next, fpy, c_soft.t(), fpx),
            );
            a.and(b)?;
        }
        Ok(())
    }

    /// Adds into `dfx` (N, C), `dfy` (M, C) and the block's parameter gradients the gradient of
    /// its pass, given the gradients of its outputs: `dc_soft` (N, M) when C̃ is the network's
    /// output, `dnext` ((N, Q), (M, Q)) when a later block reads its features. Inputs as given
    /// to forward. Walks the forward in reverse.
    #[allow(clippy::too_many_arguments)]
    pub fn backward<'a>(
        &mut self,
        mut dfx: ArrayViewMut2<'_, T>,
        mut dfy: ArrayViewMut2<'_, T>,
        dc_soft: Option<ArrayView2<'_, T>>,
        dnext: Option<(ArrayView2<'a, T>, ArrayView2<'a, T>)>,
        fx: ArrayView2<'_, T>,
        fy: ArrayView2<'_, T>,
        cache: &mut BlockCache<T>,
        compute: Compute,
    ) -> Result<()> {
        let (x, y) = (&mut cache.x, &mut cache.y);
        zeroed(&mut x.dfp, x.fp.dim());
        zeroed(&mut y.dfp, y.fp.dim());
        zeroed(&mut cache.dc, cache.dims);
        if let Some(d) = dc_soft {
            cache.dc.assign(&d);
        }
        match (&mut self.cross, dnext) {
            (Some(cross), Some((dnx, dny))) => {
                let q = x.fp.ncols();
                for (side, dnext) in [(&mut *y, dny), (&mut *x, dnx)] {
                    zeroed(&mut side.dcat, side.cat.dim());
                    cross.backward(side.dcat.view_mut(), dnext, side.cat.view(), compute)?;
                    side.dfp += &side.dcat.slice(s![.., ..q]);
                }
                // cat_Y[:, Q..] = C̃ᵀ F'_X  →  dC̃ᵀ += dcat_Y F'_Xᵀ, dF'_X += C̃ dcat_Y
                matmul_backward(
                    cache.dc.view_mut().reversed_axes(),
                    x.dfp.view_mut(),
                    y.dcat.slice(s![.., q..]),
                    cache.c_soft.t(),
                    x.fp.view(),
                    compute,
                )?;
                // cat_X[:, Q..] = C̃ F'_Y  →  dC̃ += dcat_X F'_Yᵀ, dF'_Y += C̃ᵀ dcat_X
                matmul_backward(
                    cache.dc.view_mut(),
                    y.dfp.view_mut(),
                    x.dcat.slice(s![.., q..]),
                    cache.c_soft.view(),
                    y.fp.view(),
                    compute,
                )?;
            }
            (None, Some((dnx, dny))) => {
                x.dfp += &dnx;
                y.dfp += &dny;
            }
            (_, None) => {}
        }
        zeroed(&mut cache.ds_norm, cache.dims);
        sinkhorn_backward(
            cache.ds_norm.view_mut(),
            cache.dc.view(),
            cache.s_norm.view(),
            cache.c_soft.view(),
            &cache.sinkhorn,
        )?;
        match &mut self.scorer {
            Scorer::Ais {
                affinity,
                inst_norm,
            } => {
                zeroed(&mut cache.ds, cache.dims);
                inst_norm.backward(
                    cache.ds.view_mut(),
                    cache.ds_norm.view(),
                    cache.s.view(),
                    &cache.inst_norm,
                )?;
                affinity.backward(
                    x.dfp.view_mut(),
                    y.dfp.view_mut(),
                    cache.ds.view(),
                    x.fp.view(),
                    y.fp.view(),
                    &cache.affinity,
                    compute,
                )?;
            }
            Scorer::Var1 => var1_backward(
                x.dfp.view_mut(),
                y.dfp.view_mut(),
                cache.ds_norm.view(),
                x.fp.view(),
                y.fp.view(),
            )?,
        }
        self.gconv_backward(dfy.view_mut(), y, fy, compute)?;
        self.gconv_backward(dfx.view_mut(), x, fx, compute)?;
        if let Some(tf) = &mut self.transformer {
            zeroed(&mut x.dt, cache.transformer.tx().dim());
            zeroed(&mut y.dt, cache.transformer.ty().dim());
            edges_backward(y, cache.transformer.ty().view(), compute)?;
            edges_backward(x, cache.transformer.tx().view(), compute)?;
            tf.backward(
                dfx,
                dfy,
                x.dt.view(),
                y.dt.view(),
                &mut cache.transformer,
                compute,
            )?;
        }
        Ok(())
    }
}

impl<T: Element> Parameters<T> for Block<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        let b = self.index;
        if let Some(tf) = &self.transformer {
            tf.visit_params_ref(&join_name(prefix, &format!("gmattend{b}.model")), f);
        }
        let gconv = join_name(prefix, &format!("gnn_layer_{b}.gconv"));
        self.a_fc.visit_params_ref(&join_name(&gconv, "a_fc"), f);
        self.u_fc.visit_params_ref(&join_name(&gconv, "u_fc"), f);
        if let Scorer::Ais {
            affinity,
            inst_norm,
        } = &self.scorer
        {
            affinity.visit_params_ref(&join_name(prefix, &format!("affinity_{b}")), f);
            inst_norm.visit_params_ref(&join_name(prefix, &format!("InstNorm_layer_{b}")), f);
        }
        if let Some(cross) = &self.cross {
            cross.visit_params_ref(&join_name(prefix, &format!("cross_graph_{b}")), f);
        }
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        let b = self.index;
        if let Some(tf) = &mut self.transformer {
            tf.visit_params(&join_name(prefix, &format!("gmattend{b}.model")), f);
        }
        let gconv = join_name(prefix, &format!("gnn_layer_{b}.gconv"));
        self.a_fc.visit_params(&join_name(&gconv, "a_fc"), f);
        self.u_fc.visit_params(&join_name(&gconv, "u_fc"), f);
        if let Scorer::Ais {
            affinity,
            inst_norm,
        } = &mut self.scorer
        {
            affinity.visit_params(&join_name(prefix, &format!("affinity_{b}")), f);
            inst_norm.visit_params(&join_name(prefix, &format!("InstNorm_layer_{b}")), f);
        }
        if let Some(cross) = &mut self.cross {
            cross.visit_params(&join_name(prefix, &format!("cross_graph_{b}")), f);
        }
    }
}
