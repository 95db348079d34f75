"""Training of the far strip's verifier (:mod:`cone_perception.detector.verifier`) on the crops of
:mod:`cone_perception.data.verifiercrops`: ``cone-perception train --data CROPS.npz --out DIR`` (AdamW, one-cycle,
flips, gain and offset, blur; a tenth held out) writes ``DIR/verifier.pt`` with the thresholds below.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..detector.verifier_net import new_net, patches_tensor, save_verifier
from ..errors import ConfigError

#: The thresholds written with the weights (docs/benchmarks.md, "A second look at the far strip's boxes"): boxes
#: scored below VERIFY_BELOW, MIN_PX..MAX_PX tall, are dropped where the network gives a cone less than MIN_P.
VERIFY_BELOW, MIN_P, MIN_PX, MAX_PX = 0.7, 0.1, 6.0, 60.0


def train_verifier(crops: str | Path, out_dir: str | Path, epochs: int = 12, seed: int = 0, threads: int = 1,
                   progress: bool = True) -> dict:
    """Train on the crops of :func:`verifier_crops` and write ``out_dir/verifier.pt``; the held-out tenth's figures
    of the last epoch."""
    import torch
    import torch.nn as nn

    try:
        z = np.load(crops)
        X, y, src = z["X"], z["y"].astype(np.float32), z["src"]
    except (OSError, KeyError, ValueError) as e:
        raise ConfigError(str(crops), None, f"not a verifier crop file of `data verifier-crops`: {e}") from None
    torch.manual_seed(seed)
    torch.set_num_threads(max(1, threads))
    rng = np.random.default_rng(seed)
    idx = rng.permutation(len(y))
    va, tr = idx[:len(y) // 10], idx[len(y) // 10:]
    net = new_net()
    opt = torch.optim.AdamW(net.parameters(), 2e-3, weight_decay=1e-4)
    pos_w = float((y[tr] == 0).sum() / max((y[tr] == 1).sum(), 1))
    lossf = nn.BCEWithLogitsLoss(pos_weight=torch.tensor(pos_w))
    batch = 128
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, 2e-3, total_steps=epochs * (len(tr) // batch + 1))
    xt = patches_tensor(X)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    res = {}
    for ep in range(epochs):
        net.train()
        perm = rng.permutation(tr)
        total = 0.0
        for k in tqdm(range(0, len(perm), batch), desc=f"verifier epoch {ep + 1}/{epochs}", unit="batch",
                      disable=not progress, file=sys.stderr):
            bi = perm[k:k + batch]
            xb = xt[bi]
            if rng.random() < 0.5:
                xb = xb.flip(3)
            gain = torch.from_numpy(rng.uniform(0.7, 1.3, (len(bi), 1, 1, 1)).astype(np.float32))
            off = torch.from_numpy(rng.uniform(-0.1, 0.1, (len(bi), 1, 1, 1)).astype(np.float32))
            xb = (xb * gain + off).clamp(0, 1)
            if rng.random() < 0.4:  # blur: real frames are often video, upscaled
                xb = nn.functional.avg_pool2d(xb, 3, 1, 1)
            loss = lossf(net(xb), torch.from_numpy(y[bi]))
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(bi)
        net.eval()
        with torch.inference_mode():
            pv = torch.sigmoid(net(xt[va])).numpy()
        yv = y[va]
        real = src[va] == 2
        res = {"epoch": ep + 1, "loss": total / max(len(tr), 1),
               "cones_kept": float((pv[yv == 1] >= MIN_P).mean()) if (yv == 1).any() else None,
               "not_cones_dropped": float((pv[yv == 0] < MIN_P).mean()) if (yv == 0).any() else None,
               "real_cones_kept": float((pv[real & (yv == 1)] >= MIN_P).mean()) if (real & (yv == 1)).any() else None}
        print(f"verifier epoch {ep + 1}: loss {res['loss']:.4f}, held-out tenth at p >= {MIN_P:g}: cones kept "
              f"{res['cones_kept']}, not-cones dropped {res['not_cones_dropped']}, real cones kept {res['real_cones_kept']}",
              file=sys.stderr, flush=True)
    save_verifier(out_dir / "verifier.pt", net, VERIFY_BELOW, MIN_P, MIN_PX, MAX_PX,
                  {"crops": str(crops), "n": int(len(y)), "cones": int(y.sum()), "epochs": epochs, "seed": seed, **res})
    return res
