"""Rewrite one `## <title>` section of benchmarks/RESULTS.md, keeping the others."""

from __future__ import annotations

import os
import platform
import re
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
HEADER = (
    "# Benchmark results\n\nThe summary (benchmarks/summary.py), then one section per benchmark script; "
    "re-run its command to refresh it.\n"
)


def update_section(title: str, body: str, path: Path = RESULTS, first: bool = False) -> None:
    """Replace the section `## <title>` (or add it: at the end, or before every other section if `first`)."""
    text = path.read_text() if path.exists() else HEADER
    section = f"## {title}\n\n{body.strip()}\n"
    pattern = re.compile(rf"^## {re.escape(title)}\n.*?(?=^## |\Z)", re.S | re.M)
    if pattern.search(text):
        text = pattern.sub(lambda _: section + "\n", text, count=1)
    elif first and re.search(r"^## ", text, re.M):
        at = re.search(r"^## ", text, re.M).start()
        text = text[:at] + section + "\n" + text[at:]
    else:
        text = text.rstrip("\n") + "\n\n" + section
    tmp = path.with_suffix(".tmp")
    tmp.write_text(text.rstrip("\n") + "\n")
    tmp.replace(path)


def machine() -> str:
    """Architecture, CPU model, cores and Python, for a result file (a recipe is bit-for-bit repeatable on
    one CPU model, not across them)."""
    cpuinfo = Path("/proc/cpuinfo")
    lines = cpuinfo.read_text().splitlines() if cpuinfo.exists() else []
    models = [line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")]
    model = models[0] if models else platform.processor() or "cpu"
    return f"{platform.machine()}, {model}, {os.cpu_count()} cores, python {platform.python_version()}"
