"""campaign.sh: a finished run is refused before any data is generated; an unfinished one
resumes with the campaign's recipe."""

import json
import os
import shutil
import subprocess
from pathlib import Path

CAMPAIGN = Path(__file__).resolve().parents[1] / "campaign.sh"


def campaign_tree(root: Path, run: str, last_step: int) -> None:
    """A repository root holding the script, a run's log and the data it checks for, with a
    stand-in Python that prints the arguments it is given."""
    training = root / "models" / "training"
    training.mkdir(parents=True)
    shutil.copy(CAMPAIGN, training / "campaign.sh")
    python = training / ".venv" / "bin" / "python"
    python.parent.mkdir(parents=True)
    python.write_text('#!/bin/sh\necho "$@"\n')
    python.chmod(0o755)
    log = root / "models" / "campaign" / run / "log.jsonl"
    log.parent.mkdir(parents=True)
    log.write_text("".join(json.dumps({"step": step, "total": 1.0}) + "\n" for step in (last_step - 1, last_step)))
    (root / "data" / "suite-v5-full").mkdir(parents=True)
    (root / "data" / "suite-v5-full" / "manifest.json").write_text("{}")
    (root / "data" / "suite-v5" / "val").mkdir(parents=True)


def run_campaign(root: Path, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", str(root / "models" / "training" / "campaign.sh")],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_a_finished_run_is_refused_naming_its_steps(tmp_path):
    campaign_tree(tmp_path, "finished", last_step=6000)
    result = run_campaign(tmp_path, RUN="finished", STEPS="6000")
    assert result.returncode == 1
    assert "run finished has done 6000 of its 6000 steps" in result.stderr
    assert result.stdout == ""


def test_an_unfinished_run_resumes_with_the_recipe(tmp_path):
    campaign_tree(tmp_path, "longer", last_step=6000)
    result = run_campaign(tmp_path, RUN="longer", STEPS="8000")
    assert result.returncode == 0, result.stderr
    arguments = result.stdout.split()
    assert arguments[arguments.index("--steps") + 1] == "8000"
    assert arguments[arguments.index("--run-dir") + 1] == "../campaign/longer"
    assert "--resume" in arguments
    assert "--event-jitter" in arguments
    assert arguments[arguments.index("--streams") + 1] == "8"
    assert arguments[arguments.index("--encoder-base-channels") + 1] == "24"


def test_a_run_at_the_base_width_resumes_without_widening(tmp_path):
    campaign_tree(tmp_path, "base-width", last_step=100)
    result = run_campaign(tmp_path, RUN="base-width", ENCODER_BASE_CHANNELS="")
    assert result.returncode == 0, result.stderr
    assert "--encoder-base-channels" not in result.stdout.split()
