//! The RGM network (spec §2): local features → L matching blocks → soft correspondence C̃ (N, M)
//! for one pair of clouds, with a hand-written backward pass that calls the layers' backward
//! passes in exact reverse order of the forward.
//!
//! Parameters carry the authors' PyTorch names (spec appendix), so a state dict of theirs saved
//! as safetensors loads by name ([`Rgm::load_tensors`], [`Rgm::load`]); 1×1 convolution weights
//! stored `(out, in, 1, 1)` load into the `(out, in)` linear weights.
//!
//! ```no_run
//! # use rgm_model::network::{Config, Mode, Rgm, RgmCache};
//! # fn main() -> rgm_model::network::Result<()> {
//! let mut rgm = Rgm::<f32>::new(Config::small(), 0)?;
//! let (x, y) = (ndarray::Array2::<f32>::zeros((717, 3)), ndarray::Array2::<f32>::zeros((717, 3)));
//! let mut cache = RgmCache::default();
//! rgm.forward(x.view(), y.view(), Mode::Train, &mut cache)?;
//! let dc = ndarray::Array2::<f32>::ones(cache.c_soft().dim()); // dLoss/dC̃
//! rgm.backward(dc.view(), &mut cache)?; // adds into every parameter's grad
//! # Ok(()) }
//! ```

mod block;
mod config;
mod error;
mod featurer;
mod transformer;

pub use block::{Block, BlockCache, Scorer};
pub use config::{Config, Edges, Scoring};
pub use error::{NetworkError, Result};
pub use featurer::{FeaturerCache, PointFeaturer, TestStatistics};
pub use transformer::{EdgeTransformer, EdgeTransformerCache, Stack, StackCache};

use ndarray::{Array2, ArrayD, ArrayView2, ArrayViewD, ArrayViewMutD};
use rand::{rngs::StdRng, SeedableRng};
use rayon::prelude::*;
use rgm_match::{bce_backward, bce_forward, Correspondences};
use rgm_nn::init::{Init, Unset};
use rgm_nn::param::{join_name, try_visit_buffers, try_visit_params, ParamView, ParamViewMut};
use rgm_nn::{Compute, Parameters, Scalar};
use std::collections::HashMap;
use std::path::Path;

/// The element types the network runs in (f32, f64): rgm-nn's [`Scalar`] plus `Default`, which
/// the ops' cache structs need to be created empty.
pub trait Element: Scalar + Default {}

impl<T: Scalar + Default> Element for T {}

/// Batch norm's behaviour: batch statistics (and running-statistics updates) in training,
/// running statistics at test time. Nothing else depends on it (no dropout).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Train,
    Eval,
}

/// `buf` with `shape`, all zeros (reallocated only when the shape changes).
pub(crate) fn zeroed<T: Element>(buf: &mut Array2<T>, shape: (usize, usize)) {
    if buf.dim() == shape {
        buf.fill(T::zero());
    } else {
        *buf = Array2::zeros(shape);
    }
}

/// `buf` with `shape`, its values left as they are (zeros when it is reallocated): for a
/// buffer the next op overwrites whole, where clearing it first would be a wasted pass over
/// memory.
pub(crate) fn shaped<T: Element>(buf: &mut Array2<T>, shape: (usize, usize)) {
    if buf.dim() != shape {
        *buf = Array2::zeros(shape);
    }
}

/// `a` then `b` on this thread, or side by side on rayon's pool when `side_by_side`. The two
/// must be independent: each is computed as on one thread, so the results are the same bits
/// either way.
pub(crate) fn both<A, B>(
    side_by_side: bool,
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B)
where
    A: Send,
    B: Send,
{
    if !side_by_side {
        return (a(), b());
    }
    rayon::join(a, b)
}

/// The RGM network: `pointfeaturer`, then L [`Block`]s.
#[derive(Clone, Debug)]
pub struct Rgm<T: Element> {
    config: Config,
    pub featurer: PointFeaturer<T>,
    pub blocks: Vec<Block<T>>,
    /// How its matrix products run ([`Rgm::set_compute`]): every pass hands it to the layers,
    /// whichever threads run them.
    compute: Compute,
}

