"""``pacjax batch --resume``: a run stopped by SIGINT or SIGKILL at a random point leaves a
readable file, and resuming it ends with the file an uninterrupted run writes, bit for bit."""

import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

SCENE = Path(__file__).resolve().parent.parent / "experiments" / "scenes" / "tendon_single.toml"
#: Enough rows that a kill after a random number of chunks in the first half lands mid-run.
ROWS, CHUNK = 6000, 64


#: The command line with Python's own SIGINT handler: a process started in the background by a
#: non-interactive shell (as a CI runner may start the tests) inherits SIGINT ignored, and Python
#: then leaves it ignored.
_CLI = (
    "import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
    "from pacjax.cli.main import main; main()"
)


def _batch(out: Path, *args) -> subprocess.Popen:
    command = [sys.executable, "-c", _CLI, "batch", *map(str, args), "--no-plot"]
    return subprocess.Popen(
        command, cwd=out, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )


def _rows_written(path: Path) -> int:
    try:
        with h5py.File(path, "r", locking=False) as f:
            return int(f.attrs["rows_written"])
    except (OSError, KeyError):
        return -1


def _columns(path: Path) -> dict:
    with h5py.File(path, "r") as f:
        return {name: f[name][()] for name in f} | {"rows": int(f.attrs["rows_written"])}


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("whole")
    shutil.copy(SCENE, out / "arm.toml")
    proc = _batch(out, "arm.toml", "--n", ROWS, "--chunk-size", CHUNK, "--sampler", "uniform")
    output, _ = proc.communicate(timeout=600)
    assert proc.returncode == 0, output
    return _columns(out / "arm_batch.h5")


@pytest.mark.slow  # five processes, each importing JAX and loading the solver
@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
def test_a_killed_batch_resumes_to_the_uninterrupted_file(tmp_path, uninterrupted, how):
    shutil.copy(SCENE, tmp_path / "arm.toml")
    path = tmp_path / "arm_batch.h5"
    # The kill point is drawn in rows, not seconds (a warm solver writes all 6,000 rows of this
    # scene in about a second): after a random number of chunks in the first half, then
    # somewhere within a chunk's time, in the middle of a chunk or between two.
    draw = random.Random(os.getpid() + how)
    target, delay = CHUNK * draw.randint(1, ROWS // (2 * CHUNK)), draw.uniform(0.0, 0.02)
    proc = _batch(tmp_path, "arm.toml", "--n", ROWS, "--chunk-size", CHUNK, "--sampler", "uniform")
    deadline = time.monotonic() + 600
    while _rows_written(path) < target and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    time.sleep(delay)
    proc.send_signal(how)
    proc.communicate(timeout=60)
    stopped_at = _rows_written(path)
    assert 0 < stopped_at < ROWS, f"stopped at {stopped_at} rows (signalled after {target})"
    assert stopped_at % CHUNK == 0

    resumed = _batch(tmp_path, "--resume", path)
    output, _ = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, output
    assert f"{stopped_at} of them from the run resumed" in output
    done = _columns(path)
    assert done.keys() == uninterrupted.keys()
    for name, values in uninterrupted.items():
        np.testing.assert_array_equal(done[name], values, err_msg=name)


def test_resume_refuses_to_change_the_run(tmp_path):
    from click.testing import CliRunner

    from pacjax.cli.main import cli

    path = tmp_path / "arm_batch.h5"
    with h5py.File(path, "w") as f:
        f.attrs["rows_written"] = 0
    result = CliRunner().invoke(cli, ["batch", "--resume", str(path), "--n", "10"])
    assert result.exit_code == 2 and "drop --n" in result.output
    result = CliRunner().invoke(cli, ["batch", "--resume", str(path)])
    assert result.exit_code == 1 and "cannot be resumed: no scene_toml" in result.output
