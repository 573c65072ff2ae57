#!/usr/bin/env python3
"""Trains the RGM network with PyTorch on a GPU (or the CPU), as `rgm train` does, in an rgm run
folder that `rgm train` resumes and `rgm register --weights` reads.

What it shares with `rgm train` (spec §1–3, crates/rgm-model/src/train):
* pairs: the protocol of `rgm_data::PairGenerator` — G = Rx(a)·Ry(b)·Rz(c) with a, b, c uniform
  in [0°, 45°] and t uniform in [−0.5, 0.5]³ applied to the source; the partial crop (each cloud
  its own direction uniform on the sphere, the points above the 30th percentile of the
  projections: 717 of 1,024); the jitter (σ 0.01 clipped at ±0.05); shuffling; the cut to
  `match_points` points per cloud; the ground truth rebuilt from distances in the reference
  order (`Correspondence::rebuild`). The draws are torch's, made on the device, so the pairs
  have the protocol's distribution, not `rgm train`'s exact draws;
* the network: tools/reference/rgm_reference.py (checked against rgm's model on the fixture),
  with batch norm on each cloud's own statistics, as `rgm train` runs it (a batch of one);
* the loss (BCE summed over C̃, divided by the source points, averaged over the batch), Adam as
  `rgm_nn::optim::Adam` (torch.optim.Adam), the step schedule of `MultiStepLr`;
* the run folder: config.json, state.json, log.jsonl, last.safetensors, last.optim.safetensors
  under the authors' parameter names, in rgm's formats (F32, BF16 and rgm's Log8 are read).

It needs torch only (no safetensors or numpy package): the GPU machine has nothing else.

    python3 tools/gpu/rgm_gpu_train.py train --pack PACK --run runs/NAME --minutes 8 [options]
    python3 tools/gpu/rgm_gpu_train.py bundle runs/NAME OUT/NAME     # the run as 2 files
    python3 tools/gpu/rgm_gpu_train.py unbundle OUT/NAME runs/NAME   # ... and back
    python3 tools/gpu/rgm_gpu_train.py step-fixture --out F.safetensors  # the CPU proof's data

docs/training/gpu.md says how a GPU window runs it.
"""
import argparse
import ctypes
import json
import math
import os
import struct
import sys
import tarfile
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "reference"))
import rgm_reference as ref  # noqa: E402

# Network presets, as `rgm_model::network::Config::preset` names them.
PRESETS = {
    "paper": dict(k=20, dgcnn=(64, 64, 128, 256), edge=512, q=512, heads=4, ff=1024, blocks=2, sinkhorn_iters=20),
    "small": dict(k=20, dgcnn=(32, 32, 64, 128), edge=256, q=256, heads=4, ff=512, blocks=2, sinkhorn_iters=20),
    "fast": dict(k=20, dgcnn=(16, 16, 32, 64), edge=128, q=128, heads=4, ff=256, blocks=2, sinkhorn_iters=20),
    "tiny": dict(k=4, dgcnn=(4, 4, 8, 8), edge=24, q=16, heads=4, ff=32, blocks=2, sinkhorn_iters=20),
}
MATCH_RADIUS, RESCUE_RADIUS = 0.05, 0.1  # rgm_data::correspondence


# ---------------------------------------------------------------------------------------------
# safetensors, read and written with torch alone (rgm_nn::io's dtypes, Log8 included)

_DTYPES = {"F32": torch.float32, "F64": torch.float64, "BF16": torch.bfloat16, "U8": torch.uint8,
           "I64": torch.int64, "I32": torch.int32}
_NAMES = {v: k for k, v in _DTYPES.items()}


def read_safetensors(path):
    """(tensors by name as float32 unless integer, metadata). Log8 tensors (rgm_nn::io::Storage)
    are decoded with the range their metadata gives."""
    with open(path, "rb") as f:
        data = f.read()
    (n,) = struct.unpack("<Q", data[:8])
    header = json.loads(data[8:8 + n])
    meta = header.pop("__metadata__", None) or {}
    body = memoryview(data)[8 + n:]
    out = {}
    for name, info in header.items():
        start, end = info["data_offsets"]
        if info["dtype"] == "U32":  # torch has no uint32 arithmetic everywhere: widen
            t = torch.frombuffer(bytearray(body[start:end]), dtype=torch.int32).to(torch.int64) & 0xFFFFFFFF
        else:
            t = torch.frombuffer(bytearray(body[start:end]), dtype=_DTYPES[info["dtype"]]) if end > start \
                else torch.empty(0, dtype=_DTYPES[info["dtype"]])
        t = t.reshape(info["shape"])
        key = f"log8:{name}"
        if key in meta:
            lo, hi = (float(v) for v in meta[key].split())  # "lo hi", log2 of the range
            codes = t.to(torch.float64)
            t = torch.where(codes == 0, torch.zeros_like(codes), torch.exp2(lo + (codes - 1) / 254.0 * (hi - lo)))
        if t.dtype.is_floating_point:
            t = t.to(torch.float32)
        out[name] = t
    return out, meta


