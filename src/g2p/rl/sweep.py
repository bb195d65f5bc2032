"""Fan a benchmark out over its jobs (seeds x rig variants x methods) on Ray, here or on a cluster.

    result = run_sweep(train, [{"method": "ppo", "seed": s} for s in range(15)])
    result.write_csv(out / "results.csv")

Each job is one call `fn(**params)` returning one row (a mapping). `run_sweep` starts a local Ray bound
to loopback unless given a cluster (`address=` or RAY_ADDRESS); a job that raises or whose worker dies is
reported in `SweepResult.failures` and the others go on. `fn` may be a function of an installed module or
of a script run as `__main__` (Ray sends the latter by value, with cloudpickle); what it imports must be
installed on every node. Needs the `sweep` extra (ray, tqdm): `pip install -e .[sweep]`.
"""

from __future__ import annotations

import csv
import importlib.util
import io
import json
import logging
import os
import sys
import time
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from g2p.files import write_text_atomically

__all__ = ["JobFailure", "SweepResult", "ray_session", "run_sweep"]

# Written by run_sweep's own Ray only. Ray keeps its servers on the node's address, and turns
# "127.0.0.1" into the machine's outward address, unless it believes multi-node clusters are off
# (ray._private.services.get_node_ip_address): that switch is the only way to loopback on Linux.
_LOCAL_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}
# Ray's own ray.init sets this one for the process (token authentication); put back with the others.
_RAY_SETS = ("RAY_AUTH_MODE",)


@dataclass(frozen=True)
class JobFailure:
    """A job that did not return a row.

    Attributes:
        params: the job's parameters, as given.
        error: the exception, "TypeName: message" (e.g. "ValueError: boom"), or Ray's error when the
            worker died (e.g. "WorkerCrashedError: ...").
        traceback: the job's formatted traceback, or Ray's report for a dead worker.
    """

    params: dict[str, Any]
    error: str
    traceback: str


