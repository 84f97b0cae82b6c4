"""The one input policy (hemocircuit.inputs) and output policy (hemocircuit.io) as the command
line meets them: result files re-run as data (show --rerun), provenance that lists only what
was loaded, special files never read or replaced, clear errors for names no file can have."""
import json
import os
import stat

import pytest

import hemocircuit as hc
from hemocircuit import inputs, io
from hemocircuit.cli import main
from hemocircuit.errors import HemocircuitError, NetlistError
from hemocircuit.results import Result

from guards import deadline
from paths import NETLISTS

BASE_RC = NETLISTS / "base_rc.yaml"
RC = """name: rc
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 80 mmHg}
  - {id: R1, type: resistor, nodes: [in, a], R: 2 mmHg*s/mL}
  - {id: C1, type: compliance, nodes: [a, ground], C: 0.5 mL/mmHg}
"""


@pytest.fixture
def project(tmp_path):
    """A project folder (pyproject.toml marks it) with the RC netlist, and a folder outside it."""
    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "pyproject.toml").write_text("")
    (proj / "rc.yaml").write_text(RC)
    outside = tmp_path / "outside"
    outside.mkdir()
    return proj, outside


def _result_with_argv(path, argv, cwd):
    """A result file as a colleague might send it: a real op result whose stored command line
    is ``argv`` (run in ``cwd``)."""
    res = hc.load(str(BASE_RC)).operating_point()
    res.metadata.setdefault("provenance", {}).update({"argv": argv, "cwd": str(cwd)})
    res.save(path)
    return path


# ---------------------------------------------------------------- show --rerun ----------
def test_rerun_drops_abbreviated_and_unlisted_output_options(project, capsys):
    proj, outside = project
    victim = outside / "victim.png"
    victim.write_text("keep me")
    series = outside / "series.csv"
    src = _result_with_argv(proj / "a.csv", ["op", "rc.yaml", f"--plo={victim}", "--out", str(outside / "x.csv")],
                            proj)
    new = proj / "b.csv"
    assert main(["show", str(src), "--rerun", str(new)]) == 0
    err = capsys.readouterr().err
    assert victim.read_text() == "keep me"  # '--plo=' is --plot: dropped, not passed on
    assert not (outside / "x.csv").exists() and not series.exists()
    assert "dropped the stored --plot (an output file)" in err and "dropped the stored --out" in err
    assert Result.load(new)["P(a)"][0] == pytest.approx(80.0)


def test_rerun_never_uses_a_stored_allow_path_or_scheduler(project, capsys):
    proj, outside = project
    (outside / "rc.yaml").write_text(RC)
    src = _result_with_argv(proj / "a.csv", ["op", str(outside / "rc.yaml"), "--allow-path", "/"], proj)
    assert main(["show", str(src), "--rerun", str(proj / "b.csv")]) == 2 and not (proj / "b.csv").exists()
    err = capsys.readouterr().err
    assert "outside the allowed folders" in err and "--allow-path" in err
    # the reader may allow the folder on their own command line
    assert main(["show", str(src), "--rerun", str(proj / "b.csv"), "--allow-path", str(outside)]) == 0
    assert "dropped the stored --allow-path (a folder permission)" in capsys.readouterr().err
    # a stored scheduler address is dropped: the grid runs on local processes, no connection made
    src2 = _result_with_argv(proj / "c.csv", ["freq", "rc.yaml", "--freq", "0.01:0.1Hz", "--scheduler",
                                              "tcp://127.0.0.1:9"], proj)
    from hemocircuit.cli import RESULT_COMMANDS, build_parser
    from hemocircuit.rerun import rerun_argv
    argv, notes = rerun_argv(Result.load(src2).metadata, str(src2), str(proj / "d.csv"),
                             lambda c: build_parser(c).commands[c], RESULT_COMMANDS)
    assert not any("scheduler" in a or "tcp://" in a for a in argv)
    assert any("--scheduler (a network address)" in n for n in notes)


def test_rerun_does_not_enter_the_stored_folder_and_says_what_it_runs(project, capsys):
    proj, _ = project
    src = _result_with_argv(proj / "a.csv", ["op", "rc.yaml"], proj / "gone")
    here = os.getcwd()
    assert main(["show", str(src), "--rerun", str(proj / "b.csv")]) == 2  # rc.yaml is not in proj/gone
    assert os.getcwd() == here
    assert "does not exist" in capsys.readouterr().err
    src = _result_with_argv(proj / "a.csv", ["op", "rc.yaml", "--set", "R1.R=4mmHg*s/mL"], proj)
    assert main(["show", str(src), "--rerun", str(proj / "b.csv")]) == 0
    out = capsys.readouterr().out
    assert f"re-running: hemocircuit op {proj / 'rc.yaml'} '--set=R1.R=4mmHg*s/mL' --out {proj / 'b.csv'}" in out


def test_rerun_refuses_commands_that_are_not_one_analysis(project, capsys):
    proj, _ = project
    src = _result_with_argv(proj / "a.csv", ["import-svzerod", "m.json", "-o", "/etc/passwd"], proj)
    assert main(["show", str(src), "--rerun", str(proj / "b.csv")]) == 2
    assert "cannot be re-run" in capsys.readouterr().err