def write_safetensors(path, tensors, metadata=None, dtype=torch.float32):
    """Writes `tensors` (name → tensor) as `dtype` (integer tensors as they are), sorted by name,
    through a temporary file and a rename."""
    header, chunks, offset = {}, [], 0
    for name in sorted(tensors):
        t = tensors[name].detach().cpu().contiguous()
        if t.dtype.is_floating_point:
            t = t.to(dtype)
        raw = ctypes.string_at(t.data_ptr(), t.numel() * t.element_size())  # no numpy needed
        header[name] = {"dtype": _NAMES[t.dtype], "shape": list(t.shape), "data_offsets": [offset, offset + len(raw)]}
        chunks.append(raw)
        offset += len(raw)
    if metadata:
        header["__metadata__"] = {k: str(v) for k, v in metadata.items()}
    blob = json.dumps(header, separators=(",", ":")).encode()
    blob += b" " * (-len(blob) % 8)
    tmp = f"{path}.tmp"
    with open(tmp, "wb") as f:
        f.write(struct.pack("<Q", len(blob)))
        f.write(blob)
        for c in chunks:
            f.write(c)
    os.replace(tmp, path)


# ---------------------------------------------------------------------------------------------
# The data pack (`cargo xtask pack-modelnet`, docs/training/gpu.md)

def load_pack(path, device, unseen):
    """The training shapes as float32 (S, P, 3) on `device`, and their labels (S,): decoded as
    the pack's metadata `decode` says; labels 0–19 only for the unseen-categories setting."""
    tensors, meta = read_safetensors(path)
    if meta.get("format") != "rgm-modelnet-pack":
        raise SystemExit(f"{path}: not an rgm ModelNet pack (format {meta.get('format')!r})")
    words = tensors["points"].to(device)  # (S, P) int64 holding u32
    lo = tensors["lo"].to(device)  # (S, 3)
    extent = tensors["extent"].to(device)  # (S, 3)
    label = tensors["label"].to(torch.int64).to(device)  # (S,)
    bits = [int(b) for b in meta.get("bits", "11,11,10").split(",")]
    shift, coords = 0, []
    for axis, b in enumerate(bits):
        q = ((words >> shift) & ((1 << b) - 1)).to(torch.float32)  # (S, P)
        # extent × float32(1/(2^b − 1)), as the pack's `decode` says: the same bits on every device
        step = extent[:, axis:axis + 1] * (1.0 / float((1 << b) - 1))  # (S, 1)
        coords.append(lo[:, axis:axis + 1] + q * step)
        shift += b
    points = torch.stack(coords, dim=-1)  # (S, P, 3)
    if unseen:
        keep = label < 20
        points, label = points[keep], label[keep]
    return points, label


# ---------------------------------------------------------------------------------------------
# Pairs (spec §1, rgm_data::pairs), a batch at a time

def rotation_xyz(a, b, c):
    """Rx(a)·Ry(b)·Rz(c) for angle tensors (B,) → (B, 3, 3)."""
    o, i = torch.zeros_like(a), torch.ones_like(a)
    rx = torch.stack([i, o, o, o, a.cos(), -a.sin(), o, a.sin(), a.cos()], -1).view(-1, 3, 3)
    ry = torch.stack([b.cos(), o, b.sin(), o, i, o, -b.sin(), o, b.cos()], -1).view(-1, 3, 3)
    rz = torch.stack([c.cos(), -c.sin(), o, c.sin(), c.cos(), o, o, o, i], -1).view(-1, 3, 3)
    return rx @ ry @ rz


def crop_keep_count(n, keep_ratio=0.7):
    """Points `crop_indices` keeps of n distinct projections: those above the interpolated
    percentile at rank r = (1 − keep)(n − 1), i.e. n − ⌊r⌋ − 1 (717 of 1,024)."""
    return n - int(math.floor((1.0 - keep_ratio) * (n - 1))) - 1


def random_directions(b, gen, like):
    """(B, 3) uniform on the sphere, drawn as RPM-Net's uniform_2_sphere."""
    phi = torch.rand(b, generator=gen, device=like.device, dtype=like.dtype) * (2 * math.pi)
    cos_t = torch.rand(b, generator=gen, device=like.device, dtype=like.dtype) * 2 - 1
    sin_t = (1 - cos_t * cos_t).clamp_min(0).sqrt()
    return torch.stack([sin_t * phi.cos(), sin_t * phi.sin(), cos_t], -1)


def crop(points, gen):
    """Each cloud (B, N, 3) cut to the points above the 30th percentile of its projections onto
    its own random direction, in their original order."""
    b, n, _ = points.shape
    d = random_directions(b, gen, points)  # (B, 3)
    proj = ((points - points.mean(1, keepdim=True)) * d[:, None, :]).sum(-1)  # (B, N)
    kept = proj.topk(crop_keep_count(n), dim=1).indices.sort(dim=1).values  # (B, N')
    return torch.gather(points, 1, kept[..., None].expand(-1, -1, 3))


def jitter(points, gen, std=0.01, clip=0.05):
    return points + (torch.randn(points.shape, generator=gen, device=points.device, dtype=points.dtype) * std).clamp(-clip, clip)


