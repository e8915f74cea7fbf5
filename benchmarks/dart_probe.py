"""Probe (not product): a Square base trained on demos recorded with DART noise injection.

DART (Laskey et al. 2017, "DART: Noise Injection for Robust Imitation Learning"): the scripted expert's
commanded end-effector target is perturbed before the env executes it, while the dataset records the
expert's clean target, so the base sees states off the expert's path labelled with the way back. The
question: does a base trained on such demos finish more of the states the recovery hands it back?

Stages in `outputs/square_dart` (resumable, `Stages` markers): noisy demos (seed 0, 200 episodes, the
chain's generator with the env's `step` wrapped), `base_data`, the base trained with the `cpu` profile's
command (`base_train_args`, seed 1000), then the clean `cpu` chain's data stages (in `--clean`) and its
inverse policy trained with this base bundled (same inverse policy, manifold and threshold as the clean
chain's ocr_joint checkpoint: a rebase). Evaluate with `benchmarks/probe.py`.

Noise: piecewise constant over segments of `--segment` steps; each segment is noisy with probability
`--p-noisy`, then the xyz target is offset by N(0, sigma_xy) in x, y and N(0, sigma_z) in z. The gripper
and rotation are never perturbed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(REPO / "src")]

from lerobot_ocr.pipeline import TASKS, Stages, base_train_args, chain_data, ocr_train_args, train  # noqa: E402


class NoisyTarget:
    """Wraps a Square env: `step(action)` executes the action with its xyz offset by the segment's noise."""

    def __init__(self, env, sigma_xy: float, sigma_z: float, segment: int, p_noisy: float, moving: float):
        self.env, self.sigma = env, np.array([sigma_xy, sigma_xy, sigma_z])
        self.segment, self.p_noisy, self.moving = segment, p_noisy, moving

    def __getattr__(self, name):
        return getattr(self.env, name)

    @property
    def unwrapped(self):
        return self.env.unwrapped

    def reset(self, seed=None, **kwargs):
        self.rng, self.t, self.offset, self.previous = (
            np.random.default_rng(None if seed is None else 7_000_000 + seed),
            0,
            0,
            None,
        )
        self.perturbed = self.steps = 0
        return self.env.reset(seed=seed, **kwargs)

    def step(self, action):
        if self.t % self.segment == 0:
            noisy = self.rng.random() < self.p_noisy
            self.offset = self.rng.normal(0.0, self.sigma) if noisy else np.zeros(3)
        self.t += 1
        executed = np.array(action, dtype=float).copy()
        # v2: perturb only while the expert's clean target moves (it heads for a goal); a target that
        # stands still means the expert waits (a goal to reach, the gripper, the nut to settle), and a
        # perturbed arm would make it wait longer (v1 lengthened the demos by 18%)
        moving = self.previous is not None and np.linalg.norm(executed[:3] - self.previous) > self.moving
        self.previous = executed[:3].copy()
        if moving:
            executed[:3] += self.offset
            self.perturbed += bool(np.any(self.offset != 0))
        self.steps += 1
        return self.env.step(executed)


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--work", default="outputs/square_dart2")
    parser.add_argument("--sigma-xy", type=float, default=0.01)
    parser.add_argument("--sigma-z", type=float, default=0.005)
    parser.add_argument("--segment", type=int, default=10)
    parser.add_argument("--p-noisy", type=float, default=0.5)
    parser.add_argument("--moving", type=float, default=0.001, help="m per step: the target moves")
    parser.add_argument("--clean", default="outputs/square_ocr_cpu", help="the clean chain's work dir")
    args = parser.parse_args()
    work = (REPO / args.work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    task, p = TASKS["square"], TASKS["square"].profiles["cpu"]
    stage = Stages(work)
    settings = {k: getattr(args, k) for k in ("sigma_xy", "sigma_z", "segment", "p_noisy", "moving")}
    (work / "dart.json").write_text(json.dumps(settings, indent=2))

    def demos():
        import lerobot_ocr.envs.square_env as square_env
        from lerobot_ocr.datagen.square import generate_square

        make = square_env.make_square_ocr_env
        square_env.make_square_ocr_env = lambda *a, **k: NoisyTarget(
            make(*a, **k), args.sigma_xy, args.sigma_z, args.segment, args.p_noisy, args.moving
        )
        generate_square(
            work / "demos", p["demos"], "id", "local/square_demos", seed=0, images=False, overwrite=True
        )

    stage("demos", demos)
    data = chain_data(task, p, work, [], stage)
    base_out = work / "base"
    stage(
        "base_train",
        lambda: train(
            base_train_args(p, data.base_data, base_out, task, data.base_repo),
            base_out,
            work / "logs" / "base_train.log",
        ),
    )
    base_ckpt = base_out / "checkpoints" / "last" / "pretrained_model"
    # The clean chain's inverse policy (its demos, converted; the `cpu` profile's command, seed 1000)
    # trained with this base bundled: the inverse policy does not read the base, so this is the clean
    # chain's ocr_joint checkpoint rebased onto the noise-trained base, built on a machine without it.
    clean_work = (REPO / args.clean).resolve()
    clean = chain_data(task, p, clean_work, [], Stages(clean_work))
    out = work / "ocr"
    stage(
        "ocr_train",
        lambda: train(ocr_train_args(task, p, clean, base_ckpt, out), out, work / "logs" / "ocr_train.log"),
    )
    out = out / "checkpoints" / "last" / "pretrained_model"
    print(f"base: {base_ckpt}\njoint: {out}", flush=True)
    return 0


if __name__ == "__main__":
    t0 = time.time()
    rc = main()
    print(f"done in {time.time() - t0:.0f} s")
    sys.exit(rc)
