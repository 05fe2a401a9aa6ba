"""``meta/stats.json`` and the ``stats/...`` columns of the episodes' metadata, as lerobot computes them
(huggingface/lerobot ``src/lerobot/datasets/compute_stats.py``).

Per episode and feature: ``min``, ``max``, ``mean``, ``std`` (population), ``count`` (frames, shape (1,)) and
the quantiles ``q01``, ``q10``, ``q50``, ``q90``, ``q99`` (lerobot's ``DEFAULT_QUANTILES``; lerobot estimates
them from a 5,000-bin histogram, here they are exact: ``numpy.quantile``, linear). Vectors per
dimension; images per channel over the frames lerobot samples (``sample_indices``: 100 spread evenly over an
episode of up to about 500 frames), each shrunk as lerobot shrinks them (about 150 pixels a side), scaled to 0-1,
shape (3, 1, 1), ``count`` the frames sampled. The
dataset's stats aggregate the episodes' as lerobot's ``aggregate_feature_stats`` does (lerobot 0.4.4): min of
the mins, max of the maxes, the count-weighted mean, the pooled variance, and for each quantile the
count-weighted mean of the episodes' (an estimate: the quantile of all frames is not kept by episodes' stats).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
Q_KEYS = tuple(f"q{int(q * 100):02d}" for q in QUANTILES)
KEYS = ("min", "max", "mean", "std", "count") + Q_KEYS


def vector_stats(x: np.ndarray) -> dict[str, np.ndarray]:
    """Stats of (N, D) values (or (N,)) per dimension, float64 arrays of shape (D,) (``count`` (1,))."""
    a = np.asarray(x, dtype=np.float64)
    a = a.reshape(len(a), -1)
    out = {"min": a.min(axis=0), "max": a.max(axis=0), "mean": a.mean(axis=0), "std": a.std(axis=0),
           "count": np.array([len(a)])}
    for key, q in zip(Q_KEYS, np.quantile(a, QUANTILES, axis=0)):
        out[key] = q
    return out


def sample_indices(n: int) -> np.ndarray:
    """The frames of an ``n``-frame episode whose images lerobot's stats read (``compute_stats.sample_indices``):
    ``max(min(100, n), min(int(n ** 0.75), 10000))`` of them, spread evenly from the first to the last."""
    k = max(min(100, n), min(int(n**0.75), 10_000))
    return np.round(np.linspace(0, n - 1, k)).astype(int)


def image_stats(frames: np.ndarray) -> dict[str, np.ndarray]:
    """Stats of (F, H, W, C) uint8 frames per channel over the pixels of lerobot's sample of the frames
    (``sample_indices``), every ``step``-th row and column of each (as lerobot shrinks a frame of 300 pixels
    or more to about 150 a side), scaled to 0-1, each of shape (C, 1, 1); ``count``: the frames sampled. From
    each channel's 256-value histogram, so exact (the quantiles as ``numpy.quantile``'s linear method gives
    them) at a fraction of sorting the pixels."""
    picked = sample_indices(len(frames))
    side = max(frames.shape[1], frames.shape[2])
    step = side // 150 if side >= 300 else 1  # lerobot's auto_downsample_height_width: about 150 pixels a side
    px = np.ascontiguousarray(frames[picked, ::step, ::step], dtype=np.uint8).reshape(-1, frames.shape[-1])
    values = np.arange(256, dtype=np.float64)
    rows: dict[str, list[float]] = {k: [] for k in KEYS if k != "count"}
    for c in range(px.shape[1]):
        counts = np.bincount(px[:, c], minlength=256).astype(np.float64)
        n = counts.sum()
        mean = float(counts @ values / n)
        seen = values[counts > 0]
        rows["mean"].append(mean)
        rows["std"].append(float(np.sqrt(counts @ (values - mean) ** 2 / n)))
        rows["min"].append(float(seen[0]))
        rows["max"].append(float(seen[-1]))
        cum = np.cumsum(counts)

        def nth(i: float, cum: np.ndarray = cum) -> float:
            """The i-th smallest pixel value (0-based)."""
            return float(np.searchsorted(cum, i, side="right"))

        for key, q in zip(Q_KEYS, QUANTILES):
            h = (n - 1) * q
            lo = np.floor(h)
            rows[key].append(nth(lo) + (h - lo) * (nth(min(lo + 1, n - 1)) - nth(lo)))
    out = {k: np.array(v).reshape(-1, 1, 1) / 255.0 for k, v in rows.items()}
    out["count"] = np.array([len(picked)])
    return {k: out[k] for k in KEYS}


def aggregate(stats: Sequence[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """One feature's stats over several episodes (lerobot's rule, see the module doc)."""
    means = np.stack([s["mean"] for s in stats])
    var = np.stack([s["std"] ** 2 for s in stats])
    counts = np.stack([np.asarray(s["count"], dtype=np.float64) for s in stats])
    total = counts.sum(axis=0)
    w = counts.reshape(counts.shape + (1,) * (means.ndim - counts.ndim))
    mean = (means * w).sum(axis=0) / total.reshape(total.shape + (1,) * (means.ndim - 1 - total.ndim))
    variance = ((var + (means - mean) ** 2) * w).sum(axis=0) / total.reshape(total.shape + (1,) * (means.ndim - 1 - total.ndim))
    out = {"min": np.stack([s["min"] for s in stats]).min(axis=0), "max": np.stack([s["max"] for s in stats]).max(axis=0),
           "mean": mean, "std": np.sqrt(variance), "count": total.astype(np.int64)}
    for key in Q_KEYS:
        out[key] = (np.stack([s[key] for s in stats]) * w).sum(axis=0) / total.reshape(total.shape + (1,) * (means.ndim - 1 - total.ndim))
    return out


def to_json(stats: dict[str, dict[str, np.ndarray]]) -> dict[str, dict[str, list]]:
    """Feature -> stat -> nested lists (``meta/stats.json``)."""
    return {f: {k: np.asarray(v).tolist() for k, v in s.items()} for f, s in stats.items()}