def random_subset(points, count, gen):
    """`count` of each cloud's points (all when it has no more), in random order."""
    b, n, _ = points.shape
    order = torch.rand(b, n, generator=gen, device=points.device).argsort(dim=1)[:, :min(count, n)]
    return torch.gather(points, 1, order[..., None].expand(-1, -1, 3))


def rebuild_correspondence(xm, y):
    """Ground truth (B, N, M) 0/1 from X' (the moved source) and Y, as
    `Correspondence::rebuild`: (1) mutual nearest neighbours closer than 0.05; (2) each free
    source point whose nearest target is free and closer than 0.05, lowest source index first,
    then the same from the target side; (3) mutual nearest neighbours among the points still
    free, closer than 0.1."""
    b, n, _ = xm.shape
    m = y.shape[1]
    d = torch.cdist(xm.double(), y.double())  # (B, N, M)
    sd, sj = d.min(2)  # (B, N): each source's nearest target
    td, ti = d.min(1)  # (B, M): each target's nearest source
    ar_n = torch.arange(n, device=xm.device).expand(b, n)
    ar_m = torch.arange(m, device=xm.device).expand(b, m)
    mutual = (torch.gather(ti, 1, sj) == ar_n) & (sd < MATCH_RADIUS)  # (B, N)
    target_of = torch.where(mutual, sj, torch.full_like(sj, -1))  # (B, N), −1: free
    source_of = _assign_from(target_of, m)  # (B, M), −1: free
    # Step 2, source side: the lowest free source whose nearest target is free wins it.
    cand = (target_of < 0) & (torch.gather(source_of, 1, sj) < 0) & (sd < MATCH_RADIUS)  # (B, N)
    winner = torch.full((b, m), n, dtype=torch.int64, device=xm.device)
    winner.scatter_reduce_(1, sj, torch.where(cand, ar_n, n), reduce="amin")  # (B, M)
    won = cand & (torch.gather(winner, 1, sj) == ar_n)
    target_of = torch.where(won, sj, target_of)
    source_of = _assign_from(target_of, m)
    # Step 2, target side.
    source_free = target_of < 0  # (B, N)
    cand_t = (source_of < 0) & torch.gather(source_free, 1, ti) & (td < MATCH_RADIUS)  # (B, M)
    winner_t = torch.full((b, n), m, dtype=torch.int64, device=xm.device)
    winner_t.scatter_reduce_(1, ti, torch.where(cand_t, ar_m, m), reduce="amin")  # (B, N)
    won_t = cand_t & (torch.gather(winner_t, 1, ti) == ar_m)
    source_of = torch.where(won_t, ti, source_of)
    target_of = _assign_from(source_of, n)
    # Step 3: mutual nearest neighbours among the free points.
    free = (target_of < 0)[:, :, None] & (source_of < 0)[:, None, :]  # (B, N, M)
    dr = torch.where(free, d, torch.full_like(d, float("inf")))
    rsd, rsj = dr.min(2)
    _, rti = dr.min(1)
    rescued = (target_of < 0) & (torch.gather(rti, 1, rsj) == ar_n) & (rsd < RESCUE_RADIUS)
    target_of = torch.where(rescued, rsj, target_of)
    gt = torch.zeros(b, n, m + 1, dtype=xm.dtype, device=xm.device)
    gt.scatter_(2, torch.where(target_of < 0, m, target_of)[..., None], 1.0)
    return gt[:, :, :m]


def _assign_from(partner, size):
    """The inverse of a partial one-to-one map (B, L) → (B, size), −1 where unassigned."""
    b, length = partner.shape
    inv = torch.full((b, size + 1), -1, dtype=torch.int64, device=partner.device)
    idx = torch.where(partner < 0, size, partner)
    inv.scatter_(1, idx, torch.arange(length, device=partner.device).expand(b, length).clone())
    return inv[:, :size]


def make_batch(shapes, setting, match_points, gen, info=None):
    """Source (B, N, 3), target (B, M, 3) and ground truth (B, N, M) of `shapes` (B, P, 3).
    With a dict `info`, also the statistics `pair-stats` compares with rgm-data's."""
    b = shapes.shape[0]
    dev = shapes.device
    dt = shapes.dtype
    angles = torch.rand(b, 3, generator=gen, device=dev, dtype=dt) * math.radians(45.0)
    rot = rotation_xyz(angles[:, 0], angles[:, 1], angles[:, 2])  # (B, 3, 3)
    trans = torch.rand(b, 3, generator=gen, device=dev, dtype=dt) - 0.5  # (B, 3)
    source = shapes @ rot.transpose(1, 2) + trans[:, None, :]
    target = shapes
    exact = setting == "clean" and match_points is None
    if setting == "partial":
        source, target = crop(source, gen), crop(target, gen)
    if setting != "clean":
        source, target = jitter(source, gen), jitter(target, gen)
    if info is not None:
        trace = rot.diagonal(dim1=1, dim2=2).sum(-1)
        info.update(source_points=torch.full((b,), float(source.shape[1])),
                    target_points=torch.full((b,), float(target.shape[1])),
                    rotation_deg=torch.rad2deg(((trace - 1) / 2).clamp(-1, 1).acos()),
                    translation=trans.norm(dim=-1))
    if exact:  # an exact permutation: the ground truth of the origins
        ps = torch.rand(b, source.shape[1], generator=gen, device=dev).argsort(1)
        pt = torch.rand(b, target.shape[1], generator=gen, device=dev).argsort(1)
        source = torch.gather(source, 1, ps[..., None].expand(-1, -1, 3))
        target = torch.gather(target, 1, pt[..., None].expand(-1, -1, 3))
        gt = (ps[:, :, None] == pt[:, None, :]).to(shapes.dtype)
        if info is not None:
            info["matched"] = info["matched_cut"] = gt.sum((1, 2))
        return source, target, gt
    if info is not None:
        moved_all = (source - trans[:, None, :]) @ rot
        info["matched"] = rebuild_correspondence(moved_all, target).sum((1, 2))
    count = match_points or max(source.shape[1], target.shape[1])
    source, target = random_subset(source, count, gen), random_subset(target, count, gen)
    # X' = G⁻¹ X: the source moved back onto the target.
    moved = (source - trans[:, None, :]) @ rot
    gt = rebuild_correspondence(moved, target)
    if info is not None:
        info["matched_cut"] = gt.sum((1, 2))
    return source, target, gt


