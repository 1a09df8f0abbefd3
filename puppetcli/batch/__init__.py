"""Many pose runs at once (``puppetcli batch``; docs/batch.md).

The Python API, for notebooks::

    from puppetcli.batch import Job, LocalPool, dask_pool, read_manifest, run
    rows = run(read_manifest(Path("jobs.yaml"), PoseOptions()), Path("out"))
    rows = run(jobs, Path("out"), dask_pool(client))   # a distributed.Client
"""

from puppetcli.batch.jobs import Job, read_manifest, sweep
from puppetcli.batch.run import LocalPool, dask_pool, run

__all__ = ["Job", "LocalPool", "dask_pool", "read_manifest", "run", "sweep"]
