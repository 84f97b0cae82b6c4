"""docs/tutorial.md runs as written: its python blocks, in order, in one namespace, and its sh
commands, from a folder laid out like the repository (its netlists/), and everything it writes
lands in examples/out/tutorial/ (nothing in the repository's folder itself)."""
import os
import re
import shlex
import subprocess
import sys

import numpy as np

from paths import ROOT

OUT = os.path.join("examples", "out", "tutorial")


def blocks(lang="python"):
    text = (ROOT / "docs" / "tutorial.md").read_text(encoding="utf-8")
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def commands():
    """The sh blocks' commands (one per line; a trailing backslash continues it)."""
    out = []
    for block in blocks("sh"):
        out += [ln.strip() for ln in block.replace("\\\n", " ").splitlines() if ln.strip()]
    return out


def test_tutorial_has_the_promised_steps():
    code = "\n".join(blocks())
    for step in ("operating_point", "dc_sweep", "compare_sweep", "frequency_response", "Result.load"):
        assert step in code
    assert [c.split()[:2] for c in commands()] == [["hemocircuit", "compare"], ["hemocircuit", "freq"]]


def test_tutorial_runs_as_written_and_writes_only_its_output_folder(tmp_path, monkeypatch):
    (tmp_path / "netlists").symlink_to(ROOT / "netlists")
    monkeypatch.chdir(tmp_path)
    ns = {"__name__": "tutorial"}
    for k, block in enumerate(blocks()):
        exec(compile(block, f"docs/tutorial.md block {k + 1}", "exec"), ns)
    hemocircuit = os.path.join(os.path.dirname(sys.executable), "hemocircuit")
    for cmd in commands():
        argv = shlex.split(cmd)
        argv[0] = hemocircuit if os.path.exists(hemocircuit) else argv[0]
        run = subprocess.run(argv, capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, (cmd, run.stderr[-2000:])

    # nothing but the output folder was written beside the netlists
    assert sorted(os.listdir(tmp_path)) == ["examples", "netlists"]
    assert os.listdir(tmp_path / "examples") == ["out"]
    assert os.listdir(tmp_path / "examples" / "out") == ["tutorial"]
    written = set(os.listdir(tmp_path / OUT))
    assert {"sweep.csv", "sweep.png", "compare.png", "bode.png", "compare_cli.png", "freq.csv",
            "bode_cli.png"} <= written, written
    for png in ("sweep.png", "compare.png", "bode.png", "compare_cli.png", "bode_cli.png"):
        assert os.path.getsize(tmp_path / OUT / png) > 10_000

    # the physics the tutorial shows: cerebral flow within the autoregulation plateau, and the
    # slower Ca time constant turning the flow's lead at 0.1 Hz into a lag
    fr = ns["fr"]
    assert fr.n_rows == 4
    phase = {(tau, f): p for tau, f, p in zip(fr["art.tau_Ca"], fr["frequency"], fr["phase(Q(Rla)/Pa.value)"])}
    assert phase[(1.0, 0.1)] > 0 > phase[(10.0, 0.1)]
    import hemocircuit as hc
    cli = hc.Result.load(tmp_path / OUT / "freq.csv")
    assert "freq" in cli.metadata["analysis"] and set(np.round(cli["art.tau_Ca"], 6)) == {1.0, 10.0}
    gains = cli["rel_gain(Q(Rla)/Pa.value)"]
    assert np.all(np.isfinite(gains)) and np.all((gains > 0) & (gains < 5))
