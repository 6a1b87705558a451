"""A small synthetic dataset shared by the dataset tests (built once per session)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

#: (relative path, partner, method, road_type, seed, derived)
LAYOUT = [
    ("kit/a1.aveas", "KIT", "aerial", "motorway", 1, True),
    ("kit/a2.aveas.zip", "KIT", "aerial", "motorway", 2, True),
    ("kit/u1.aveas", "KIT", "aerial", "urban", 3, False),
    ("tub/v1.aveas", "TUB", "road_vehicle", "motorway", 4, True),
    ("tub/v2.aveas", "TUB", "road_vehicle", "rural", 5, False),
]


def _set_meta(path: Path, partner: str, method: str, road_type: str) -> None:
    """Re-label a written directory recording (recording.json is not part of any checksum)."""
    p = path / "recording.json"
    meta = json.loads(p.read_text())
    meta["acquisition"]["partner"] = partner
    meta["acquisition"]["method"] = method
    meta["acquisition"]["site"]["road_type"] = road_type
    meta["recording_id"] = path.name.split(".")[0]
    p.write_text(json.dumps(meta, indent=2))


def build_dataset(root: Path, layout=LAYOUT) -> dict[str, Path]:
    import aveas_format
    from aveas_format.derive import derive
    from aveas_format.sample import highway_scene

    out = {}
    for rel, partner, method, road_type, seed, derived in layout:
        rec = highway_scene(6, 8.0, rate_hz=10.0, length_m=400.0, seed=seed)
        if derived:
            derive(rec)
        target = root / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = root / "_tmp" / (Path(rel).name.split(".")[0] + ".aveas")
        tmp.parent.mkdir(parents=True, exist_ok=True)
        rec.write(tmp, overwrite=True)
        _set_meta(tmp, partner, method, road_type)
        if rel.endswith(".zip"):
            aveas_format.open(tmp).write(target)
        else:
            shutil.copytree(tmp, target)
        out[rel] = target
    shutil.rmtree(root / "_tmp")
    return out


@pytest.fixture(scope="session")
def dataset_root(tmp_path_factory) -> Path:
    """5 valid recordings of 2 partners under kit/ and tub/ (read-only: copy before changing)."""
    root = tmp_path_factory.mktemp("dataset") / "archive"
    build_dataset(root)
    return root


@pytest.fixture
def broken_dataset(tmp_path, dataset_root) -> Path:
    """The dataset plus a recording with findings and a file that is not a recording at all."""
    root = tmp_path / "archive"
    shutil.copytree(dataset_root, root)
    meta_p = root / "tub" / "v2.aveas" / "recording.json"
    meta = json.loads(meta_p.read_text())
    meta["tables"]["states"]["rows"] = 1  # structure.row_count: an error
    meta_p.write_text(json.dumps(meta))
    (root / "tub" / "corrupt.aveas.zip").write_bytes(b"this is not a zip archive")
    return root
