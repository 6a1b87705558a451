"""Datasets: many recordings, processed one task per recording, locally or on a Dask cluster.

>>> from aveas_format import dataset
>>> paths = dataset.discover("archive/")                      # directories, globs, lists, file:// URLs
>>> rep = dataset.validate_dataset(paths, workers=4)          # or scheduler="tcp://host:8786"
>>> rep.exit_code(), rep.counts, rep.worst(3)
>>> table = dataset.catalog(paths, workers=4)                 # one row per recording (pyarrow.Table)
>>> speeds = dataset.per_vehicle_stats(paths, "mean_speed", filters={"road_type": "motorway"})

A dataset is a directory (searched recursively for ``NAME.aveas/`` directories holding a
``recording.json`` and for ``NAME.aveas.zip`` files), a glob, a single recording, or a list of
those; URLs are listed through pyarrow.fs and each remote recording is copied locally by the task
that processes it (docs/datasets.md).

Every batch operation maps a module-level task function over the recordings with
:func:`aveas_format.parallel.run_tasks`: results stream back as they finish, and a recording that
raises, or crashes its worker, becomes an entry with its error while the others complete. Only small,
picklable summaries travel back to the caller; per-recording reports can be written by the workers
themselves (``reports_dir``), so a dataset of thousands of recordings never sits in one process.

What lives where:

- :mod:`.discovery` — which recordings a spec names (``discover``, ``is_recording``,
  ``is_dataset_spec``), local copies of remote ones (``local_copy``), ``map_recordings``;
- :mod:`.report` — the typed entries (``RecordingEntry``, ``RuleCount``, ``FailedRecording``,
  ``RuleTotal``), their aggregate ``DatasetReport`` and ``run_dataset``;
- :mod:`.validation` — ``validate_recording`` / ``validate_dataset`` (``ValidationEntry``);
- :mod:`.derivation` — ``derive_recording`` / ``derive_dataset`` (``DerivationEntry``);
- :mod:`.conversion` — ``conversion_groups`` / ``convert_dataset`` (``ConversionEntry``);
- :mod:`.cataloging` — the catalog: ``catalog``, ``catalog_row``, ``catalog_schema``,
  ``write_catalog``;
- :mod:`.stats` — dataset-wide statistics: ``per_vehicle_stats`` over ``METRICS``;
- :mod:`.html` — ``render_dataset_html``, the dataset report as an HTML page.
"""

from aveas_format.dataset.cataloging import catalog, catalog_row, catalog_schema, write_catalog
from aveas_format.dataset.conversion import (
    ConversionEntry,
    conversion_groups,
    convert_dataset,
    convert_recording,
)
from aveas_format.dataset.derivation import (
    DerivationEntry,
    derive_dataset,
    derive_recording,
    output_path_for,
)
from aveas_format.dataset.discovery import (
    discover,
    is_dataset_spec,
    is_recording,
    local_copy,
    map_recordings,
)
from aveas_format.dataset.html import render_dataset_html
from aveas_format.dataset.report import (
    DatasetReport,
    FailedRecording,
    RecordingEntry,
    RuleCount,
    RuleTotal,
    ToolFailureSummary,
    run_dataset,
)
from aveas_format.dataset.stats import METRICS, per_vehicle_stats, per_vehicle_task
from aveas_format.dataset.validation import ValidationEntry, validate_dataset, validate_recording

__all__ = [
    "METRICS", "ConversionEntry", "DatasetReport", "DerivationEntry", "FailedRecording",
    "RecordingEntry", "RuleCount", "RuleTotal", "ToolFailureSummary", "ValidationEntry", "catalog",
    "catalog_row", "catalog_schema", "conversion_groups", "convert_dataset", "convert_recording",
    "derive_dataset", "derive_recording", "discover", "is_dataset_spec", "is_recording",
    "local_copy", "map_recordings", "output_path_for", "per_vehicle_stats", "per_vehicle_task",
    "render_dataset_html", "run_dataset", "validate_dataset", "validate_recording",
    "write_catalog",
]
