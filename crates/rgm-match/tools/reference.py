"""Pinned values for rgm-match's tests (pasted into src/reference.rs), computed from the spec's
formulas (RGM.md §2.4, §3) literally, in float64: the padded matrix is built and its rows and
columns normalised in place.

Run: python3 crates/rgm-match/tools/reference.py   (needs numpy)
"""
import numpy as np

np.set_printoptions(precision=17, floatmode="unique", linewidth=140)

# The 3×4 input used by the pinned tests.
S = np.array([[0.5, -1.0, 2.0, 0.0],
              [1.5, 0.25, -0.5, 1.0],
              [-2.0, 0.75, 0.3, -0.4]])


def logsumexp(x, axis):
    m = x.max(axis=axis, keepdims=True)
    return m + np.log(np.exp(x - m).sum(axis=axis, keepdims=True))


def sinkhorn(s, iterations=20, slack=True):
    """Spec §2.4: pad a zero (log 1) slack row and column, then `iterations` times normalise every
    real row over all columns and every real column over all rows; drop the slack, exponentiate."""
    n, m = s.shape
    p = np.pad(s, ((0, 1), (0, 1))) if slack else s.copy()
    for _ in range(iterations):
        p[:n, :] -= logsumexp(p[:n, :], axis=1)  # real rows, slack row untouched
        p[:, :m] -= logsumexp(p[:, :m], axis=0)  # real columns, slack column untouched
    return np.exp(p)


def inst_norm(x, gamma=1.0, beta=0.0, eps=1e-5):
    """InstanceNorm2d(1, affine=True) on the whole matrix: biased variance."""
    return gamma * (x - x.mean()) / np.sqrt(x.var() + eps) + beta


def bce(c, pairs):
    """BCELoss(reduction='sum') / N with PyTorch's log clamp at -100."""
    y = np.zeros_like(c)
    for i, j in pairs:
        y[i, j] = 1.0
    log = lambda v: np.maximum(np.log(v), -100.0)
    with np.errstate(divide="ignore"):
        return -(y * log(c) + (1 - y) * log(1 - c)).sum() / c.shape[0]


padded = sinkhorn(S)
print("sinkhorn with slack, C (3x4):\n", padded[:3, :4])
print("slack column (3):", padded[:3, 4])
print("slack row (4):", padded[3, :4])
print("sinkhorn without slack, C (3x4):\n", sinkhorn(S, slack=False))
print("inst_norm(S, gamma=1.5, beta=-0.25):\n", inst_norm(S, 1.5, -0.25))
print("bce(C with slack, pairs (0,2),(1,0),(2,1)):", bce(padded[:3, :4], [(0, 2), (1, 0), (2, 1)]))