@dataclass
class SweepResult:
    """What a sweep produced.

    Attributes:
        rows: one per successful job, in job order: the job's params merged with fn's row (fn's keys
            win on a clash).
        failures: one per failed job, in job order.
        wall_s: the sweep's wall time (s), Ray start excluded.
        workers: the CPUs the cluster offered (Ray's "CPU" resource) while the sweep ran.
        param_columns: the keys of every job's params (failed ones included), in first-seen order:
            the table's leading columns.
    """

    rows: list[dict[str, Any]]
    failures: list[JobFailure]
    wall_s: float
    workers: float
    param_columns: tuple[str, ...] = ()

    def columns(self) -> list[str]:
        """The table's columns: `param_columns`, then the rows' other keys in first-seen order."""
        params = dict.fromkeys(self.param_columns)
        results = dict.fromkeys(k for row in self.rows for k in row if k not in params)
        return [*params, *results]

    def write_csv(self, path: str | os.PathLike[str]) -> Path:
        """Write the rows as a tidy CSV table (one row per successful job), atomically.

        Columns are `columns()`; a row lacking a column leaves it empty, as does a None. Scalars (str,
        int, float, bool, numpy scalars) are written as they are; anything else (lists, dicts, arrays)
        as JSON text.

        Args:
            path: the CSV file; its directory is created when missing.

        Returns:
            The path written.
        """
        columns = self.columns()
        text = io.StringIO()
        writer = csv.DictWriter(text, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        for row in self.rows:
            writer.writerow({k: _cell(row[k]) for k in columns if k in row})
        return write_text_atomically(Path(path), text.getvalue())

    def write_failures(self, path: str | os.PathLike[str]) -> Path:
        """Write the failures as a JSON list of {"params", "error", "traceback"}, atomically.

        Args:
            path: the JSON file; its directory is created when missing.

        Returns:
            The path written.
        """
        failures = [asdict(f) for f in self.failures]
        return write_text_atomically(Path(path), json.dumps(failures, indent=1, default=_json_default) + "\n")


@dataclass(frozen=True)
class _Outcome:
    """What a job sends back: its row, or why there is none."""

    row: dict[str, Any] | None
    error: str = ""
    traceback: str = ""


def _run_job(fn: Callable[..., Mapping[str, Any]], params: dict[str, Any], threads: int) -> _Outcome:
    """Run one job inside a Ray worker; its exceptions come back as data, with their traceback."""
    if importlib.util.find_spec("torch") is not None:
        import torch

        # torch would otherwise use every core of the node, whatever the job reserved.
        torch.set_num_threads(threads)
    try:
        row = fn(**params)
        if not isinstance(row, Mapping):
            raise TypeError(f"the job returned {type(row).__name__}, not a mapping (one row)")
        return _Outcome(dict(row))
    except Exception as err:
        return _Outcome(None, _describe(err), traceback.format_exc())


@contextmanager
def ray_session(address: str | None = None, workers: int | None = None) -> Iterator[float]:
    """Ray for the duration of the block: the one already initialized, a cluster, or a local one.

    A Ray this process already initialized is used as it is. Otherwise, with `address` (or RAY_ADDRESS)
    it connects to that cluster; without, it starts a local Ray whose servers listen on 127.0.0.1 only,
    with no dashboard and no usage reporting. What it started or connected to it shuts down at the end;
    the environment variables it set are put back then. Several sweeps in one block share one Ray start
    (about 4 s).

    Args:
        address: a cluster's address, "HOST:6379" (`ray start --head`), or "auto" for the one
            `ray start` runs on this machine; None: RAY_ADDRESS if set, else a local Ray.
        workers: local Ray only: the CPUs it may use (default os.cpu_count()); a cluster's nodes
            declare theirs (`ray start --num-cpus`).

    Yields:
        The CPUs the cluster offers.

    Raises:
        ValueError: `workers` is below 1, or given with a cluster.
    """
    import ray

    if workers is not None and workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    if ray.is_initialized():
        yield _cluster_cpus()
        return
    address = address or os.environ.get("RAY_ADDRESS") or None
    if address is not None and workers is not None:
        raise ValueError(
            f"workers={workers} applies to a local Ray only; the nodes of the cluster at {address} "
            "declare their CPUs (ray start --num-cpus)"
        )
    saved = {name: os.environ.get(name) for name in (*_LOCAL_ENV, *_RAY_SETS)}
    try:
        if address is not None:
            ray.init(address=address, logging_level=logging.WARNING)
        else:
            os.environ.update(_LOCAL_ENV)
            from ray._private import ray_constants

            # Read from the environment when ray is first imported, maybe before this call.
            cluster_switch = ray_constants.ENABLE_RAY_CLUSTER
            ray_constants.ENABLE_RAY_CLUSTER = False
            try:
                ray.init(
                    num_cpus=workers or os.cpu_count() or 1,
                    include_dashboard=False,
                    _node_ip_address="127.0.0.1",
                    logging_level=logging.WARNING,
                )
            finally:
                ray_constants.ENABLE_RAY_CLUSTER = cluster_switch
        yield _cluster_cpus()
    finally:
        ray.shutdown()
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def run_sweep(
    fn: Callable[..., Mapping[str, Any]],
    jobs: Sequence[Mapping[str, Any]],
    *,
    address: str | None = None,
    workers: int | None = None,
    cpus_per_job: float = 1.0,
    progress: bool = True,
    desc: str = "sweep",
) -> SweepResult:
    """Run `fn(**params)` for every job's params on Ray and gather the rows.

    Ray is the one this process initialized if any (left running), else as `ray_session` starts or
    connects to it (shut down at the end). Jobs are queued at once and run as CPUs free up, each with
    `cpus_per_job` CPUs reserved and torch limited to that many threads. A job that raises, returns
    something other than a mapping, or whose worker dies is not retried: it becomes a `JobFailure` and
    the sweep goes on.

    Args:
        fn: one job; called as fn(**params) in a Ray worker, returns one row. A function of an
            installed module, or of a script run as __main__ (sent by value).
        jobs: each job's params, e.g. {"method": "ppo", "seed": 3, "variant": "default"}.
        address: a cluster's address ("HOST:6379"); None: RAY_ADDRESS if set, else a local Ray
            started in-process, listening on 127.0.0.1 only.
        workers: local Ray only: the CPUs it may use (default os.cpu_count()).
        cpus_per_job: CPUs reserved per job (Ray's num_cpus); torch gets max(1, int(cpus_per_job))
            threads.
        progress: show a tqdm bar on stderr: jobs done / total, failures in its postfix.
        desc: the bar's label.

    Returns:
        The rows and failures, in job order, the wall time and the CPUs offered.

    Raises:
        ValueError: `cpus_per_job` is not positive or more than any node offers, or `workers` is bad
            (see ray_session).
    """
    import ray
    from ray.exceptions import RayError
    from tqdm import tqdm  # type: ignore[import-untyped,unused-ignore]

    if not cpus_per_job > 0:
        raise ValueError(f"cpus_per_job must be positive, got {cpus_per_job}")
    params = [dict(p) for p in jobs]
    with ray_session(address, workers) as cpus:
        # A job asking for more CPUs than any node has would wait forever.
        nodes = ray.nodes()  # type: ignore[no-untyped-call]
        node_cpus = max((n["Resources"].get("CPU", 0.0) for n in nodes if n["Alive"]), default=0.0)
        if cpus_per_job > node_cpus:
            raise ValueError(f"cpus_per_job={cpus_per_job} is more than any node offers ({node_cpus} CPUs)")
        task = ray.remote(_run_job).options(num_cpus=cpus_per_job, max_retries=0)
        threads = max(1, int(cpus_per_job))
        t0 = time.perf_counter()
        fn_ref = ray.put(fn)  # serialized once, not once per job
        outcomes: dict[int, _Outcome] = {}
        pending: dict[Any, int] = {}
        for i, p in enumerate(params):
            try:
                pending[task.remote(fn_ref, p, threads)] = i
            except Exception as err:  # params that cannot be serialized
                outcomes[i] = _Outcome(None, _describe(err), traceback.format_exc())
        failed = sum(1 for o in outcomes.values() if o.row is None)
        with tqdm(total=len(params), desc=desc, file=sys.stderr, disable=not progress) as bar:
            bar.update(len(outcomes))
            bar.set_postfix(failed=failed)
            try:
                while pending:
                    (ref,), _ = ray.wait(list(pending), num_returns=1)
                    i = pending.pop(ref)
                    try:
                        outcomes[i] = ray.get(ref)
                    except RayError as err:  # the worker died, or Ray could not run the task
                        outcomes[i] = _Outcome(None, _describe(_cause(err)), str(err))
                    failed += outcomes[i].row is None
                    bar.update(1)
                    bar.set_postfix(failed=failed)
            except BaseException:
                for ref in pending:  # on a shared cluster they would run on after an interrupt
                    ray.cancel(ref, force=True)
                raise
        wall_s = time.perf_counter() - t0
    rows, failures = [], []
    for i, p in enumerate(params):
        outcome = outcomes[i]
        if outcome.row is None:
            failures.append(JobFailure(p, outcome.error, outcome.traceback))
        else:
            rows.append({**p, **outcome.row})
    return SweepResult(rows, failures, wall_s, cpus, tuple(dict.fromkeys(k for p in params for k in p)))


def _cluster_cpus() -> float:
    """The CPUs the connected Ray cluster offers, all nodes together."""
    import ray

    return float(ray.cluster_resources().get("CPU", 0.0))  # type: ignore[no-untyped-call]


def _describe(err: BaseException) -> str:
    """'ValueError: boom'; the first line only of a long message."""
    message = str(err).strip().splitlines()
    return f"{type(err).__name__}: {message[0]}" if message else type(err).__name__


def _cause(err: BaseException) -> BaseException:
    """The job's own exception inside Ray's wrapper (RayTaskError), else Ray's error itself."""
    cause = getattr(err, "cause", None)
    return cause if isinstance(cause, BaseException) else err


def _cell(value: Any) -> Any:
    """A CSV cell: scalars as they are, None as empty, the rest as JSON."""
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    return json.dumps(value, default=_json_default)


def _json_default(value: Any) -> Any:
    """Arrays and numpy scalars as lists and numbers; anything else as its str."""
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    return str(value)
