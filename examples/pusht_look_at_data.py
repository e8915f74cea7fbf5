"""Look at Push-T ID/OOD data: start positions coloured by region, and one episode as a frame strip.

    .venv/bin/lerobot-ocr generate pusht --region id --episodes 3 --root /tmp/pusht_id
    .venv/bin/python examples/pusht_look_at_data.py --root /tmp/pusht_id --output outputs/examples

Writes start_regions.png (300 random resets of `pusht_ocr --env.region=all`, block keypoints coloured
id / ood / neither, plus the first frames of the dataset) and episode_strip.png (8 frames of episode 0).
"""

import argparse
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402

from lerobot_ocr.envs.pusht_env import block_keypoints, make_pusht_ocr_env  # noqa: E402

warnings.filterwarnings("ignore")
parser = argparse.ArgumentParser()
parser.add_argument("--root", required=True, help="A dataset written by `lerobot-ocr generate pusht`.")
parser.add_argument("--repo-id", default="local/pusht_ocr")
parser.add_argument("--output", default="outputs/examples")
args = parser.parse_args()
out = Path(args.output)
out.mkdir(parents=True, exist_ok=True)

env = make_pusht_ocr_env(region="all", obs_type="environment_state_agent_pos")
colors = {"id": "tab:blue", "ood": "tab:orange", "neither": "lightgray"}
fig, ax = plt.subplots(figsize=(5.5, 5.5), dpi=110)
for seed in range(300):
    obs, info = env.reset(seed=seed)
    kps = block_keypoints(obs["object_pose"])
    ax.scatter(kps[:, 0], kps[:, 1], s=2, c=colors[info["start_region"]])
ds = LeRobotDataset(args.repo_id, root=args.root)
hf = ds.hf_dataset.with_format("numpy")
ep, pose = np.asarray(hf["episode_index"]), np.stack(hf["observation.object_pose"])
for e in np.unique(ep):
    kps = block_keypoints(pose[ep == e][0])
    ax.scatter(kps[:, 0], kps[:, 1], s=12, c="black", marker="x")
ax.axvline(256, color="k", lw=0.8, ls="--")
ax.set(
    xlim=(0, 512),
    ylim=(0, 512),
    aspect="equal",
    title="Start keypoints: ID (blue), OOD (orange); x = dataset",
)
fig.tight_layout()
fig.savefig(out / "start_regions.png")

frames = np.nonzero(ep == 0)[0]
picks = np.linspace(frames[0], frames[-1], 8).astype(int)
fig, axes = plt.subplots(1, 8, figsize=(16, 2.3), dpi=100)
for a, i in zip(axes, picks):
    a.imshow(ds[int(i)]["observation.image"].permute(1, 2, 0).numpy())
    a.set_title(f"t={int(hf['frame_index'][i])}", fontsize=9)
    a.axis("off")
fig.tight_layout()
fig.savefig(out / "episode_strip.png")
print("wrote", out / "start_regions.png", "and", out / "episode_strip.png")
