"""docs/tutorial.md's code runs: its python blocks, in order, in one namespace, in a scratch
folder that sees the repository's netlists."""
import os
import re

from paths import ROOT


def blocks():
    text = (ROOT / "docs" / "tutorial.md").read_text(encoding="utf-8")
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def test_tutorial_has_the_promised_steps():
    code = "\n".join(blocks())
    for step in ("operating_point", "dc_sweep", "compare_sweep", "frequency_response", "Result.load"):
        assert step in code


def test_tutorial_code_runs(tmp_path, monkeypatch):
    (tmp_path / "netlists").symlink_to(ROOT / "netlists")
    monkeypatch.chdir(tmp_path)
    ns = {"__name__": "tutorial"}
    for k, block in enumerate(blocks()):
        exec(compile(block, f"docs/tutorial.md block {k + 1}", "exec"), ns)
    for png in ("sweep.png", "compare.png", "bode.png"):
        assert os.path.getsize(png) > 10_000
    assert ns["fr"].n_rows == 4
