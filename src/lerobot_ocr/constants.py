"""Names and values shared across the package: observation keys, task strings, the Push-T goal.

Pure constants (no imports beyond numpy), so every module can use them without import cycles.
"""

import numpy as np

# Features that `lerobot-ocr convert` adds and that the `ocr_joint` policy and our envs use.
OBS_OBJECT_POSE = "observation.object_pose"  # (P,) object pose, world frame (see `pose_rotation`)
OBS_OBJECT_KEYPOINTS = "observation.object_keypoints"  # (K*D,) world keypoints, flattened
OBS_STATE = "observation.state"  # LeRobot's robot state key

# Task strings of our sim envs (LeRobot passes them to language-conditioned policies as `task`).
PUSHT_TASK = "Push the T-shaped block onto the T-shaped target."
SQUARE_TASK = "Pick up the square nut and place it over the square peg."

# gym-pusht's goal pose of the T: (x, y) in pixels, theta in radians.
PUSHT_GOAL_POSE = np.array([256.0, 256.0, np.pi / 4])
# A collected frame's mode (`lerobot-ocr collect`); not an `observation.*` key: no policy takes it as input.
OCR_IN_RECOVERY = "ocr.in_recovery"
