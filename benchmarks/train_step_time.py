"""Benchmark: low-dim diffusion training step time, plain lerobot-train vs lerobot_ocr.train_in_memory.

    .venv/bin/python benchmarks/train_step_time.py [--steps 150] [--no-update]

Trains the Push-T low-dim base of `pusht_ocr.py` (quick profile settings, batch 64) on the quick
profile's base dataset (run `benchmarks/pusht_ocr.py --profile quick` first) and reads lerobot-train's
own `updt_s` / `data_s` log values (mean of the log lines after the first). Writes the
"Low-dim training step time" section of RESULTS.md.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path[:0] = [str(HERE), str(REPO / "src")]
from results_md import update_section  # noqa: E402

from lerobot_ocr.pipeline import BIN, PUSHT, base_train_args  # noqa: E402


def timed_run(cmd: list[str]) -> dict:
    out = subprocess.run(
        cmd, capture_output=True, text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"}, cwd=REPO
    )
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-3000:])
    lines = re.findall(r"updt_s:([0-9.]+) data_s:([0-9.]+)", out.stdout + out.stderr)[1:]
    updt = sum(float(u) for u, _ in lines) / len(lines)
    data = sum(float(d) for _, d in lines) / len(lines)
    return {"updt_s": updt, "data_s": data, "step_s": updt + data, "log_lines": len(lines)}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=150)
    parser.add_argument("--no-update", action="store_true")
    args = parser.parse_args()
    data = REPO / "outputs" / "pusht_ocr_quick" / "base_data"
    if not (data / "meta" / "info.json").exists():
        sys.exit(f"{data} missing: run `.venv/bin/python benchmarks/pusht_ocr.py --profile quick` first.")
    p = dict(PUSHT.profiles["quick"], base_steps=args.steps)
    results = {
        "benchmark": "train_step_time",
        "date": dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "steps": args.steps,
    }
    with tempfile.TemporaryDirectory() as tmp:
        for name, out in (("lerobot_train", "a"), ("in_memory", "b")):
            cmd = base_train_args(
                p, data, Path(tmp) / out, PUSHT, "local/pusht_base"
            )  # python -m lerobot_ocr.train_in_memory
            cmd = [c if not c.startswith("--log_freq") else "--log_freq=25" for c in cmd]
            if name == "lerobot_train":
                cmd = [str(BIN / "lerobot-train"), *cmd[3:]]
            results[name] = timed_run(cmd)
    print(json.dumps(results))
    if not args.no_update:
        rows = [
            f"| {name} | {r['updt_s']:.3f} | {r['data_s']:.3f} | {r['step_s']:.3f} |"
            for name, r in (
                ("`lerobot-train`", results["lerobot_train"]),
                ("`python -m lerobot_ocr.train_in_memory`", results["in_memory"]),
            )
        ]
        body = "\n".join(
            [
                "Push-T low-dim base (diffusion [64,128,256], horizon 16, n_obs 2, batch 64, "
                f"`num_workers=0`) on the quick profile's dataset, {args.steps} steps; lerobot-train's "
                "own `updt_s` / `data_s` (mean over its log lines after the first).",
                "",
                "| trainer | update (s/step) | data (s/step) | total (s/step) |",
                "|---|---|---|---|",
                *rows,
                "",
                f"Machine: {results['machine']}. Date: {results['date']}.",
                "",
                "Command: `.venv/bin/python benchmarks/train_step_time.py`",
            ]
        )
        update_section("Low-dim training step time", body)


if __name__ == "__main__":
    main()