# ---------------------------------------------------------------------------------------------
# The network: the reference with batch norm on each cloud's own statistics

class CloudBatchNorm(nn.BatchNorm2d):
    """BatchNorm2d whose training statistics are each cloud's own (over points × neighbours),
    as `rgm train` normalises a batch of one; the running statistics move by the batch's mean of
    the clouds' statistics (rgm averages its workers' instead)."""

    def forward(self, x):  # (B, C, N, K)
        if not self.training:
            return super().forward(x)
        mean = x.mean(dim=(2, 3), keepdim=True)  # (B, C, 1, 1)
        var = x.var(dim=(2, 3), unbiased=False, keepdim=True)
        with torch.no_grad():
            count = x.shape[2] * x.shape[3]
            self.running_mean.mul_(1 - self.momentum).add_(self.momentum * mean.mean(0).flatten())
            unbiased = var.mean(0).flatten() * count / max(count - 1, 1)
            self.running_var.mul_(1 - self.momentum).add_(self.momentum * unbiased)
        y = (x - mean) * torch.rsqrt(var + self.eps)
        return y * self.weight[None, :, None, None] + self.bias[None, :, None, None]


def build_network(preset):
    model = ref.RGM(**PRESETS[preset])
    feat = model.pointfeaturer
    for i in range(1, 6):
        old = getattr(feat, f"bn{i}")
        setattr(feat, f"bn{i}", CloudBatchNorm(old.num_features))
    return model


def rgm_order(model):
    """Parameter names in the order rgm visits them (its optimiser files list them so):
    the featurer, then per block its edge generator, graph conv, affinity, instance norm, and the
    cross-graph conv after block 0."""
    names = [n for n, _ in model.named_parameters()]
    groups = ["pointfeaturer."]
    blocks = model.blocks
    for b in range(blocks):
        groups += [f"gmattend{b}.", f"gnn_layer_{b}.", f"affinity_{b}.", f"InstNorm_layer_{b}."]
        if b == 0 and blocks > 1:
            groups.append("cross_graph_0.")
    return [n for g in groups for n in names if n.startswith(g)]


def load_weights(model, path):
    tensors, _ = read_safetensors(path)
    state = model.state_dict()
    missing = [k for k in state if k not in tensors and not k.endswith("num_batches_tracked")]
    if missing:
        raise SystemExit(f"{path}: missing {missing[:3]} (another network size?)")
    with torch.no_grad():
        for k, v in state.items():
            if k in tensors:
                v.copy_(tensors[k].reshape(v.shape))


def rgm_shaped(t):
    """rgm's shape of a parameter: 1×1 convolution weights as matrices."""
    return t.reshape(t.shape[0], t.shape[1]) if t.dim() == 4 else t


def save_weights(model, path):
    tensors = {k: rgm_shaped(v) for k, v in model.state_dict().items() if v.dtype.is_floating_point}
    write_safetensors(path, tensors)


def bce_loss(c_soft, gt):
    """Spec §3: BCE summed over N·M (each log clamped at −100), divided by N, batch mean."""
    return F.binary_cross_entropy(c_soft, gt, reduction="sum") / (c_soft.shape[0] * c_soft.shape[1])


# ---------------------------------------------------------------------------------------------
# The run folder (crates/rgm-model/src/train)

def multistep_lr(base, milestones, gamma, epoch):
    return base * gamma ** sum(1 for m in milestones if epoch >= m)


def load_optimizer(opt, model, path, device):
    """Adam state from rgm's file: `m.NAME` (may be missing: zeros), `v.NAME`, `step`."""
    tensors, meta = read_safetensors(path)
    if meta.get("optimizer") != "adam":
        raise SystemExit(f"{path}: optimiser {meta.get('optimizer')!r}; this trainer runs Adam")
    step = int(meta["step"])
    params = dict(model.named_parameters())
    for name in meta["order"].split("\n"):
        p = params[name]
        v = tensors[f"v.{name}"].reshape(p.shape).to(device)
        m = tensors.get(f"m.{name}")
        m = torch.zeros_like(p) if m is None else m.reshape(p.shape).to(device)
        # Fused Adam keeps its step count on the parameters' device.
        opt.state[p] = {"step": torch.tensor(float(step), device=device), "exp_avg": m.clone(), "exp_avg_sq": v.clone()}
    return step


