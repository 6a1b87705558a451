"""Generated reference docs are in sync with the code."""

from __future__ import annotations

import pytest

from docgen import generated


@pytest.mark.parametrize("path,text", list(generated().items()), ids=lambda v: getattr(v, "name", ""))
def test_generated_doc_is_up_to_date(path, text):
    assert path.exists(), f"{path} missing: run `make docs`"
    assert path.read_text(encoding="utf-8") == text, f"{path.name} is stale: run `make docs`"


def test_readme_build_recording_example_states_what_only_a_person_knows(tmp_path, monkeypatch):
    """The README's ``build_recording`` example runs as written (on the straight test map) and
    gives a valid recording without the warnings of stand-in metadata (partner, start time,
    licence); what remains are the data's own (no uncertainty, no coverage), which it names."""
    import re

    from helpers_common import ROOT, STRAIGHT_MAP

    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    block = next(b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "build_recording(" in b)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "site.xodr").write_bytes(STRAIGHT_MAP.read_bytes())
    ns: dict = {}
    exec(compile(block, "README.md", "exec"), ns)  # noqa: S102 - the README's own example
    report = ns["aveas_format"].validate(ns["rec"])
    codes = report.codes()
    assert report.counts["error"] == 0, codes
    assert not codes & {"metadata.start_time_implausible", "metadata.rights_unclear",
                        "metadata.partner_placeholder"}, codes
    assert "uncertainty.std_missing" in codes  # the data's own: said in the README's comment
