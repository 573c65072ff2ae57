#!/usr/bin/env python3
"""A PyTorch implementation of the RGM network, written from `shared/spec/RGM.md` §2–3, with the
authors' parameter names (spec appendix), so that

* `dump_fixture` writes a tiny-configuration state — inputs, every parameter, the soft
  correspondence C̃ of a training-mode forward, the loss, every parameter gradient, the batch-norm
  running statistics after that step and the C̃ of an evaluation-mode forward with them — as a
  safetensors file that the Rust
  model's tests compare against tensor by tensor (the tests need no Python), and
* a state-dict of this module has exactly the layout of the authors' checkpoints, which proves a
  checkpoint converter on a randomly initialised paper-size model.

Usage:
    pip install torch safetensors numpy
    python3 tools/reference/rgm_reference.py dump --out crates/rgm-model/tests/fixtures/tiny.safetensors
    python3 tools/reference/rgm_reference.py params        # paper size: 25,002,889 values
    python3 tools/reference/rgm_reference.py convert model.pth --out rgm_weights.safetensors

Semantics that the spec leaves to the reference code and this file assumes:
* both clouds go through the feature extractor in two separate calls (batch-norm statistics of
  each cloud on its own; in training the running statistics are updated twice per step);
* batch normalisation over (batch × points × neighbours) for conv1–4, (batch × points) for conv5;
* kNN on the coordinates, the point itself first (distance 0), K = `k` neighbours in all.
"""
import argparse
import json
import math

import torch
import torch.nn as nn
import torch.nn.functional as F


PAPER = dict(k=20, dgcnn=(64, 64, 128, 256), edge=512, q=512, heads=4, ff=1024, blocks=2, sinkhorn_iters=20)
TINY = dict(k=4, dgcnn=(4, 4, 8, 8), edge=24, q=16, heads=4, ff=32, blocks=2, sinkhorn_iters=20)


class PointFeaturer(nn.Module):
    """DGCNN-style local features: four 1×1 convs on (x_n, x_i) edge rows, max over K after each,
    concatenated into node features; a fifth 1×1 conv on those gives edge features."""

    def __init__(self, k, widths, edge):
        super().__init__()
        self.k = k
        chans = (6,) + tuple(widths)
        for i in range(4):
            setattr(self, f"conv{i + 1}", nn.Conv2d(chans[i], chans[i + 1], 1, bias=False))
            setattr(self, f"bn{i + 1}", nn.BatchNorm2d(chans[i + 1]))
        self.conv5 = nn.Conv2d(sum(widths), edge, 1, bias=False)
        self.bn5 = nn.BatchNorm2d(edge)

    def forward(self, pts):  # pts (B, N, 3) → node (B, N, ΣW), edge (B, N, E)
        b, n, _ = pts.shape
        d = torch.cdist(pts, pts)  # (B, N, N)
        idx = d.topk(self.k, dim=-1, largest=False).indices  # (B, N, K), self first
        neigh = torch.gather(pts.unsqueeze(1).expand(b, n, n, 3), 2, idx.unsqueeze(-1).expand(b, n, self.k, 3))
        centre = pts.unsqueeze(2).expand(b, n, self.k, 3)
        x = torch.cat([neigh, centre], dim=-1).permute(0, 3, 1, 2)  # (B, 6, N, K)
        maxima = []
        for i in range(1, 5):
            x = F.relu(getattr(self, f"bn{i}")(getattr(self, f"conv{i}")(x)))  # (B, C, N, K)
            maxima.append(x.max(dim=-1, keepdim=True).values)  # (B, C, N, 1)
        node = torch.cat(maxima, dim=1)  # (B, ΣW, N, 1)
        edge = F.relu(self.bn5(self.conv5(node)))  # (B, E, N, 1)
        return node.squeeze(-1).transpose(1, 2), edge.squeeze(-1).transpose(1, 2)


class LayerNorm(nn.Module):
    """The annotated transformer's LayerNorm: unbiased std, eps added to the std."""

    def __init__(self, c, eps=1e-6):
        super().__init__()
        self.a_2 = nn.Parameter(torch.ones(c))
        self.b_2 = nn.Parameter(torch.zeros(c))
        self.eps = eps

    def forward(self, x):
        mean = x.mean(-1, keepdim=True)
        std = x.std(-1, keepdim=True)
        return self.a_2 * (x - mean) / (std + self.eps) + self.b_2


