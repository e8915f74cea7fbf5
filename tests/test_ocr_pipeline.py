"""lerobot_ocr.pipeline: stage commands import this clone's `lerobot_ocr`, whatever the venv points at."""

import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
from lerobot_ocr import pipeline as ocr_pipeline  # noqa: E402


def test_stage_commands_import_this_clones_sources(tmp_path, monkeypatch):
    # Another clone's package on PYTHONPATH stands in for a shared venv whose editable install points
    # elsewhere.
    other = tmp_path / "other_clone" / "src" / "lerobot_ocr"
    other.mkdir(parents=True)
    (other / "__init__.py").write_text("")
    monkeypatch.setenv("PYTHONPATH", str(other.parent))
    log = tmp_path / "logs" / "where.log"
    ocr_pipeline.run(
        [
            sys.executable,
            "-c",
            "import lerobot_ocr, os; print('FILE=' + os.path.realpath(lerobot_ocr.__file__))",
        ],
        log,
    )
    found = next(line for line in log.read_text().splitlines() if line.startswith("FILE="))[5:]
    assert Path(found) == (REPO / "src" / "lerobot_ocr" / "__init__.py").resolve()


def test_failed_stage_raises_with_the_log_tail(tmp_path):
    log = tmp_path / "fail.log"
    with pytest.raises(RuntimeError, match="stage-went-wrong"):
        ocr_pipeline.run([sys.executable, "-c", "import sys; print('stage-went-wrong'); sys.exit(3)"], log)
    assert "stage-went-wrong" in log.read_text()