/// One forward pass of a pair: every intermediate the backward needs, and the backward's
/// scratch. Reused across calls (buffers are reallocated only when N or M change).
#[derive(Clone, Debug, Default)]
pub struct RgmCache<T> {
    fx: FeaturerCache<T>, // X's local features (N, C)
    fy: FeaturerCache<T>, // Y's local features (M, C)
    blocks: Vec<BlockCache<T>>,
    dfeat: Vec<(Array2<T>, Array2<T>)>, // per block: gradient of its inputs, (N, C_b), (M, C_b)
    dc_soft: Array2<T>,                 // (N, M) loss gradient of C̃
    /// The blocks ran on features given by the caller ([`Rgm::forward_from_features`]): `fx`
    /// and `fy` are not this pass's, so there is no backward.
    from_features: bool,
}

impl<T> RgmCache<T> {
    /// C̃ (N, M) of the last forward pass: row i, column j is the soft correspondence of source
    /// point i and target point j. Empty before any forward.
    pub fn c_soft(&self) -> ArrayView2<'_, T> {
        match self.blocks.last() {
            Some(b) => b.c_soft.view(),
            None => ArrayView2::from_shape((0, 0), &[]).expect("empty"),
        }
    }
}

fn check_cloud<T: Element>(what: &'static str, p: ArrayView2<'_, T>) -> Result<()> {
    if p.ncols() != 3 {
        return Err(NetworkError::InputShape {
            what,
            got: p.shape().to_vec(),
        });
    }
    Ok(())
}

impl<T: Element> Rgm<T> {
    /// A network of `config`'s sizes with PyTorch's default initialisation drawn from `seed`.
    pub fn new(config: Config, seed: u64) -> Result<Self> {
        Self::with_init(config, &mut StdRng::seed_from_u64(seed))
    }

    /// A network of `config`'s sizes whose parameters come from `init`: [`Unset`] for one
    /// whose every parameter is set next ([`Rgm::load_tensors`]).
    pub fn with_init(config: Config, init: &mut impl Init) -> Result<Self> {
        config.validate()?;
        let featurer = PointFeaturer::new(config.k, config.dgcnn, config.edge, init);
        let blocks = (0..config.blocks)
            .map(|b| Block::new(&config, b, init))
            .collect::<Result<_>>()?;
        Ok(Self {
            config,
            featurer,
            blocks,
            compute: Compute::default(),
        })
    }

    /// A network of `config`'s sizes with every parameter and batch-norm statistic read from
    /// the safetensors file at `path` (see [`Rgm::load_tensors`]).
    pub fn load(config: Config, path: &Path) -> Result<Self> {
        Self::from_bytes(config, &rgm_nn::io::read_bytes(path)?, path)
    }