class SublayerConnection(nn.Module):
    def __init__(self, c):
        super().__init__()
        self.norm = LayerNorm(c)

    def forward(self, x, sublayer):
        return x + sublayer(self.norm(x))


class MultiHeadedAttention(nn.Module):
    def __init__(self, heads, c):
        super().__init__()
        self.h, self.d = heads, c // heads
        self.linears = nn.ModuleList([nn.Linear(c, c) for _ in range(4)])

    def forward(self, query, key, value):  # (B, N, C), (B, M, C), (B, M, C)
        b = query.shape[0]
        q, k, v = [lin(x).view(b, -1, self.h, self.d).transpose(1, 2) for lin, x in zip(self.linears, (query, key, value))]
        scores = q @ k.transpose(-2, -1) / math.sqrt(self.d)  # (B, H, N, M)
        x = scores.softmax(dim=-1) @ v  # (B, H, N, d)
        return self.linears[3](x.transpose(1, 2).contiguous().view(b, -1, self.h * self.d))


class FeedForward(nn.Module):
    def __init__(self, c, ff):
        super().__init__()
        self.w_1 = nn.Linear(c, ff)
        self.w_2 = nn.Linear(ff, c)

    def forward(self, x):
        return self.w_2(F.relu(self.w_1(x)))


class EncoderLayer(nn.Module):
    def __init__(self, c, heads, ff):
        super().__init__()
        self.self_attn = MultiHeadedAttention(heads, c)
        self.feed_forward = FeedForward(c, ff)
        self.sublayer = nn.ModuleList([SublayerConnection(c) for _ in range(2)])

    def forward(self, x):
        x = self.sublayer[0](x, lambda y: self.self_attn(y, y, y))
        return self.sublayer[1](x, self.feed_forward)


class DecoderLayer(nn.Module):
    def __init__(self, c, heads, ff):
        super().__init__()
        self.self_attn = MultiHeadedAttention(heads, c)
        self.src_attn = MultiHeadedAttention(heads, c)
        self.feed_forward = FeedForward(c, ff)
        self.sublayer = nn.ModuleList([SublayerConnection(c) for _ in range(3)])

    def forward(self, x, memory):
        x = self.sublayer[0](x, lambda y: self.self_attn(y, y, y))
        x = self.sublayer[1](x, lambda y: self.src_attn(y, memory, memory))
        return self.sublayer[2](x, self.feed_forward)


class Stack(nn.Module):
    def __init__(self, layer, c):
        super().__init__()
        self.layers = nn.ModuleList([layer])
        self.norm = LayerNorm(c)


class EncoderDecoder(nn.Module):
    def __init__(self, c, heads, ff):
        super().__init__()
        self.encoder = Stack(EncoderLayer(c, heads, ff), c)
        self.decoder = Stack(DecoderLayer(c, heads, ff), c)

    def forward(self, src, tgt):  # decoder(tgt, encoder(src))
        memory = src
        for layer in self.encoder.layers:
            memory = layer(memory)
        memory = self.encoder.norm(memory)
        x = tgt
        for layer in self.decoder.layers:
            x = layer(x, memory)
        return self.decoder.norm(x)


class Transformer(nn.Module):
    def __init__(self, c, heads, ff):
        super().__init__()
        self.model = EncoderDecoder(c, heads, ff)

    def forward(self, fx, fy):
        """T_X = decoder(X, encoder(Y)), T_Y = decoder(Y, encoder(X)); the same weights twice."""
        return self.model(fy, fx), self.model(fx, fy)


class GConv(nn.Module):
    def __init__(self, c, q):
        super().__init__()
        self.a_fc = nn.Linear(c, q)
        self.u_fc = nn.Linear(c, q)

    def forward(self, adj, x):
        """F' = Ê·ReLU(f_adj(F)) + ReLU(f_self(F)), Ê with columns summing to 1."""
        adj = F.normalize(adj, p=1, dim=-2)
        return adj @ F.relu(self.a_fc(x)) + F.relu(self.u_fc(x))


class GnnLayer(nn.Module):
    def __init__(self, c, q):
        super().__init__()
        self.gconv = GConv(c, q)


class Affinity(nn.Module):
    def __init__(self, q):
        super().__init__()
        self.A = nn.Parameter(torch.eye(q) + torch.empty(q, q).uniform_(-1 / math.sqrt(q), 1 / math.sqrt(q)))

    def forward(self, fx, fy):
        w = (self.A + self.A.transpose(0, 1)) / 2
        return fx @ w @ fy.transpose(1, 2)


