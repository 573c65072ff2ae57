//! The edge generator's transformer (spec §2.2): a pre-norm encoder layer and decoder layer
//! (the annotated transformer's, one layer each, no dropout), run in both directions with the
//! same weights: T_X = decoder(X, encoder(Y)), T_Y = decoder(Y, encoder(X)).

use super::{both, shaped, zeroed, Element, Result};
use ndarray::{Array2, ArrayView2, ArrayViewMut2};
use rgm_nn::init::Init;
use rgm_nn::param::{join_name, ParamView, ParamViewMut};
use rgm_nn::{
    AttentionCache, Compute, FeedForward, FeedForwardCache, LayerNorm, LayerNormCache,
    MultiHeadAttention, Parameters,
};

/// An encoder (sub-layers: self-attention, feed-forward) or decoder (self-attention,
/// cross-attention to the memory, feed-forward) with its final LayerNorm. Sub-layer i computes
/// `x + op_i(LN_i(x))`.
#[derive(Clone, Debug)]
pub struct Stack<T: Element> {
    pub self_attn: MultiHeadAttention<T>,
    pub src_attn: Option<MultiHeadAttention<T>>, // decoder only
    pub feed_forward: FeedForward<T>,
    pub sublayer_norms: Vec<LayerNorm<T>>, // 2 (encoder) or 3 (decoder)
    pub norm: LayerNorm<T>,
}

/// One pass through a [`Stack`]: what the backward needs and its scratch.
#[derive(Clone, Debug, Default)]
pub struct StackCache<T> {
    xs: Vec<Array2<T>>, // S + 1: (R, C) each sub-layer's input, then the final norm's
    normed: Vec<Array2<T>>, // S: (R, C) each sub-layer's LayerNorm output
    ln: Vec<LayerNormCache<T>>, // S + 1
    attn: Vec<AttentionCache<T>>, // one per attention sub-layer
    ff: FeedForwardCache<T>,
    /// (R, C) the stack's output.
    pub out: Array2<T>,
    dx: Array2<T>,      // (R, C) gradient of the current sub-layer's output
    dnormed: Array2<T>, // (R, C)
}

/// The operation of sub-layer `i` of a stack.
enum Op {
    SelfAttention,
    CrossAttention,
    FeedForward,
}

impl<T: Element> Stack<T> {
    fn new(c: usize, heads: usize, ff: usize, decoder: bool, init: &mut impl Init) -> Result<Self> {
        let self_attn = MultiHeadAttention::new(c, heads, init)?;
        let src_attn = if decoder {
            Some(MultiHeadAttention::new(c, heads, init)?)
        } else {
            None
        };
        let feed_forward = FeedForward::new(c, ff, init);
        let subs = if decoder { 3 } else { 2 };
        Ok(Self {
            self_attn,
            src_attn,
            feed_forward,
            sublayer_norms: (0..subs).map(|_| LayerNorm::new(c)).collect(),
            norm: LayerNorm::new(c),
        })
    }

    fn op(&self, i: usize) -> Op {
        match (i, self.src_attn.is_some()) {
            (0, _) => Op::SelfAttention,
            (1, true) => Op::CrossAttention,
            _ => Op::FeedForward,
        }
    }

    /// `x` (R, C) through the stack into `cache.out`; `memory` (R_m, C) is the encoder output
    /// a decoder attends to (ignored by an encoder). At `test_time` no backward follows, and
    /// the attention weights are not kept.
    pub fn forward(
        &self,
        x: ArrayView2<'_, T>,
        memory: ArrayView2<'_, T>,
        cache: &mut StackCache<T>,
        test_time: bool,
        compute: Compute,
    ) -> Result<()> {
        let subs = self.sublayer_norms.len();
        let shape = x.dim();
        cache.xs.resize_with(subs + 1, Default::default);
        cache.normed.resize_with(subs, Default::default);
        cache.ln.resize_with(subs + 1, Default::default);
        cache.attn.resize_with(subs - 1, Default::default);
        shaped(&mut cache.xs[0], shape);
        cache.xs[0].assign(&x);
        shaped(&mut cache.dx, shape); // scratch: each sub-layer's output before the residual
        for i in 0..subs {
            shaped(&mut cache.normed[i], shape);
            self.sublayer_norms[i].forward(
                cache.normed[i].view_mut(),
                cache.xs[i].view(),
                &mut cache.ln[i],
            )?;
            let (normed, out) = (cache.normed[i].view(), cache.dx.view_mut());
            match self.op(i) {
                Op::SelfAttention => self.self_attn.forward_keeping(
                    out,
                    normed,
                    normed,
                    &mut cache.attn[0],
                    !test_time,
                    compute,
                )?,
                Op::CrossAttention => self.src_attn.as_ref().expect("decoder").forward_keeping(
                    out,
                    normed,
                    memory,
                    &mut cache.attn[1],
                    !test_time,
                    compute,
                )?,
                Op::FeedForward => {
                    self.feed_forward
                        .forward(out, normed, &mut cache.ff, compute)?
                }
            }
            // x_{i+1} = x_i + op_i(LN_i(x_i))
            let (done, rest) = cache.xs.split_at_mut(i + 1);
            shaped(&mut rest[0], shape);
            rest[0].assign(&done[i]);
            rest[0] += &cache.dx;
        }
        shaped(&mut cache.out, shape);
        self.norm.forward(
            cache.out.view_mut(),
            cache.xs[subs].view(),
            &mut cache.ln[subs],
        )?;
        Ok(())
    }

