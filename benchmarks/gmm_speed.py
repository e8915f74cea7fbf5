"""Benchmark: density + recovery vector, ours (closed form, vectorised) vs the reference style.

The reference style (the OCR authors' GMMGradient) builds one torch MultivariateNormal per component
on every call and runs `backward()` once per keypoint to get the gradient of the raw pdf.

    .venv/bin/python benchmarks/gmm_speed.py [--repeats 300] [--no-update]

Prints one JSON line and updates the "GMM speed" section of benchmarks/RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_md import update_section  # noqa: E402

from lerobot_ocr.manifold import KeypointManifold  # noqa: E402
from lerobot_ocr.synthetic import synthetic_pusht_keypoints  # noqa: E402

PHI, ETA = 5500.0, 1100.0


def naive_recovery(manifold: KeypointManifold, keypoints: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Reference-style density + recovery vector: fresh distributions and autograd per keypoint."""
    densities, vectors = [], []
    for k in range(manifold.n_keypoints):
        x = keypoints[:, k].clone().requires_grad_(True)
        pdf = 0.0
        for m in range(manifold.n_components):
            dist = torch.distributions.MultivariateNormal(manifold.means_[k, m], manifold.covariances_[k, m])
            pdf = pdf + manifold.weights_[k, m] * torch.exp(dist.log_prob(x))
        pdf.sum().backward()
        grad = x.grad
        norm = grad.norm(dim=-1, keepdim=True)
        vectors.append(grad / norm * torch.exp((PHI - norm) / ETA))  # NaN where the gradient is 0
        densities.append(pdf.detach())
    return torch.stack(densities, -1).mean(-1), torch.stack(vectors, 1).mean(1)


def fast_recovery(manifold: KeypointManifold, keypoints: torch.Tensor):
    return manifold.recovery(keypoints, magnitude="paper", phi=PHI, eta=ETA)


def time_call(fn, repeats: int) -> float:
    for _ in range(max(5, repeats // 10)):
        fn()
    best = float("inf")
    for _ in range(5):  # best of 5 rounds, each the mean over `repeats` calls
        t0 = time.perf_counter()
        for _ in range(repeats):
            fn()
        best = min(best, (time.perf_counter() - t0) / repeats)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=300)
    parser.add_argument("--no-update", action="store_true", help="Do not rewrite benchmarks/RESULTS.md.")
    args = parser.parse_args()

    torch.set_num_threads(max(1, os.cpu_count() or 1))
    train = synthetic_pusht_keypoints(n_episodes=50, seed=0)
    manifold = KeypointManifold(n_components=4).fit(train)
    rng = np.random.default_rng(1)
    results: dict = {
        "benchmark": "gmm_speed",
        "keypoints": manifold.n_keypoints,
        "components": manifold.n_components,
        "date": dt.date.today().isoformat(),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"torch {torch.__version__}",
    }
    for batch in (1, 64):
        x = torch.from_numpy(train[rng.choice(len(train), batch)] + rng.normal(scale=30, size=(batch, 9, 2)))
        fast_d = fast_recovery(manifold, x)
        naive_d, naive_v = naive_recovery(manifold, x)
        # Same numbers (where the reference is not NaN): a speed comparison of equal work.
        torch.testing.assert_close(fast_d.log_density.exp().mean(-1), naive_d, rtol=1e-6, atol=0)
        torch.testing.assert_close(fast_d.vector, naive_v, rtol=1e-6, atol=1e-9)
        with torch.inference_mode():
            t_fast = time_call(lambda: fast_recovery(manifold, x), args.repeats)
        t_naive = time_call(lambda: naive_recovery(manifold, x), max(20, args.repeats // 10))
        results[f"batch{batch}"] = {
            "ours_us": round(t_fast * 1e6, 1),
            "naive_us": round(t_naive * 1e6, 1),
            "speedup": round(t_naive / t_fast, 1),
            "ours_us_per_query": round(t_fast * 1e6 / batch, 2),
        }
    print(json.dumps(results))
    if not args.no_update:
        b1, b64 = results["batch1"], results["batch64"]
        body = "\n".join(
            [
                f"Density + recovery vector, {results['keypoints']} keypoints x {results['components']} "
                "components (float64), ours (closed form, one vectorised pass) vs the reference style "
                "(MultivariateNormal objects per call, `backward()` per keypoint). Both give the same "
                "numbers (checked in the run).",
                "",
                "| batch | ours (µs/call) | naive (µs/call) | speed-up | ours per query (µs) |",
                "|---|---|---|---|---|",
                f"| 1 | {b1['ours_us']} | {b1['naive_us']} | {b1['speedup']}× | {b1['ours_us_per_query']} |",
                f"| 64 | {b64['ours_us']} | {b64['naive_us']} | {b64['speedup']}× | "
                f"{b64['ours_us_per_query']} |",
                "",
                f"Targets: ≥ 50× at batch 1, ≤ 100 µs per query. Machine: {results['machine']}. Date: "
                f"{results['date']}.",
                "",
                "Command: `.venv/bin/python benchmarks/gmm_speed.py`",
                "",
                f"Raw: `{json.dumps(results)}`",
            ]
        )
        update_section("GMM speed", body)


if __name__ == "__main__":
    main()