def save_optimizer(opt, model, path, lr, weight_decay, step):
    params = dict(model.named_parameters())
    tensors = {}
    order = rgm_order(model)
    for name in order:
        st = opt.state.get(params[name])
        z = torch.zeros_like(params[name])
        tensors[f"m.{name}"] = rgm_shaped(st["exp_avg"] if st else z)
        tensors[f"v.{name}"] = rgm_shaped(st["exp_avg_sq"] if st else z)
    meta = {"optimizer": "adam", "lr": repr(lr), "beta1": "0.9", "beta2": "0.999", "eps": "0.00000001",
            "weight_decay": repr(weight_decay), "step": str(step), "order": "\n".join(order)}
    write_safetensors(path, tensors, meta)


def new_config(args):
    return {
        "setting": args.setting, "unseen": args.unseen,
        "network": {**{k: list(v) if isinstance(v, tuple) else v for k, v in PRESETS[args.preset].items()},
                    "scoring": "Ais", "edges": "Transformer"},
        "match_points": args.match_points or None, "epochs": args.epochs, "batch": args.batch, "optimizer": "adam",
        "lr": args.lr, "momentum": 0.9, "weight_decay": args.weight_decay, "milestones": args.milestones,
        "gamma": args.gamma, "train_shapes": args.train_shapes, "val_shapes": args.val_shapes, "val_sample": "spread", "workers": 2,
        "checkpoint_every": 50, "seed": args.seed, "test_statistics": "cloud", "precision": "f32",
        **({"init": args.init} if args.init else {}),
    }


def preset_of(network):
    for name, p in PRESETS.items():
        if all(list(v) == network[k] if isinstance(v, tuple) else v == network[k] for k, v in p.items()):
            return name
    raise SystemExit(f"no preset has the sizes {network}")


def write_json(path, value):
    tmp = f"{path}.tmp"
    with open(tmp, "w") as f:
        json.dump(value, f, indent=2)
    os.replace(tmp, path)


class Run:
    """An rgm run folder: its config, state and log, and the network and Adam it holds."""

    def __init__(self, folder, args, device):
        self.folder = folder
        os.makedirs(folder, exist_ok=True)
        state_path = os.path.join(folder, "state.json")
        if os.path.exists(state_path):
            self.config = json.load(open(os.path.join(folder, "config.json")))
            self.state = json.load(open(state_path))
            log_path = os.path.join(folder, "log.jsonl")
            log = open(log_path, "rb").read() if os.path.exists(log_path) else b""
            self.log = log[: self.state.get("log_bytes") or len(log)]
            resumed = True
        else:
            self.config = new_config(args)
            self.state = {"epoch": 0, "batch": 0, "steps": 0, "pairs_seen": 0, "seconds": 0.0, "best": None,
                          "log_bytes": 0}
            self.log = b""
            resumed = False
        if self.config["optimizer"] != "adam" or self.config["network"].get("edges", "Transformer") != "Transformer" \
                or self.config["network"].get("scoring", "Ais") != "Ais":
            raise SystemExit(f"{folder}: this trainer runs Adam on the full network only")
        self.model = build_network(preset_of(self.config["network"])).to(device)
        weights = os.path.join(folder, "last.safetensors") if resumed else self.config.get("init")
        if weights:
            load_weights(self.model, weights)
        self.opt = torch.optim.Adam(self.model.parameters(), lr=self.config["lr"],
                                    weight_decay=self.config["weight_decay"], fused=True)
        optim = os.path.join(folder, "last.optim.safetensors")
        self.step = load_optimizer(self.opt, self.model, optim, device) if resumed and os.path.exists(optim) else 0

    def lr(self, epoch):
        c = self.config
        return multistep_lr(c["lr"], c["milestones"], c["gamma"], epoch)

    def append_log(self, record):
        self.log += (json.dumps(record) + "\n").encode()

    def save(self, out):
        """The run as rgm writes it, into the folder `out` (files replaced one by one)."""
        os.makedirs(out, exist_ok=True)
        save_weights(self.model, os.path.join(out, "last.safetensors"))
        save_optimizer(self.opt, self.model, os.path.join(out, "last.optim.safetensors"),
                       self.lr(self.state["epoch"]), self.config["weight_decay"], self.step)
        with open(os.path.join(out, "log.jsonl.tmp"), "wb") as f:
            f.write(self.log)
        os.replace(os.path.join(out, "log.jsonl.tmp"), os.path.join(out, "log.jsonl"))
        self.state["log_bytes"] = len(self.log)
        write_json(os.path.join(out, "config.json"), self.config)
        write_json(os.path.join(out, "state.json"), self.state)


# ---------------------------------------------------------------------------------------------
# Training

