"""Prints the PyTorch reference values pinned in crates/rgm-nn/src/pytorch_pinned.rs.

Run: python3 tools/pytorch/pinned_values.py > /tmp/pinned.rs   (torch 1.13, float64, CPU)
and paste the printed constants into the `values` module of that file.

Every input is `sin(0.7 k + seed)` over the flat row-major index k (the Rust test builds the same
arrays), every loss is `sum(out * R)` with R = `pinned(out.shape, 99)`, so the printed gradients
are dL/d(input) for that R.
"""
import math
import torch
import torch.nn.functional as F

torch.set_default_dtype(torch.float64)


def pinned(shape, seed):
    n = math.prod(shape)
    return torch.tensor([math.sin(0.7 * k + seed) for k in range(n)]).reshape(shape)


def leaf(shape, seed):
    return pinned(shape, seed).requires_grad_(True)


def emit(name, t):
    t = t.detach().reshape(-1).tolist()
    body = ", ".join(repr(float(v)) for v in t)
    print(f"pub const {name}: &[f64] = &[{body}];")


def backprop(out):
    (out * pinned(tuple(out.shape), 99)).sum().backward()


# Linear: out = x W^T + b; x (5, 3), W (4, 3), b (4).
x, w, b = leaf((5, 3), 1), leaf((4, 3), 2), leaf((4,), 3)
out = F.linear(x, w, b)
backprop(out)
emit("LINEAR_OUT", out); emit("LINEAR_DX", x.grad); emit("LINEAR_DW", w.grad); emit("LINEAR_DB", b.grad)

# BatchNorm1d over rows, training step then evaluation; x (6, 3).
bn = torch.nn.BatchNorm1d(3)
with torch.no_grad():
    bn.weight.copy_(pinned((3,), 5)); bn.bias.copy_(pinned((3,), 6))
x = leaf((6, 3), 4)
out = bn(x)
backprop(out)
emit("BN_TRAIN_OUT", out); emit("BN_TRAIN_DX", x.grad); emit("BN_DWEIGHT", bn.weight.grad); emit("BN_DBIAS", bn.bias.grad)
emit("BN_RUNNING_MEAN", bn.running_mean); emit("BN_RUNNING_VAR", bn.running_var)
bn.eval()
x = leaf((6, 3), 4)
out = bn(x)
backprop(out)
emit("BN_EVAL_OUT", out); emit("BN_EVAL_DX", x.grad)


# The annotated transformer's LayerNorm: a (x - mean) / (std + eps) + b, unbiased std.
def annotated_layer_norm(x, a, b, eps=1e-6):
    mean = x.mean(-1, keepdim=True)
    std = x.std(-1, keepdim=True)
    return a * (x - mean) / (std + eps) + b


x, a, b = leaf((4, 5), 7), leaf((5,), 8), leaf((5,), 9)
out = annotated_layer_norm(x, a, b)
backprop(out)
emit("LN_OUT", out); emit("LN_DX", x.grad); emit("LN_DA", a.grad); emit("LN_DB", b.grad)

# Row softmax; x (3, 5) scaled by 3.
x = (3.0 * pinned((3, 5), 10)).requires_grad_(True)
out = torch.softmax(x, dim=1)
backprop(out)
emit("SOFTMAX_OUT", out); emit("SOFTMAX_DX", x.grad)

# L1 normalisation along dim 0 (columns sum to 1); column 1 is all zero.
x0 = pinned((4, 3), 11)
x0[:, 1] = 0.0
x = x0.clone().requires_grad_(True)
out = F.normalize(x, p=1, dim=0)
backprop(out)
emit("L1_OUT", out); emit("L1_DX", x.grad)


# The annotated transformer's multi-head attention (no mask, no dropout), H = 2, C = 4.
def attention(q_in, kv_in, ws, bs, h):
    nq, c = q_in.shape
    dk = c // h
    q, k, v = (F.linear(t, w, bb).view(-1, h, dk).transpose(0, 1) for t, w, bb in zip((q_in, kv_in, kv_in), ws[:3], bs[:3]))
    p = torch.softmax(q @ k.transpose(-2, -1) / math.sqrt(dk), dim=-1)
    o = (p @ v).transpose(0, 1).contiguous().view(nq, c)
    return F.linear(o, ws[3], bs[3])


q_in, kv_in = leaf((3, 4), 12), leaf((5, 4), 13)
ws = [leaf((4, 4), 20 + i) for i in range(4)]
bs = [leaf((4,), 30 + i) for i in range(4)]
out = attention(q_in, kv_in, ws, bs, 2)
backprop(out)
emit("MHA_OUT", out); emit("MHA_DQ", q_in.grad); emit("MHA_DKV", kv_in.grad)
emit("MHA_DWQ", ws[0].grad); emit("MHA_DWK", ws[1].grad); emit("MHA_DWV", ws[2].grad); emit("MHA_DWO", ws[3].grad)
emit("MHA_DBQ", bs[0].grad); emit("MHA_DBO", bs[3].grad)

# Max over the neighbour axis: (N*K, C) = (3*4, 2) viewed as (N, K, C).
x = leaf((12, 2), 14)
out, idx = x.view(3, 4, 2).max(dim=1)
backprop(out)
emit("MAXK_OUT", out); emit("MAXK_DX", x.grad)

# Optimiser trajectories: p = pinned((2, 3), 40), the gradient of step t is pinned((2, 3), 41 + t).
for name, make in [("SGD", lambda ps: torch.optim.SGD(ps, lr=0.1, momentum=0.9, weight_decay=0.01)),
                   ("ADAM", lambda ps: torch.optim.Adam(ps, lr=0.01, weight_decay=0.01))]:
    p = leaf((2, 3), 40)
    opt = make([p])
    for t in range(3):
        p.grad = pinned((2, 3), 41 + t)
        opt.step()
    emit(f"{name}_AFTER_3", p)

# Position-wise feed-forward: w_2(relu(w_1(x))); x (5, 4), F = 6.
x = leaf((5, 4), 50)
w1, b1, w2, b2 = leaf((6, 4), 51), leaf((6,), 52), leaf((4, 6), 53), leaf((4,), 54)
out = F.linear(torch.relu(F.linear(x, w1, b1)), w2, b2)
backprop(out)
emit("FF_OUT", out); emit("FF_DX", x.grad); emit("FF_DW1", w1.grad); emit("FF_DB1", b1.grad); emit("FF_DW2", w2.grad)

# DGCNN edge features as RGM's reference builds them: rows (x[idx[n, k]], x[n]); x (4, 3), K = 3,
# idx[n, k] = (n + 2k) % 4 (point itself first).
x = leaf((4, 3), 60)
idx = torch.tensor([[(n + 2 * k) % 4 for k in range(3)] for n in range(4)])
out = torch.cat([x[idx], x[:, None, :].expand(4, 3, 3)], dim=2).reshape(12, 6)
backprop(out)
emit("EDGE_OUT", out); emit("EDGE_DX", x.grad)

# Product with a transposed operand: a (9, 4) @ b(10, 4)^T.
a, b = leaf((9, 4), 70), leaf((10, 4), 71)
out = a @ b.t()
backprop(out)
emit("MATMUL_OUT", out); emit("MATMUL_DA", a.grad); emit("MATMUL_DB", b.grad)
