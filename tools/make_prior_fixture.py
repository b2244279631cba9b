"""Write tests/fixtures/prior_torch.npz: a small residual prior trained in torch (fixed seed), its
unfolded parameters and torch's own outputs, so CI checks the numpy prior against torch without
torch (tests/mocap/test_prior_training.py).

Usage (needs the training extra, ``make train-deps``)::

    .venv/bin/python tools/make_prior_fixture.py

The network is the shipped prior's architecture (``train_prior_residual``: Linear -> BatchNorm ->
ReLU -> Dropout stem, residual blocks of two such layers, a linear head) at width 32, one block,
two epochs on synthetic poses; the outputs are torch's in evaluation mode on 50 held-out inputs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from pose_lifter.core.model.synthetic import synthetic_poses
from pose_lifter.mocap import prior_training as pt

OUT = Path(__file__).resolve().parents[1] / "tests" / "fixtures" / "prior_torch.npz"
#: The training run (seeded: it repeats exactly).
SETTINGS: dict[str, Any] = {"width": 32, "blocks": 1, "epochs": 2, "samples_per_epoch": 1024,
                            "batch_size": 128, "seed": 4, "log": None}


def main() -> None:
    seqs = [synthetic_poses(200, seed=s, n_actions=2) for s in range(3)]
    captured: dict[str, Any] = {}
    original = pt._fold_residual

    def spy(stem: Any, body: Any, head: Any, *rest: Any) -> Any:
        captured.update(stem=stem, body=body, head=head, out_mean=rest[0], out_scale=rest[1])
        return original(stem, body, head, *rest)

    pt._fold_residual = spy  # type: ignore[assignment]
    try:
        pt.train_prior_residual(seqs[:2], seqs[2:], **SETTINGS)
    finally:
        pt._fold_residual = original  # type: ignore[assignment]
    stem, body, head = captured["stem"], captured["body"], captured["head"]
    for module in (stem, *body, head):
        module.eval()
    x = pt.make_batch(seqs[2:], 50, np.random.default_rng(3)).features
    with torch.no_grad():
        h = stem(torch.from_numpy(x.astype(np.float32)))
        for blk in body:
            h = h + blk(h)
        y = head(h).double().numpy()

    arrays: dict[str, Any] = {"x": x, "y_torch": y, "out_mean": captured["out_mean"],
                              "out_scale": captured["out_scale"], "n_blocks": np.int64(len(body))}

    def put(name: str, lin: Any, bn: Any) -> None:
        for key, t in (("weight", lin.weight), ("bias", lin.bias), ("gamma", bn.weight), ("beta", bn.bias),
                       ("mean", bn.running_mean), ("var", bn.running_var)):
            arrays[f"{name}_{key}"] = t.detach().double().numpy()
        arrays[f"{name}_eps"] = np.float64(bn.eps)

    put("stem", stem[0], stem[1])
    for i, blk in enumerate(body):
        put(f"block{i}_a", blk[0], blk[1])
        put(f"block{i}_b", blk[4], blk[5])
    arrays["head_weight"] = head.weight.detach().double().numpy()
    arrays["head_bias"] = head.bias.detach().double().numpy()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(OUT, **arrays)
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes, torch {torch.__version__})")


if __name__ == "__main__":
    main()