def train(args):
    device = torch.device(args.device)
    torch.backends.cuda.matmul.allow_tf32 = args.tf32
    torch.backends.cudnn.allow_tf32 = args.tf32
    run = Run(args.run, args, device)
    cfg = run.config
    shapes, _ = load_pack(args.pack, device, cfg["unseen"])
    if cfg.get("train_shapes"):
        shapes = shapes[:cfg["train_shapes"]]
    n_shapes = shapes.shape[0]
    batch = cfg["batch"]
    batches = -(-n_shapes // batch)
    out = args.out or args.run
    model = run.model.train()
    step_fn = model
    if args.compile:
        step_fn = torch.compile(model)
    start = time.time()
    last_save = start
    pairs_before = run.state["pairs_seen"]
    since = torch.zeros((), device=device)  # loss summed since the last log line
    time_milestones = list(args.milestones_by_time or [])
    print(f"{args.run}: {cfg['setting']}{' unseen' if cfg['unseen'] else ''}, {preset_of(cfg['network'])} at "
          f"{cfg['match_points']} points, batch {batch}, {n_shapes} shapes, epoch {run.state['epoch']} batch "
          f"{run.state['batch']}, on {device}", flush=True)
    done = False
    while not done and run.state["epoch"] < cfg["epochs"]:
        epoch = run.state["epoch"]
        elapsed = (time.time() - start) / 60
        while time_milestones and elapsed >= time_milestones[0] * args.minutes:
            time_milestones.pop(0)
            if epoch not in cfg["milestones"] and run.state["batch"] == 0:
                cfg["milestones"] = sorted(cfg["milestones"] + [epoch])
        lr = run.lr(epoch)
        for g in run.opt.param_groups:
            g["lr"] = lr
        order_gen = torch.Generator(device="cpu").manual_seed(cfg["seed"] * 1_000_003 + epoch)
        order = torch.randperm(n_shapes, generator=order_gen).to(device)
        clock = time.time()
        logged_batch = run.state["batch"]
        while run.state["batch"] < batches:
            b = run.state["batch"]
            idx = order[b * batch:(b + 1) * batch]
            gen = torch.Generator(device=device).manual_seed((cfg["seed"] << 40) ^ (epoch << 20) ^ b)
            with torch.no_grad():
                x, y, gt = make_batch(shapes[idx], cfg["setting"], cfg["match_points"], gen)
            c_soft = step_fn(x, y)
            loss = bce_loss(c_soft, gt)
            run.opt.zero_grad(set_to_none=True)
            loss.backward()
            run.opt.step()
            run.step += 1
            run.state["batch"] += 1
            run.state["steps"] += 1
            run.state["pairs_seen"] += idx.numel()
            since += loss.detach()
            now = time.time()
            out_of_time = now - start >= args.minutes * 60
            if run.state["batch"] % 50 == 0 or run.state["batch"] == batches or out_of_time:
                run.state["seconds"] += now - clock
                clock = now
                run.append_log({"kind": "train", "epoch": epoch, "batch": run.state["batch"], "batches": batches,
                                "pairs_seen": run.state["pairs_seen"], "lr": lr,
                                "loss": since.item() / (run.state["batch"] - logged_batch), "seconds": run.state["seconds"]})
                since.zero_()
                logged_batch = run.state["batch"]
            if out_of_time:
                done = True
                break
            if now - last_save >= args.checkpoint_seconds:
                save_and_bundle(run, out, args)
                last_save = time.time()
                print(f"{args.run}: epoch {epoch} batch {run.state['batch']}/{batches} loss {loss.item():.4f} lr {lr:.2e} "
                      f"({(now - start) / 60:.1f} min, {(run.state['pairs_seen'] - pairs_before) / (now - start):.0f} "
                      f"pairs/s)", flush=True)
        if run.state["batch"] >= batches:
            run.state["epoch"] += 1
            run.state["batch"] = 0
    save_and_bundle(run, out, args)
    took = time.time() - start
    print(f"{args.run}: stopped at epoch {run.state['epoch']} batch {run.state['batch']}, "
          f"{run.state['pairs_seen']} pairs seen ({run.state['pairs_seen'] - pairs_before} in {took:.0f} s, "
          f"{(run.state['pairs_seen'] - pairs_before) / took:.0f} pairs/s); milestones {cfg['milestones']}", flush=True)


def save_and_bundle(run, out, args):
    run.save(out)
    if args.bundle:
        bundle(out, args.bundle)


# ---------------------------------------------------------------------------------------------
# Two files per run, for a machine that returns a few files only

SMALL_FILES = ["config.json", "state.json", "log.jsonl", "last.safetensors"]


def bundle(folder, stem):
    """`stem.tar` (config, state, log, weights) and `stem.optim.safetensors`, each replaced
    atomically."""
    tmp = f"{stem}.tar.tmp"
    with tarfile.open(tmp, "w") as tar:
        for name in SMALL_FILES:
            tar.add(os.path.join(folder, name), arcname=name)
    os.replace(tmp, f"{stem}.tar")
    with open(os.path.join(folder, "last.optim.safetensors"), "rb") as src, open(f"{stem}.optim.tmp", "wb") as dst:
        dst.write(src.read())
    os.replace(f"{stem}.optim.tmp", f"{stem}.optim.safetensors")


def unbundle(stem, folder):
    os.makedirs(folder, exist_ok=True)
    with tarfile.open(f"{stem}.tar") as tar:
        for name in SMALL_FILES:
            data = tar.extractfile(name).read()
            with open(os.path.join(folder, name), "wb") as f:
                f.write(data)
    with open(f"{stem}.optim.safetensors", "rb") as src, open(os.path.join(folder, "last.optim.safetensors"), "wb") as dst:
        dst.write(src.read())
    print(f"{folder}: unbundled from {stem}.tar and {stem}.optim.safetensors")


# ---------------------------------------------------------------------------------------------
# The CPU proof's data: one batched step in f64, for rgm's test to repeat pair by pair

def step_fixture(out, seed=3, pairs=4, points=40, match_points=24):
    """Four partial pairs made by `make_batch` from random shapes, and the tiny network's loss and
    gradients over the batch (per-cloud batch norm). (Adam's step is pinned against PyTorch in
    rgm_nn::pytorch_pinned.)"""
    torch.manual_seed(seed)
    model = build_network("tiny").double().train()
    shapes = F.normalize(torch.randn(pairs, points, 3, dtype=torch.float64), dim=-1) * \
        torch.rand(pairs, points, 1, dtype=torch.float64).pow(1 / 3)
    gen = torch.Generator().manual_seed(seed)
    x, y, gt = make_batch(shapes, "partial", match_points, gen)
    before = {k: v.detach().clone() for k, v in model.state_dict().items()}
    c_soft = model(x, y)
    loss = bce_loss(c_soft, gt)
    loss.backward()
    grads = {n: p.grad.detach().clone() for n, p in model.named_parameters()}
    tensors = {"output.loss": loss.detach().reshape(1)}
    for i in range(pairs):
        tensors[f"input.x.{i}"] = x[i]
        tensors[f"input.y.{i}"] = y[i]
        tensors[f"input.gt.{i}"] = gt[i]
    for name, v in before.items():
        if v.dtype.is_floating_point:
            tensors[f"param.{name}"] = rgm_shaped(v)
    for name, g in grads.items():
        tensors[f"grad.{name}"] = rgm_shaped(g)
    write_safetensors(out, tensors, {"format": "rgm-gpu-step", "pairs": str(pairs),
                                     "config": json.dumps(PRESETS["tiny"]), "torch": torch.__version__},
                      dtype=torch.float64)
    print(f"wrote {out}: loss {loss.item():.12f}, {int(gt.sum())} correspondences in {pairs} pairs")


def rebuild_line_by_line(xm, y):
    """`Correspondence::rebuild` as rgm-data writes it, one point at a time (one pair): what the
    batched `rebuild_correspondence` is checked against."""
    d = torch.cdist(xm.double(), y.double())
    n, m = d.shape
    sd, sj = d.min(1)
    td, ti = d.min(0)
    to, so = [None] * n, [None] * m
    for i in range(n):
        j = int(sj[i])
        if int(ti[j]) == i and sd[i] < MATCH_RADIUS:
            to[i], so[j] = j, i
    for i in range(n):
        j = int(sj[i])
        if to[i] is None and so[j] is None and sd[i] < MATCH_RADIUS:
            to[i], so[j] = j, i
    for j in range(m):
        i = int(ti[j])
        if so[j] is None and to[i] is None and td[j] < MATCH_RADIUS:
            to[i], so[j] = j, i
    rest_s = [i for i in range(n) if to[i] is None]
    rest_t = [j for j in range(m) if so[j] is None]
    if rest_s and rest_t:
        dd = d[rest_s][:, rest_t]
        ad, ab = dd.min(1)
        _, ba = dd.min(0)
        for a in range(len(rest_s)):
            b = int(ab[a])
            if int(ba[b]) == a and ad[a] < RESCUE_RADIUS:
                to[rest_s[a]] = rest_t[b]
    gt = torch.zeros(n, m, dtype=torch.float64)
    for i, j in enumerate(to):
        if j is not None:
            gt[i, j] = 1.0
    return gt


def check_rebuild(trials=30, seed=0):
    """The batched rebuild against the line-by-line one on random clouds dense enough (60 and 50
    points in a 0.4 cube) that every step matches some points."""
    gen = torch.Generator().manual_seed(seed)
    wrong = 0
    for _ in range(trials):
        x = torch.rand(3, 60, 3, generator=gen, dtype=torch.float64) * 0.4
        y = torch.rand(3, 50, 3, generator=gen, dtype=torch.float64) * 0.4
        gt = rebuild_correspondence(x, y)
        wrong += sum(not torch.equal(gt[b], rebuild_line_by_line(x[b], y[b])) for b in range(3))
    print(f"rebuild: {3 * trials - wrong} of {3 * trials} random pairs equal to the line-by-line rebuild")
    return wrong == 0


STAT_NAMES = ["source_points", "target_points", "matched", "matched_cut", "rotation_deg", "translation"]


def pair_stats(pack, setting, count, match_points, rust_json=None, seed=0):
    """Mean and standard deviation of each statistic over `count` pairs of the first training
    shapes; with `rust_json` (the output of rgm-data's `pair_stats` example on the same shapes),
    each mean compared: they must agree within 4 standard errors of the difference."""
    shapes, _ = load_pack(pack, "cpu", False)
    shapes = shapes[:count].double()
    gen = torch.Generator().manual_seed(seed)
    parts = {}
    for start in range(0, shapes.shape[0], 256):
        info = {}
        make_batch(shapes[start:start + 256], setting, match_points, gen, info)
        for k, v in info.items():
            parts.setdefault(k, []).append(v.double().cpu())
    mine = {"pairs": shapes.shape[0]}
    for k in STAT_NAMES:
        v = torch.cat(parts[k])
        mine[k] = [v.mean().item(), v.std().item() if v.numel() > 1 else 0.0]
    print(json.dumps(mine))
    if rust_json is None:
        return True
    theirs = json.load(open(rust_json))
    ok = True
    print(f"{'statistic':<15}{'GPU trainer':>22}{'rgm-data':>22}{'|diff| / se':>13}")
    for k in STAT_NAMES:
        (m1, s1), (m2, s2) = mine[k], theirs[k]
        se = math.sqrt(s1 ** 2 / mine["pairs"] + s2 ** 2 / theirs["pairs"])
        z = abs(m1 - m2) / se if se > 0 else (0.0 if m1 == m2 else math.inf)
        ok &= z < 4
        print(f"{k:<15}{m1:>14.4f} ± {s1:<6.3f}{m2:>14.4f} ± {s2:<6.3f}{z:>13.2f}")
    print("pairs: same statistics" if ok else "pairs: DIFFERENT statistics")
    return ok


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="train (or resume) the run in --run for --minutes")
    t.add_argument("--pack", required=True, help="the data pack (cargo xtask pack-modelnet)")
    t.add_argument("--run", required=True, help="run folder: resumed when it holds state.json")
    t.add_argument("--out", help="where checkpoints go (default: --run)")
    t.add_argument("--bundle", help="also write each checkpoint as BUNDLE.tar + BUNDLE.optim.safetensors")
    t.add_argument("--minutes", type=float, required=True, help="wall time to train, then checkpoint and stop")
    t.add_argument("--checkpoint-seconds", type=float, default=60.0)
    t.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    t.add_argument("--compile", action="store_true", help="torch.compile the network")
    t.add_argument("--tf32", action="store_true", help="TF32 matrix products on the GPU")
    t.add_argument("--milestones-by-time", type=lambda s: [float(v) for v in s.split(",")],
                   help="fractions of --minutes after which the next epoch starts a new milestone (×gamma)")
    # A new run's settings (as `rgm train`'s options); a resumed run keeps its own.
    t.add_argument("--setting", choices=["clean", "noise", "partial"], default="partial")
    t.add_argument("--unseen", action="store_true")
    t.add_argument("--preset", choices=sorted(PRESETS), default="fast")
    t.add_argument("--match-points", type=int, default=384, help="cut each cloud to N points (0: whole clouds)")
    t.add_argument("--batch", type=int, default=32)
    t.add_argument("--lr", type=float, default=3e-4)
    t.add_argument("--weight-decay", type=float, default=0.0)
    t.add_argument("--epochs", type=int, default=200)
    t.add_argument("--milestones", type=lambda s: [int(v) for v in s.split(",") if v], default=[])
    t.add_argument("--gamma", type=float, default=0.2)
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--train-shapes", type=int, help="only the first N training shapes (as rgm train's option)")
    t.add_argument("--val-shapes", type=int, default=300, help="recorded for rgm train, which validates")
    t.add_argument("--init", help="weights a new run starts from")
    b = sub.add_parser("bundle", help="a run folder as STEM.tar + STEM.optim.safetensors")
    b.add_argument("folder")
    b.add_argument("stem")
    u = sub.add_parser("unbundle", help="STEM.tar + STEM.optim.safetensors back into a run folder")
    u.add_argument("stem")
    u.add_argument("folder")
    s = sub.add_parser("step-fixture", help="write the batched-step fixture rgm's test compares against")
    s.add_argument("--out", required=True)
    sub.add_parser("check-rebuild", help="the batched ground-truth rebuild against a line-by-line port of rgm-data's")
    st = sub.add_parser("pair-stats", help="statistics of training pairs, compared with rgm-data's (pair_stats example)")
    st.add_argument("--pack", required=True)
    st.add_argument("--setting", choices=["clean", "noise", "partial"], default="partial")
    st.add_argument("--pairs", type=int, default=2000)
    st.add_argument("--match-points", type=int)
    st.add_argument("--compare", help="the JSON that `cargo run -p rgm-data --example pair_stats` printed")
    a = p.parse_args()
    if a.cmd == "train":
        train(a)
    elif a.cmd == "bundle":
        bundle(a.folder, a.stem)
    elif a.cmd == "unbundle":
        unbundle(a.stem, a.folder)
    elif a.cmd == "check-rebuild":
        sys.exit(0 if check_rebuild() else 1)
    elif a.cmd == "pair-stats":
        sys.exit(0 if pair_stats(a.pack, a.setting, a.pairs, a.match_points, a.compare) else 1)
    else:
        step_fixture(a.out)


if __name__ == "__main__":
    main()
