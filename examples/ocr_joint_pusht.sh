#!/usr/bin/env bash
# Walk-through: give a Push-T diffusion policy an OOD recovery mode with ocr_joint.
#   demos -> (your) base policy -> lerobot-ocr convert -> lerobot-train ocr_joint -> lerobot-eval (OOD starts)
# Defaults are CPU-sized so that the whole thing runs in about 8 minutes on 2 cores (the policies are undertrained:
# this shows the commands, not the success rates; see benchmarks/ for those). Scale with the variables:
#   DEMOS=100 BASE_STEPS=50000 OCR_STEPS=30000 EPISODES=50 DEVICE=cuda bash examples/ocr_joint_pusht.sh
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-outputs/walkthrough}
DEMOS=${DEMOS:-10}
BASE_STEPS=${BASE_STEPS:-200}
OCR_STEPS=${OCR_STEPS:-200}
EPISODES=${EPISODES:-2}
DEVICE=${DEVICE:-cpu}
BIN=.venv/bin
export HF_HUB_OFFLINE=${HF_HUB_OFFLINE:-1} MUJOCO_GL=${MUJOCO_GL:-egl} SDL_VIDEODRIVER=${SDL_VIDEODRIVER:-dummy}
rm -rf "$OUT"
set -x

# 0. Demonstrations that all start in the left half (ID). With your own data, skip to step 2.
$BIN/lerobot-ocr generate pusht --region id --episodes "$DEMOS" --root "$OUT/demos" --repo-id local/pusht_demos
# The base sees what LeRobot's pusht env gives (image + agent xy): drop the keypoint state it would otherwise use.
$BIN/lerobot-edit-dataset --repo_id local/pusht_demos --root "$OUT/demos" --new_repo_id local/pusht \
  --new_root "$OUT/pusht" --operation.type remove_feature --operation.feature_names "['observation.environment_state']"

# 1. The base policy: an image diffusion policy (you probably have one already; a hub id works too).
$BIN/lerobot-train --dataset.repo_id=local/pusht --dataset.root="$OUT/pusht" --policy.type=diffusion \
  --policy.device="$DEVICE" --policy.push_to_hub=false --policy.down_dims='[64,128,256]' --policy.horizon=16 \
  --policy.n_action_steps=8 --policy.noise_scheduler_type=DDIM --policy.num_inference_steps=10 \
  --policy.pretrained_backbone_weights=null --policy.use_group_norm=true --policy.crop_shape='[84,84]' \
  --steps="$BASE_STEPS" --batch_size=32 --num_workers=0 --env_eval_freq=0 --save_freq="$BASE_STEPS" \
  --output_dir="$OUT/base"
BASE="$OUT/base/checkpoints/last/pretrained_model"

# 2. Convert: add observation.object_pose + observation.object_keypoints (the paper's 9 T keypoints).
$BIN/lerobot-ocr convert --repo-id local/pusht --root "$OUT/pusht" --object pusht_t \
  --pose-from feature:observation.object_pose --output-root "$OUT/pusht_ocr" --output-repo-id local/pusht_ocr

# 3. Train ocr_joint: fits the keypoint manifold, trains the keypoint inverse policy; the base stays frozen.
$BIN/lerobot-train --config_path=configs/policy/ocr_joint_pusht.json --dataset.repo_id=local/pusht_ocr \
  --dataset.root="$OUT/pusht_ocr" --policy.base_path="$BASE" --policy.device="$DEVICE" \
  --policy.down_dims='[64,128,256]' --steps="$OCR_STEPS" --batch_size=64 --num_workers=0 \
  --save_freq="$OCR_STEPS" --output_dir="$OUT/ocr"

# 4. Evaluate both from OOD starts (T in the right half) with plain lerobot-eval.
for name in base ocr; do
  $BIN/lerobot-eval --policy.path="$OUT/$name/checkpoints/last/pretrained_model" --env.type=pusht_ocr \
    --env.region=ood --eval.n_episodes="$EPISODES" --eval.batch_size="$EPISODES" --policy.device="$DEVICE" \
    --output_dir="$OUT/eval_$name"
done
set +x
for name in base ocr; do
  echo "$name: $(python3 -c "import json,sys; o=json.load(open(sys.argv[1]))['overall']; print(f\"OOD success {o['pc_success']:.0f}% over {o['n_episodes']} episodes\")" "$OUT/eval_$name/eval_info.json")"
done
