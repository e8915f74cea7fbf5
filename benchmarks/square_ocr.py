"""Square result pipeline: demos -> low-dim base -> convert -> ocr_joint -> lerobot-eval (4 cells).

    MUJOCO_GL=egl .venv/bin/python benchmarks/square_ocr.py --profile cpu  # ≈ 5 h on 2 cores: the row
    MUJOCO_GL=egl .venv/bin/python benchmarks/square_ocr.py --profile gpu  # the reference's sizes, GPU

Like the reference, the base policy is low-dimensional (eef pose + gripper, nut pose). The profiles
and the chain: `lerobot_ocr.pipeline.SQUARE`; publishing: `ocr_pipeline.py` (results in
`benchmarks/results/square_<profile>.json`, pictures in `benchmarks/results/square_<profile>/`, the
"Square (<profile>)" section of RESULTS.md).
"""

import sys
from pathlib import Path

sys.path[:0] = [str(Path(__file__).resolve().parent), str(Path(__file__).resolve().parents[1] / "src")]
import ocr_pipeline  # noqa: E402

from lerobot_ocr.pipeline import SQUARE  # noqa: E402

if __name__ == "__main__":
    ocr_pipeline.main(SQUARE)
