"""g2p.rl.sweep on a real local Ray (one start for the module): rows, failures, the tidy table."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from g2p.rl.sweep import JobFailure, SweepResult, ray_session, run_sweep


def job(seed: int, kind: str) -> dict[str, Any]:
    """A benchmark's job in miniature: fails on demand, else reports a scalar, a list and torch's threads."""
    if kind == "raise":
        raise ValueError(f"boom {seed}")
    if kind == "crash":
        os._exit(3)  # the worker process dies, as on a segfault or the OOM killer
    import torch

    return {"double": 2 * seed, "trace": [seed, seed + 1], "threads": torch.get_num_threads()}


@pytest.fixture(scope="module")
def ray_address() -> Iterator[str]:
    """One local Ray (2 CPUs) for the module, as run_sweep starts it; its GCS address."""
    import ray

    with ray_session(workers=2):
        yield ray.get_runtime_context().gcs_address


def test_a_failing_job_is_reported_and_the_others_go_on(ray_address: str, tmp_path: Path) -> None:
    jobs = [{"seed": 3, "kind": "ok"}, {"seed": 4, "kind": "raise"}, {"seed": 5, "kind": "ok"}]
    result = run_sweep(job, jobs, progress=False)

    assert result.rows == [
        {"seed": 3, "kind": "ok", "double": 6, "trace": [3, 4], "threads": 1},
        {"seed": 5, "kind": "ok", "double": 10, "trace": [5, 6], "threads": 1},
    ]
    (failure,) = result.failures
    assert failure.params == {"seed": 4, "kind": "raise"}
    assert failure.error == "ValueError: boom 4"
    assert "in job" in failure.traceback and failure.traceback.rstrip().endswith("ValueError: boom 4")
    assert result.workers == 2.0
    assert result.wall_s > 0

    path = result.write_csv(tmp_path / "out" / "results.csv")
    with path.open(newline="") as f:
        table = list(csv.DictReader(f))
    assert list(table[0]) == ["seed", "kind", "double", "trace", "threads"]
    assert [(r["seed"], r["double"], json.loads(r["trace"])) for r in table] == [
        ("3", "6", [3, 4]),
        ("5", "10", [5, 6]),
    ]
    assert [p.name for p in path.parent.iterdir()] == ["results.csv"]  # no temporary file left

    failures = json.loads(result.write_failures(tmp_path / "failures.json").read_text())
    assert failures == [
        {
            "params": {"seed": 4, "kind": "raise"},
            "error": "ValueError: boom 4",
            "traceback": failure.traceback,
        }
    ]


def test_a_dead_worker_is_a_failure_too(ray_address: str) -> None:
    result = run_sweep(job, [{"seed": 1, "kind": "crash"}, {"seed": 2, "kind": "ok"}], progress=False)

    assert [r["seed"] for r in result.rows] == [2]
    (failure,) = result.failures
    assert failure.params == {"seed": 1, "kind": "crash"}
    assert failure.error.startswith("WorkerCrashedError: ")


def test_torch_gets_the_threads_of_the_job(ray_address: str) -> None:
    (row,) = run_sweep(job, [{"seed": 0, "kind": "ok"}], cpus_per_job=2.0, progress=False).rows
    assert row["threads"] == 2


def test_a_job_larger_than_any_node_is_refused(ray_address: str) -> None:
    with pytest.raises(ValueError, match=r"cpus_per_job=3\.0 is more than any node offers \(2\.0 CPUs\)"):
        run_sweep(job, [{"seed": 0, "kind": "ok"}], cpus_per_job=3.0, progress=False)


def _descends_from(pid: int, ancestor: int) -> bool:
    while pid > 1:
        if pid == ancestor:
            return True
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            return False
        pid = int(stat.rpartition(")")[2].split()[1])  # the field after the command name is the parent
    return False


@pytest.mark.skipif(shutil.which("ss") is None, reason="needs ss (iproute2)")
def test_the_local_ray_listens_on_loopback_only(ray_address: str) -> None:
    run_sweep(job, [{"seed": 0, "kind": "ok"}], progress=False)  # a worker is up
    listening = subprocess.run(["ss", "-ltnpH"], capture_output=True, text=True, check=True).stdout
    ours = []
    for line in listening.splitlines():
        local = line.split()[3]
        pids = [int(p) for p in re.findall(r"pid=(\d+)", line)]
        if any(_descends_from(p, os.getpid()) for p in pids):
            ours.append(local.rpartition(":")[0])
    assert len(ours) >= 4  # the GCS, the raylet's two servers, this driver's and the worker's
    assert set(ours) <= {"127.0.0.1", "[::ffff:127.0.0.1]"}
    assert ray_address.startswith("127.0.0.1:")


def test_the_table_keeps_param_columns_first_and_encodes_what_is_not_scalar(tmp_path: Path) -> None:
    result = SweepResult(
        rows=[
            {"variant": "a", "seed": 0, "reward_mm": np.float64(1.5), "n": np.int64(3), "ok": np.bool_(True)},
            {"variant": "b", "seed": 1, "extra": {"k": np.arange(2)}, "reward_mm": None},
        ],
        failures=[JobFailure({"variant": "c", "seed": 2, "method": "ppo"}, "ValueError: x", "")],
        wall_s=1.0,
        workers=2.0,
        param_columns=("variant", "seed", "method"),
    )
    assert result.columns() == ["variant", "seed", "method", "reward_mm", "n", "ok", "extra"]
    text = result.write_csv(tmp_path / "t.csv").read_text()
    assert text.splitlines() == [
        "variant,seed,method,reward_mm,n,ok,extra",
        "a,0,,1.5,3,True,",
        'b,1,,,,,"{""k"": [0, 1]}"',
    ]


@pytest.mark.slow
def test_a_function_of_a_script_run_as_main_runs_on_a_cluster(ray_address: str, tmp_path: Path) -> None:
    """A benchmark script's own function, sent by value, on the module's Ray reached by its address."""
    script = tmp_path / "bench_toy.py"
    script.write_text(
        textwrap.dedent(
            """
            import json, sys
            from g2p.rl.sweep import run_sweep

            OFFSET = 100  # a global of the script: travels with the function

            def toy(seed):
                return {"value": seed + OFFSET}

            if __name__ == "__main__":
                result = run_sweep(toy, [{"seed": 1}, {"seed": 2}], address=sys.argv[1], progress=False)
                print(json.dumps({"rows": result.rows, "failures": len(result.failures)}))
            """
        )
    )
    # Outside the repository, so only the installed g2p and the script itself are importable.
    proc = subprocess.run(
        [sys.executable, str(script), ray_address], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out == {"rows": [{"seed": 1, "value": 101}, {"seed": 2, "value": 102}], "failures": 0}