def test_show_on_malformed_provenance_is_a_clear_error(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("# provenance: [1, 2]\nx [s]\n1\n")
    assert main(["show", str(bad)]) == 2
    assert "not a mapping" in capsys.readouterr().err


# ---------------------------------------------------------------- provenance ----------
def test_provenance_lists_only_what_the_loader_read(project, tmp_path):
    proj, outside = project
    secret = outside / "secret.txt"
    secret.write_text("do not read")
    (proj / "n.yaml").write_text(RC.replace("name: rc\n", "name: rc\nderived: {x: {expr: 'P(a) * 2', unit: mmHg, "
                                                          f"notes: {{file: {secret}}}}}}}\n"))
    out = proj / "o.json"
    assert main(["op", str(proj / "n.yaml"), "--out", str(out)]) == 0
    prov = json.loads(out.read_text())["metadata"]["provenance"]
    assert prov["netlist_files"] == [str(proj / "n.yaml")]
    src = inputs.Sources()
    src.add(str(proj / "n.yaml"), (proj / "n.yaml").read_bytes())
    assert prov["netlist_sha256"] == src.sha256()


# ---------------------------------------------------------------- special files ----------
def test_special_input_files_are_refused_without_blocking(project):
    proj, _ = project
    fifo = proj / "pipe.yaml"
    os.mkfifo(fifo)
    (proj / "child.yaml").write_text("extends: pipe.yaml\n")
    with deadline(20):
        with pytest.raises(NetlistError, match="not a regular file"):
            hc.load(str(proj / "child.yaml"))
        with pytest.raises(NetlistError, match="not a regular file"):
            hc.load("/dev/zero")
        with pytest.raises(NetlistError, match="NUL"):
            hc.load("rc\x00.yaml")


def test_latin1_input_names_the_file_and_the_fix(project):
    proj, _ = project
    (proj / "l.yaml").write_bytes(RC.replace("name: rc", "name: r\xe9sistance").encode("latin-1"))
    with pytest.raises(NetlistError, match=r"not UTF-8 text \(byte 0xe9 on line 1\); save it as UTF-8"):
        hc.load(str(proj / "l.yaml"))


def test_out_never_replaces_a_device_or_fifo(project, capsys):
    proj, _ = project
    for target in ("/dev/null", str(proj / "fifo.csv")):
        if target.endswith("fifo.csv"):
            os.mkfifo(target)
        assert main(["op", str(proj / "rc.yaml"), "--out", target]) == 2
        assert "not a regular file" in capsys.readouterr().err
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode) and stat.S_ISFIFO(os.stat(proj / "fifo.csv").st_mode)


def test_out_through_a_link_only_inside_the_folder(project, capsys):
    proj, outside = project
    far = outside / "far.json"
    far.write_text("{}")
    (proj / "link.json").symlink_to(far)
    assert main(["op", str(proj / "rc.yaml"), "--out", str(proj / "link.json")]) == 2
    assert "outside the output folder" in capsys.readouterr().err and far.read_text() == "{}"
    near = proj / "near.json"
    near.write_text("{}")
    (proj / "ok.json").symlink_to("near.json")
    assert main(["op", str(proj / "rc.yaml"), "--out", str(proj / "ok.json")]) == 0
    assert os.path.islink(proj / "ok.json") and "metadata" in near.read_text()  # the link kept, its file written


def test_outputs_get_the_usual_mode(project):
    proj, _ = project
    old = os.umask(0o022)
    try:
        assert main(["op", str(proj / "rc.yaml"), "--out", str(proj / "o.json")]) == 0
        assert main(["dc", str(proj / "rc.yaml"), "--sweep", "Ps.value=10,20mmHg", "--plot", str(proj / "p.png")]) == 0
    finally:
        os.umask(old)
    for f in ("o.json", "p.png"):
        assert stat.S_IMODE(os.stat(proj / f).st_mode) == 0o644


@pytest.mark.parametrize("flag, value, message", [
    ("--out", "", "an empty file name"),
    ("--plot", "p.txt", ".txt is not a figure format"),
    ("--out", "a\x00b.csv", "NUL byte"),
])
def test_bad_output_names_are_clear_errors_before_computing(project, capsys, flag, value, message):
    proj, _ = project
    args = ["dc", str(proj / "rc.yaml"), "--sweep", "Ps.value=10,20mmHg", flag, value if "\x00" in value or not value
            else str(proj / value)]
    assert main(args) == 2
    assert message in capsys.readouterr().err


def test_writer_refuses_a_device_even_through_the_api(tmp_path):
    with pytest.raises(HemocircuitError, match="not a regular file"):
        io.atomic_write("/dev/null", "x")


def test_reproduce_out_on_a_file_is_a_clear_error(tmp_path, capsys):
    f = tmp_path / "report"
    f.write_text("")
    assert main(["reproduce", "--quick", "--only", "ch4_lee97", "--out", str(f)]) == 2
    assert "exists and is not a folder" in capsys.readouterr().err
