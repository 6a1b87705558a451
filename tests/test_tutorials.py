"""Every tutorial in docs/tutorials runs as written and produces the figures it shows (one that says
``<!-- slow: ... -->`` in `make test-all`)."""

from __future__ import annotations

import pytest

from docgen import DOCS, run_tutorial, tutorial_missing, tutorial_paths, tutorial_slow


def test_there_are_tutorials():
    assert len(tutorial_paths()) >= 4


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if tutorial_slow(p) else p
                                  for p in tutorial_paths()], ids=lambda p: p.stem)
def test_tutorial_runs(path, tmp_path):
    why = tutorial_missing(path)
    if why:
        pytest.skip(why)
    figures = run_tutorial(path, tmp_path)
    for produced, committed in figures:
        assert produced.stat().st_size > 1000
        assert committed.exists(), f"{committed.name} missing: run `make docs`"
        assert f"../figures/{committed.name}" in path.read_text(encoding="utf-8")


def test_tutorial_figures_are_referenced():
    index = (DOCS / "tutorials" / "README.md").read_text(encoding="utf-8")
    for path in tutorial_paths():
        assert path.name in index, f"{path.name} not listed in docs/tutorials/README.md"


def test_tutorials_run_where_make_demo_installs(tmp_path):
    """The tutorials' and the README's Python run in the environment of ``make demo`` (the
    ``[demo]`` extra): tools/tutorial_env.py blocks every module that install would lack, so a
    tutorial that needs one (pandas, before it joined ``[demo]``) fails here with "No module
    named ..." as it would for a user. Checked on what the blocker refuses and lets through."""
    from tutorial_env import PythonRunner, blocked_modules, env_with_blocker

    demo = set(blocked_modules(["demo"]))
    assert {"sklearn", "geopandas", "pytest", "dask"} & set(
        __import__("importlib").metadata.packages_distributions()) <= demo
    assert not demo & {"pandas", "matplotlib", "pyarrow", "shapely", "mcap", "numpy"}
    assert "sklearn" not in blocked_modules(["demo", "fit"])
    import os

    env = env_with_blocker(dict(os.environ), sorted(demo | {"pandas"}), tmp_path / "env")
    py = PythonRunner(env, tmp_path, tmp_path / "env")
    try:
        assert py.run("import pyarrow as pa\nx = pa.table({'a': [1]})", "b1") is None
        assert "No module named 'pandas'" in py.run("# continues the block above\n"
                                                   "x.to_pandas()", "b2")
        assert "NameError: name 'x'" in py.run("x.to_pandas()", "b3")  # a fresh namespace
        assert py.run("import importlib.util\n"
                      "assert importlib.util.find_spec('pandas') is None\n"
                      "assert importlib.util.find_spec('pyarrow') is not None", "b4") is None
    finally:
        py.close()


def test_readme_python_runs_where_make_demo_installs(tmp_path):
    """Each Python block of the README runs as written, on its own, in the ``[demo]`` environment
    (``rec.states.to_pandas()`` included), on a sample recording and map under the names it uses."""
    import os
    import re

    from helpers_common import ROOT, STRAIGHT_MAP
    from tutorial_env import PythonRunner, blocked_modules, env_with_blocker

    from aveas_format.sample import highway_scene

    highway_scene(n_vehicles=8, duration_s=12.0, seed=2).write(tmp_path / "highway.aveas")
    (tmp_path / "site.xodr").write_bytes(STRAIGHT_MAP.read_bytes())
    blocks = re.findall(r"^```python\n(.*?)^```", (ROOT / "README.md").read_text(encoding="utf-8"),
                        re.S | re.M)
    assert any("to_pandas()" in b for b in blocks)
    env = env_with_blocker(dict(os.environ), blocked_modules(["demo"]), tmp_path / "env")
    py = PythonRunner(env, tmp_path, tmp_path / "env")
    try:
        for k, block in enumerate(blocks, 1):
            assert py.run(block, f"README.md, Python block {k}") is None
    finally:
        py.close()
    assert (tmp_path / "copy.aveas.zip").exists()