def sinkhorn_slack(log_alpha, iters):
    """Log-domain Sinkhorn with one slack row and column (spec §2.4)."""
    padded = F.pad(log_alpha, (0, 1, 0, 1), value=0.0)  # (B, N+1, M+1)
    for _ in range(iters):
        padded = torch.cat(
            (padded[:, :-1, :] - torch.logsumexp(padded[:, :-1, :], dim=2, keepdim=True), padded[:, -1:, :]), dim=1
        )
        padded = torch.cat(
            (padded[:, :, :-1] - torch.logsumexp(padded[:, :, :-1], dim=1, keepdim=True), padded[:, :, -1:]), dim=2
        )
    return padded[:, :-1, :-1].exp()


class RGM(nn.Module):
    def __init__(self, k, dgcnn, edge, q, heads, ff, blocks, sinkhorn_iters):
        super().__init__()
        self.blocks, self.iters = blocks, sinkhorn_iters
        self.pointfeaturer = PointFeaturer(k, dgcnn, edge)
        c = sum(dgcnn) + edge
        for b in range(blocks):
            width = c if b == 0 else q
            setattr(self, f"gmattend{b}", Transformer(width, heads, ff))
            setattr(self, f"gnn_layer_{b}", GnnLayer(width, q))
            setattr(self, f"affinity_{b}", Affinity(q))
            setattr(self, f"InstNorm_layer_{b}", nn.InstanceNorm2d(1, affine=True))
        self.cross_graph_0 = nn.Linear(2 * q, q)

    def forward(self, x, y):  # (B, N, 3), (B, M, 3) → C̃ (B, N, M)
        fx = torch.cat(self.pointfeaturer(x), dim=-1)  # (B, N, C)
        fy = torch.cat(self.pointfeaturer(y), dim=-1)  # (B, M, C)
        for b in range(self.blocks):
            tx, ty = getattr(self, f"gmattend{b}")(fx, fy)
            scale = math.sqrt(tx.shape[-1])
            ex = (tx @ tx.transpose(1, 2) / scale).softmax(dim=-1)  # (B, N, N)
            ey = (ty @ ty.transpose(1, 2) / scale).softmax(dim=-1)  # (B, M, M)
            gconv = getattr(self, f"gnn_layer_{b}").gconv
            fx, fy = gconv(ex, fx), gconv(ey, fy)  # (B, N, Q), (B, M, Q)
            s = getattr(self, f"affinity_{b}")(fx, fy)  # (B, N, M)
            s = getattr(self, f"InstNorm_layer_{b}")(s.unsqueeze(1)).squeeze(1)
            c_soft = sinkhorn_slack(s, self.iters)
            if b == 0 and self.blocks > 1:
                fx, fy = (
                    self.cross_graph_0(torch.cat((fx, c_soft @ fy), dim=-1)),
                    self.cross_graph_0(torch.cat((fy, c_soft.transpose(1, 2) @ fx), dim=-1)),
                )
        return c_soft


def loss_bce(c_soft, gt):
    """BCE summed over all entries, divided by the number of source points (and the batch)."""
    return F.binary_cross_entropy(c_soft, gt, reduction="sum") / (c_soft.shape[0] * c_soft.shape[1])


def dump_fixture(out, seed=0, n=12, m=10):
    torch.manual_seed(seed)
    model = RGM(**TINY).double().train()
    x = torch.rand(1, n, 3, dtype=torch.float64) * 2 - 1
    y = torch.rand(1, m, 3, dtype=torch.float64) * 2 - 1
    gt = torch.zeros(1, n, m, dtype=torch.float64)
    for i in range(min(n, m) - 2):  # two outliers on each side
        gt[0, i, (i * 3) % m] = 1.0
    c_soft = model(x, y)
    loss = loss_bce(c_soft, gt)
    loss.backward()
    with torch.no_grad():  # test time: batch norm on the running statistics the step left
        c_soft_eval = model.eval()(x, y)
    tensors = {
        "input.x": x[0],
        "input.y": y[0],
        "input.gt": gt[0],
        "output.c_soft": c_soft[0].detach(),
        "output.loss": loss.detach().reshape(1),
        "output.c_soft_eval": c_soft_eval[0],
    }
    for name, p in model.named_parameters():
        tensors[f"param.{name}"] = p.detach()
        tensors[f"grad.{name}"] = p.grad.detach()
    for name, buf in model.named_buffers():
        if buf.dtype.is_floating_point:
            tensors[f"buffer.{name}"] = buf.detach()
    from safetensors.torch import save_file

    save_file({k: v.contiguous() for k, v in tensors.items()}, out, metadata={"format": "rgm-reference", "version": "1", "config": json.dumps(TINY), "seed": str(seed), "torch": torch.__version__, "mode": "train"})
    print(f"wrote {len(tensors)} tensors to {out}: loss {loss.item():.12f}")