    /// Adds into `dx` (R, C) and, for a decoder, `dmemory` (R_m, C) the gradients of the pass
    /// given `dout` (R, C), and into the stack's parameter gradients.
    pub fn backward(
        &mut self,
        mut dx: ArrayViewMut2<'_, T>,
        dmemory: Option<ArrayViewMut2<'_, T>>,
        dout: ArrayView2<'_, T>,
        memory: ArrayView2<'_, T>,
        cache: &mut StackCache<T>,
        compute: Compute,
    ) -> Result<()> {
        let subs = self.sublayer_norms.len();
        let shape = cache.out.dim();
        zeroed(&mut cache.dx, shape);
        // out = LN(x_S)
        self.norm.backward(
            cache.dx.view_mut(),
            dout,
            cache.xs[subs].view(),
            &cache.ln[subs],
        )?;
        let mut dmemory = dmemory;
        for i in (0..subs).rev() {
            // x_{i+1} = x_i + op_i(n_i), n_i = LN_i(x_i): dx_i = dx_{i+1} + LN_i'(op_i'(dx_{i+1}))
            zeroed(&mut cache.dnormed, shape);
            let (dnormed, d_op, normed) = (
                cache.dnormed.view_mut(),
                cache.dx.view(),
                cache.normed[i].view(),
            );
            match self.op(i) {
                Op::SelfAttention => self.self_attn.backward(
                    dnormed,
                    None,
                    d_op,
                    normed,
                    normed,
                    &mut cache.attn[0],
                    compute,
                )?,
                Op::CrossAttention => self.src_attn.as_mut().expect("decoder").backward(
                    dnormed,
                    dmemory.as_mut().map(|d| d.view_mut()),
                    d_op,
                    normed,
                    memory,
                    &mut cache.attn[1],
                    compute,
                )?,
                Op::FeedForward => {
                    self.feed_forward
                        .backward(dnormed, d_op, normed, &mut cache.ff, compute)?
                }
            }
            self.sublayer_norms[i].backward(
                cache.dx.view_mut(),
                cache.dnormed.view(),
                cache.xs[i].view(),
                &cache.ln[i],
            )?;
        }
        dx += &cache.dx;
        Ok(())
    }
}

impl<T: Element> Parameters<T> for Stack<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        let layer = join_name(prefix, "layers.0");
        self.self_attn
            .visit_params_ref(&join_name(&layer, "self_attn"), f);
        if let Some(src) = &self.src_attn {
            src.visit_params_ref(&join_name(&layer, "src_attn"), f);
        }
        self.feed_forward
            .visit_params_ref(&join_name(&layer, "feed_forward"), f);
        for (i, norm) in self.sublayer_norms.iter().enumerate() {
            norm.visit_params_ref(&join_name(&layer, &format!("sublayer.{i}.norm")), f);
        }
        self.norm.visit_params_ref(&join_name(prefix, "norm"), f);
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        let layer = join_name(prefix, "layers.0");
        self.self_attn
            .visit_params(&join_name(&layer, "self_attn"), f);
        if let Some(src) = &mut self.src_attn {
            src.visit_params(&join_name(&layer, "src_attn"), f);
        }
        self.feed_forward
            .visit_params(&join_name(&layer, "feed_forward"), f);
        for (i, norm) in self.sublayer_norms.iter_mut().enumerate() {
            norm.visit_params(&join_name(&layer, &format!("sublayer.{i}.norm")), f);
        }
        self.norm.visit_params(&join_name(prefix, "norm"), f);
    }
}

/// The shared encoder-decoder (`gmattend{b}.model`).
#[derive(Clone, Debug)]
pub struct EdgeTransformer<T: Element> {
    pub encoder: Stack<T>,
    pub decoder: Stack<T>,
}

