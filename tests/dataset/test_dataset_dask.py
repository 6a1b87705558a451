"""Datasets on a real Dask cluster: a distributed.LocalCluster with 2 worker processes."""

from __future__ import annotations

from pathlib import Path

import pytest

from aveas_format import dataset as ds

from helpers_dataset import validate_or_crash

distributed = pytest.importorskip("distributed")
dask = pytest.importorskip("dask")


@pytest.fixture(scope="module")
def scheduler():
    # a task that kills its worker is given up after its second dead worker (default: 4)
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster:
            yield cluster.scheduler_address


def test_validate_on_a_local_cluster_finds_what_the_dataset_holds(scheduler, broken_dataset):
    """The broken dataset's known contents, found on the cluster: five recordings of which one
    (tub/v2) has the one error planted in it (a wrong row count), and a file that is no recording
    at all, failed with the reader's error; the exit code is the worst (3)."""
    paths = ds.discover(broken_dataset)
    rep = ds.validate_dataset(paths, scheduler=scheduler)
    assert rep.exit_code() == 3 and rep.recordings == 6
    assert [Path(f.path).name for f in rep.failed] == ["corrupt.aveas.zip"]
    assert "RecordingIOError" in rep.failed[0].error and rep.failed[0].traceback
    findings = {Path(e.path).name: [(r.code, r.count) for r in e.rules if r.severity == "error"]
                for e in rep.entries}
    assert len(findings) == 5 and findings.pop("v2.aveas") == [("structure.row_count", 1)]
    assert all(not f for f in findings.values()), findings
    assert rep.to_dict()["runner"]["scheduler"] == scheduler


def test_a_recording_that_kills_its_dask_worker_is_reported_and_the_rest_complete(
        scheduler, dataset_root, tmp_path):
    paths = ds.discover(dataset_root)
    poison = tmp_path / "poison.aveas"
    poison.mkdir()
    rep = ds.validate_dataset([*paths, str(poison)], scheduler=scheduler, task=validate_or_crash)
    assert [f.path for f in rep.failed] == [str(poison)]
    assert "worker process died" in rep.failed[0].error
    assert sorted(e.path for e in rep.entries) == sorted(paths)
    # the cluster recovered (the nannies restarted the workers): the next run is complete
    table = ds.catalog(paths, scheduler=scheduler, validate=False)
    assert table.num_rows == 5 and table.column("read_error").null_count == 5
    speeds = ds.per_vehicle_stats(paths, "mean_speed", filters={"partner": "TUB"},
                                  scheduler=scheduler)
    assert set(speeds.column("recording_id").to_pylist()) == {"v1", "v2"}
    assert all(Path(p).exists() for p in paths)


def test_cli_on_a_scheduler(scheduler, dataset_root):
    import json
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-m", "aveas_format", "validate", str(dataset_root),
                          "--scheduler", scheduler, "--format", "json"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    d = json.loads(res.stdout)
    assert d["recordings"] == 5 and d["valid"] == 5 and d["runner"]["scheduler"] == scheduler
