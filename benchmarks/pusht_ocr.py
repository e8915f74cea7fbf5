"""Push-T result pipeline: demos -> base diffusion policy -> convert -> ocr_joint -> lerobot-eval (4 cells).

    .venv/bin/python benchmarks/pusht_ocr.py --profile quick   # <= 15 min on a 2-core CPU: shows the effect
    .venv/bin/python benchmarks/pusht_ocr.py --profile cpu     # ≈ 3 h on 2 cores: the row (200 episodes)
    .venv/bin/python benchmarks/pusht_ocr.py --profile paper   # the paper's image base; meant for a GPU

The profiles and the chain: `lerobot_ocr.pipeline.PUSHT`; publishing: `ocr_pipeline.py` (results in
`benchmarks/results/pusht_<profile>.json`, pictures in `benchmarks/results/pusht_<profile>/`, the
"Push-T (<profile>)" section of RESULTS.md).
"""

import sys
from pathlib import Path

sys.path[:0] = [str(Path(__file__).resolve().parent), str(Path(__file__).resolve().parents[1] / "src")]
import ocr_pipeline  # noqa: E402

from lerobot_ocr.pipeline import PUSHT  # noqa: E402

if __name__ == "__main__":
    ocr_pipeline.main(PUSHT)