/// Both directions' passes.
#[derive(Clone, Debug, Default)]
pub struct EdgeTransformerCache<T> {
    enc_x: StackCache<T>,
    enc_y: StackCache<T>,
    dec_x: StackCache<T>, // out: T_X (N, C)
    dec_y: StackCache<T>, // out: T_Y (M, C)
    dmem_x: Array2<T>,    // (N, C)
    dmem_y: Array2<T>,    // (M, C)
}

impl<T> EdgeTransformerCache<T> {
    /// T_X (N, C) after a forward pass.
    pub fn tx(&self) -> &Array2<T> {
        &self.dec_x.out
    }

    /// T_Y (M, C) after a forward pass.
    pub fn ty(&self) -> &Array2<T> {
        &self.dec_y.out
    }
}

impl<T: Element> EdgeTransformer<T> {
    /// Width C, H heads, feed-forward width `ff`; PyTorch initialisation.
    pub fn new(c: usize, heads: usize, ff: usize, init: &mut impl Init) -> Result<Self> {
        let encoder = Stack::new(c, heads, ff, false, init)?;
        Ok(Self {
            encoder,
            decoder: Stack::new(c, heads, ff, true, init)?,
        })
    }

    /// T_X = decoder(F_X, encoder(F_Y)), T_Y = decoder(F_Y, encoder(F_X)).
    /// `fx`: (N, C), `fy`: (M, C). At `test_time` (no backward follows) the two encoders run
    /// side by side on rayon's pool, then the two decoders.
    pub fn forward(
        &self,
        fx: ArrayView2<'_, T>,
        fy: ArrayView2<'_, T>,
        cache: &mut EdgeTransformerCache<T>,
        test_time: bool,
        compute: Compute,
    ) -> Result<()> {
        let (enc_x, enc_y) = (&mut cache.enc_x, &mut cache.enc_y);
        let (a, b) = both(
            test_time,
            || self.encoder.forward(fx, fx, enc_x, test_time, compute),
            || self.encoder.forward(fy, fy, enc_y, test_time, compute),
        );
        a.and(b)?;
        let (mem_x, mem_y) = (cache.enc_y.out.view(), cache.enc_x.out.view());
        let (dec_x, dec_y) = (&mut cache.dec_x, &mut cache.dec_y);
        let (a, b) = both(
            test_time,
            || self.decoder.forward(fx, mem_x, dec_x, test_time, compute),
            || self.decoder.forward(fy, mem_y, dec_y, test_time, compute),
        );
        a.and(b)
    }

    /// Adds into `dfx` (N, C), `dfy` (M, C) the gradients given `dtx` (N, C), `dty` (M, C):
    /// the four passes in reverse.
    pub fn backward(
        &mut self,
        mut dfx: ArrayViewMut2<'_, T>,
        mut dfy: ArrayViewMut2<'_, T>,
        dtx: ArrayView2<'_, T>,
        dty: ArrayView2<'_, T>,
        cache: &mut EdgeTransformerCache<T>,
        compute: Compute,
    ) -> Result<()> {
        zeroed(&mut cache.dmem_x, cache.enc_x.out.dim());
        zeroed(&mut cache.dmem_y, cache.enc_y.out.dim());
        self.decoder.backward(
            dfy.view_mut(),
            Some(cache.dmem_x.view_mut()),
            dty,
            cache.enc_x.out.view(),
            &mut cache.dec_y,
            compute,
        )?;
        self.decoder.backward(
            dfx.view_mut(),
            Some(cache.dmem_y.view_mut()),
            dtx,
            cache.enc_y.out.view(),
            &mut cache.dec_x,
            compute,
        )?;
        let empty = Array2::zeros((0, 0));
        self.encoder.backward(
            dfy,
            None,
            cache.dmem_y.view(),
            empty.view(),
            &mut cache.enc_y,
            compute,
        )?;
        self.encoder.backward(
            dfx,
            None,
            cache.dmem_x.view(),
            empty.view(),
            &mut cache.enc_x,
            compute,
        )
    }
}

impl<T: Element> Parameters<T> for EdgeTransformer<T> {
    fn visit_params_ref<'a>(&'a self, prefix: &str, f: &mut dyn FnMut(&str, ParamView<'a, T>)) {
        self.encoder
            .visit_params_ref(&join_name(prefix, "encoder"), f);
        self.decoder
            .visit_params_ref(&join_name(prefix, "decoder"), f);
    }

    fn visit_params(&mut self, prefix: &str, f: &mut dyn FnMut(&str, ParamViewMut<'_, T>)) {
        self.encoder.visit_params(&join_name(prefix, "encoder"), f);
        self.decoder.visit_params(&join_name(prefix, "decoder"), f);
    }
}