    /// [`Rgm::load`] from the bytes of a safetensors file in memory (`origin` names them in
    /// errors). The feature extractor and each block are made and filled side by side on
    /// rayon's pool: loading is most of what a one-pair process waits for besides the pair.
    pub fn from_bytes(config: Config, bytes: &[u8], origin: &Path) -> Result<Self> {
        config.validate()?;
        let fill = |part: &mut dyn Parameters<T>, prefix: &str| {
            rgm_nn::io::load_params_from_bytes(bytes, origin, prefix, part)
        };
        let (featurer, blocks) = rayon::join(
            || -> Result<PointFeaturer<T>> {
                let mut featurer =
                    PointFeaturer::new(config.k, config.dgcnn, config.edge, &mut Unset);
                fill(&mut featurer, "pointfeaturer")?;
                Ok(featurer)
            },
            || {
                (0..config.blocks)
                    .into_par_iter()
                    .map(|b| {
                        let mut block = Block::new(&config, b, &mut Unset)?;
                        fill(&mut block, "")?;
                        Ok(block)
                    })
                    .collect::<Result<Vec<_>>>()
            },
        );
        Ok(Self {
            config,
            featurer: featurer?,
            blocks: blocks?,
            compute: Compute::default(),
        })
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Runs the matrix products of every later pass as `compute` says: its precision f32 (the
    /// default) or bf16 (on AMX or AVX-512 BF16 where the processor has either, f32
    /// elsewhere). Parameters, batch-norm statistics, softmax, norms, Sinkhorn and the loss
    /// stay f32 either way; f64 networks ignore it.
    pub fn set_compute(&mut self, compute: Compute) {
        self.compute = compute;
    }

    /// The compute settings of its passes ([`Rgm::set_compute`]).
    pub fn compute(&self) -> Compute {
        self.compute
    }

    /// Sets every parameter and buffer from `tensors` by name (the authors' state-dict names).
    /// A `(out, in, 1, 1)` tensor fills an `(out, in)` weight; tensors the network does not use
    /// (`num_batches_tracked`, ...) are ignored; a missing or mis-shaped one is an error.
    pub fn load_tensors(&mut self, tensors: &HashMap<String, ArrayD<T>>) -> Result<()> {
        let fill = |name: &str, mut dst: ArrayViewMutD<'_, T>| {
            let t = tensors
                .get(name)
                .ok_or_else(|| NetworkError::MissingTensor {
                    name: name.to_string(),
                })?;
            let conv_1x1 =
                t.ndim() == 4 && t.shape()[2..] == [1, 1] && t.shape()[..2] == *dst.shape();
            if t.shape() != dst.shape() && !conv_1x1 {
                return Err(NetworkError::TensorShape {
                    name: name.to_string(),
                    expected: dst.shape().to_vec(),
                    got: t.shape().to_vec(),
                });
            }
            // Both in row order (a 1×1 convolution's trailing axes add none): one copy.
            match (dst.as_slice_mut(), t.as_slice()) {
                (Some(d), Some(v)) => d.copy_from_slice(v),
                _ => dst.iter_mut().zip(t.iter()).for_each(|(d, &v)| *d = v),
            }
            Ok(())
        };
        try_visit_params(self, "", |name, p| fill(name, p.value))?;
        try_visit_buffers(self, "", fill)
    }

    /// Runs the network on X (N, 3) and Y (M, 3); C̃ is then [`RgmCache::c_soft`]. `Mode::Train`
    /// uses and updates batch statistics (each cloud's on its own, X first).
    pub fn forward(
        &mut self,
        x: ArrayView2<'_, T>,
        y: ArrayView2<'_, T>,
        mode: Mode,
        cache: &mut RgmCache<T>,
    ) -> Result<()> {
        check_cloud("x", x)?;
        check_cloud("y", y)?;
        self.featurer
            .forward(x, mode, &mut cache.fx, self.compute)?;
        self.featurer
            .forward(y, mode, &mut cache.fy, self.compute)?;
        cache.from_features = false;
        let (fx, fy) = (cache.fx.features.view(), cache.fy.features.view());
        self.forward_blocks(fx, fy, &mut cache.blocks, false)
    }

    /// The local features (N, ΣC + E) of one cloud `points` (N, 3) at test time, into
    /// `cache.features`. In evaluation mode they depend on this cloud alone, so a cloud that
    /// meets several partners (the target over every pass, both clouds in the reverse pass) is
    /// run once; [`Rgm::forward_from_features`] then gives the same C̃ as [`Rgm::forward`].
    pub fn features(&self, points: ArrayView2<'_, T>, cache: &mut FeaturerCache<T>) -> Result<()> {
        check_cloud("points", points)?;
        self.featurer.forward_eval(points, cache, self.compute)
    }

    /// The blocks of an evaluation-mode forward on the local features `fx` (N, ΣC + E) and
    /// `fy` (M, ΣC + E) made by [`Rgm::features`]; C̃ is then [`RgmCache::c_soft`]. No
    /// backward follows such a pass: each block's two sides run side by side on rayon's pool,
    /// and the attention weights are not kept.
    pub fn forward_from_features(
        &self,
        fx: ArrayView2<'_, T>,
        fy: ArrayView2<'_, T>,
        cache: &mut RgmCache<T>,
    ) -> Result<()> {
        self.check_features(fx, fy)?;
        cache.from_features = true;
        self.forward_blocks(fx, fy, &mut cache.blocks, true)
    }

    /// The pass (X, Y) on `fx`, `fy` into `forward` and the reverse pass (Y, X) into `reverse`:
    /// what [`Rgm::forward_from_features`] gives for each, bit for bit, with block 0's edges
    /// and graph convolutions (its transformer, the widest layers) computed once and the
    /// reverse pass's taken from the forward's ([`Block::graph_from_swapped`] says why that is
    /// exact). The two passes then run side by side on rayon's pool. No backward follows.
    pub fn forward_both(
        &self,
        fx: ArrayView2<'_, T>,
        fy: ArrayView2<'_, T>,
        forward: &mut RgmCache<T>,
        reverse: &mut RgmCache<T>,
    ) -> Result<()> {
        self.check_features(fx, fy)?;
        let (n, m) = (fx.nrows(), fy.nrows());
        for (cache, dims) in [(&mut *forward, (n, m)), (&mut *reverse, (m, n))] {
            cache.from_features = true;
            self.size_blocks(&mut cache.blocks, dims);
        }
        let first = &self.blocks[0];
        first.graph_forward(fx, fy, &mut forward.blocks[0], true, self.compute)?;
        first.graph_from_swapped(&forward.blocks[0], &mut reverse.blocks[0])?;
        let (a, b) = both(
            true,
            || self.blocks_after_graph(&mut forward.blocks, true),
            || self.blocks_after_graph(&mut reverse.blocks, true),
        );
        a.and(b)
    }

    /// `fx` and `fy` are local features of the width block 0 reads.
    fn check_features(&self, fx: ArrayView2<'_, T>, fy: ArrayView2<'_, T>) -> Result<()> {
        let width = self.config.block_width(0);
        for (what, f) in [("fx", fx.view()), ("fy", fy.view())] {
            if f.ncols() != width {
                return Err(rgm_nn::NnError::Shape {
                    op: "rgm forward_from_features",
                    what,
                    expected: vec![f.nrows(), width],
                    got: f.shape().to_vec(),
                }
                .into());
            }
        }
        Ok(())
    }

    /// `blocks` sized for the L blocks on (N, M) = `dims` (rebuilt when N or M change).
    fn size_blocks(&self, blocks: &mut Vec<BlockCache<T>>, dims: (usize, usize)) {
        if blocks.len() != self.blocks.len() || blocks.first().map(|b| b.dims()) != Some(dims) {
            // Side by side: a new cache is mostly fresh memory filled with zeros (page faults),
            // and a one-pair process makes each once.
            *blocks = (0..self.blocks.len())
                .into_par_iter()
                .map(|_| BlockCache::new(&self.config, dims.0, dims.1))
                .collect();
        }
    }

    /// The L blocks on `fx` (N, C), `fy` (M, C), into `blocks`; at `test_time` no backward
    /// follows ([`Block::forward`]).
    fn forward_blocks(
        &self,
        fx: ArrayView2<'_, T>,
        fy: ArrayView2<'_, T>,
        blocks: &mut Vec<BlockCache<T>>,
        test_time: bool,
    ) -> Result<()> {
        self.size_blocks(blocks, (fx.nrows(), fy.nrows()));
        self.blocks[0].graph_forward(fx, fy, &mut blocks[0], test_time, self.compute)?;
        self.blocks_after_graph(blocks, test_time)
    }

    /// The rest of the L blocks once block 0's graph features are in `blocks[0]`: its
    /// scoring, Sinkhorn and cross convolution, then blocks 1 to L − 1.
    fn blocks_after_graph(&self, blocks: &mut [BlockCache<T>], test_time: bool) -> Result<()> {
        self.blocks[0].match_forward(&mut blocks[0], test_time, self.compute)?;
        for b in 1..self.blocks.len() {
            let (done, rest) = blocks.split_at_mut(b);
            let (fx, fy) = done[b - 1].outputs(self.blocks[b - 1].cross.is_some());
            self.blocks[b].forward(fx, fy, &mut rest[0], test_time, self.compute)?;
        }
        Ok(())
    }

    /// Adds into every parameter's gradient the gradient of a loss whose gradient with respect
    /// to C̃ is `dc_soft` (N, M), for the pass held in `cache`: the blocks from last to first,
    /// then the feature extractor for Y and for X.
    pub fn backward(&mut self, dc_soft: ArrayView2<'_, T>, cache: &mut RgmCache<T>) -> Result<()> {
        let blocks = self.blocks.len();
        if cache.from_features {
            return Err(NetworkError::Backward {
                why: "the cached pass ran from given features (forward_from_features); \
                      a backward needs Rgm::forward"
                    .to_string(),
            });
        }
        if cache.blocks.len() != blocks || dc_soft.dim() != cache.c_soft().dim() {
            return Err(NetworkError::Backward {
                why: format!(
                    "dc_soft has shape {:?}, the cached forward's C̃ {:?}",
                    dc_soft.shape(),
                    cache.c_soft().shape()
                ),
            });
        }
        cache.dfeat.resize_with(blocks, Default::default);
        for b in (0..blocks).rev() {
            let (before, after) = cache.blocks.split_at_mut(b);
            let (dnow, dlater) = cache.dfeat.split_at_mut(b + 1);
            let (fx, fy) = match before.last() {
                Some(prev) => prev.outputs(self.blocks[b - 1].cross.is_some()),
                None => (cache.fx.features.view(), cache.fy.features.view()),
            };
            let (dx, dy) = &mut dnow[b];
            zeroed(dx, fx.dim());
            zeroed(dy, fy.dim());
            let dnext = dlater.first().map(|(a, b)| (a.view(), b.view()));
            let dc = (b + 1 == blocks).then_some(dc_soft);
            self.blocks[b].backward(
                dx.view_mut(),
                dy.view_mut(),
                dc,
                dnext,
                fx,
                fy,
                &mut after[0],
                self.compute,
            )?;
        }
        let (dx, dy) = &cache.dfeat[0];
        self.featurer
            .backward(dy.view(), &mut cache.fy, self.compute)?;
        self.featurer
            .backward(dx.view(), &mut cache.fx, self.compute)?;
        Ok(())
    }

    /// One training pass for a pair: the forward in training mode, the BCE loss against the
    /// ground truth `gt` (spec §3: summed over N·M entries, divided by N), and its backward
    /// (adding into the parameter gradients). Returns the loss.
    pub fn forward_backward(
        &mut self,
        x: ArrayView2<'_, T>,
        y: ArrayView2<'_, T>,
        gt: &Correspondences,
        cache: &mut RgmCache<T>,
    ) -> Result<T> {
        self.forward(x, y, Mode::Train, cache)?;
        let loss = bce_forward(cache.c_soft(), gt)?;
        let mut dc = std::mem::take(&mut cache.dc_soft);
        zeroed(&mut dc, cache.c_soft().dim());
        bce_backward(dc.view_mut(), T::one(), cache.c_soft(), gt)?;
        let result = self.backward(dc.view(), cache);
        cache.dc_soft = dc;
        result.map(|()| loss)
    }
}

impl<T: Element> Parameters<T> for Rgm<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        self.featurer
            .visit_params_ref(&join_name(prefix, "pointfeaturer"), f);
        for block in &self.blocks {
            block.visit_params_ref(prefix, f);
        }
    }

    fn visit_buffers_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ArrayViewD<'a, T>)) {
        self.featurer
            .visit_buffers_ref(&join_name(prefix, "pointfeaturer"), f);
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        self.featurer
            .visit_params(&join_name(prefix, "pointfeaturer"), f);
        for block in &mut self.blocks {
            block.visit_params(prefix, f);
        }
    }

    fn visit_buffers(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ArrayViewMutD<'_, T>)) {
        self.featurer
            .visit_buffers(&join_name(prefix, "pointfeaturer"), f);
    }
}