def export_state_dict(out, config, points, seed):
    """What a converted checkpoint looks like: the state dict under the authors' names (the
    (out, in, 1, 1) conv weights kept 4-D), float32; plus `input.x`, `input.y` and the
    evaluation-mode `output.c_soft_eval` of the same weights, to check a loader against."""
    from safetensors.torch import save_file

    torch.manual_seed(seed)
    model = RGM(**config).eval()
    x = torch.rand(1, points, 3) * 2 - 1
    y = torch.rand(1, points, 3) * 2 - 1
    with torch.no_grad():
        c_soft = model(x, y)
    tensors = {k: v.contiguous() for k, v in model.state_dict().items() if v.dtype.is_floating_point}
    tensors.update({"input.x": x[0], "input.y": y[0], "output.c_soft_eval": c_soft[0]})
    save_file(tensors, out, metadata={"format": "rgm-state-dict", "config": json.dumps(config)})
    print(f"wrote {len(tensors)} tensors to {out}")


def convert_checkpoint(path, out):
    """An authors' checkpoint → safetensors under the same names, float32. The state dict may
    sit at the top level or under "model"/"state_dict"; a `module.` prefix (DataParallel) is
    dropped, and so are integer buffers (`num_batches_tracked`), which rgm does not use."""
    from safetensors.torch import save_file

    state = torch.load(path, map_location="cpu", weights_only=False)
    for key in ("state_dict", "model"):
        if isinstance(state, dict) and key in state and isinstance(state[key], dict):
            state = state[key]
    tensors = {
        name.removeprefix("module."): t.detach().float().contiguous()
        for name, t in state.items()
        if torch.is_tensor(t) and t.dtype.is_floating_point
    }
    names = set(RGM(**PAPER).state_dict())
    missing = sorted(n for n in names if n not in tensors and not n.endswith("num_batches_tracked"))
    if missing:
        raise SystemExit(f"{path}: not a paper-size RGM checkpoint; missing {missing[:5]}")
    save_file(tensors, out, metadata={"format": "rgm-state-dict", "source": str(path)})
    print(f"wrote {len(tensors)} tensors to {out}; use: rgm register SRC TGT --method rgm --weights {out}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="cmd", required=True)
    dump = sub.add_parser("dump", help="write the tiny-configuration reference state")
    dump.add_argument("--out", required=True)
    dump.add_argument("--seed", type=int, default=0)
    sub.add_parser("params", help="print the paper-size parameter count and names")
    export = sub.add_parser(
        "export",
        help="save a randomly initialised state dict (authors' names, float32) as safetensors, with a test pair and its evaluation-mode C̃",
    )
    export.add_argument("--out", required=True)
    export.add_argument("--preset", choices=["paper", "tiny"], default="paper")
    export.add_argument("--points", type=int, default=717)
    export.add_argument("--seed", type=int, default=0)
    convert = sub.add_parser("convert", help="turn an authors' PyTorch checkpoint (.pth) into a weight file for `rgm --weights`")
    convert.add_argument("checkpoint")
    convert.add_argument("--out", required=True)
    args = parser.parse_args()
    if args.cmd == "dump":
        dump_fixture(args.out, args.seed)
    elif args.cmd == "convert":
        convert_checkpoint(args.checkpoint, args.out)
    elif args.cmd == "export":
        export_state_dict(args.out, PAPER if args.preset == "paper" else TINY, args.points, args.seed)
    else:
        model = RGM(**PAPER)
        total = sum(p.numel() for p in model.parameters())
        buffers = sum(b.numel() for b in model.buffers())
        for name, p in model.state_dict().items():
            print(f"{name} {tuple(p.shape)}")
        print(f"parameters {total:,}; parameters + buffers {total + buffers:,}")


if __name__ == "__main__":
    main()
