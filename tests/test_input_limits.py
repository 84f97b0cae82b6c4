"""Hostile and careless input (issue 9, input side): one test per fault found by fuzzing.
Each bad input gets a HemocircuitError naming the file (and element, limit or option) - no
traceback, no hang, no unbounded memory, no file contents from outside the allowed folders."""
import time

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.analyses.dc import parse_range
from hemocircuit.arguments import range_spacing, unit_spacing
from hemocircuit.cli import main
from hemocircuit.derived import evaluate_derived
from hemocircuit.errors import HemocircuitError, NetlistError

from paths import NETLISTS, PAYNE06, ROOT

RC = """
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 80 mmHg}
  - {id: R1, type: resistor, nodes: [in, a], R: 1 mmHg*s/mL}
  - {id: C1, type: log_compliance, nodes: [a, ground], k: 0.186 1/mL, P0: -2.25 mmHg, Vn: 28 mL}
"""
BUNDLED = ROOT / "netlists"


def _error(path, **kw):
    with pytest.raises(NetlistError) as ei:
        hc.load(str(path), **kw)
    return ei.value


# ------------------------------------------------------------------- input limits ----------
@pytest.mark.parametrize("doc", ["elements: " + "[" * 50000 + "]" * 50000 + "\n",
                                 "elements:\n" + "".join("  " * i + "- \n" for i in range(300))])
def test_deeply_nested_yaml_is_refused(write, doc):
    p = write(doc)
    e = _error(p)
    assert e.file == str(p) and "nested" in str(e) and "HEMOCIRCUIT_MAX_YAML_DEPTH" in str(e)


def test_long_expressions_are_refused_before_parsing(write):
    p = write(RC.replace("R: 1 mmHg*s/mL", 'R: "= ' + "+".join(["1"] * 20000) + '"'))
    e = _error(p)
    assert "HEMOCIRCUIT_MAX_VALUE_CHARS" in str(e) and e.file == str(p)
    # within the length limit, the number of terms is limited (compiling recursed on ~3000)
    p = write(RC.replace("R: 1 mmHg*s/mL", 'R: "= ' + "-" * 4000 + '1 * R0"').replace(
        "elements:", "parameters: {R0: 1 mmHg*s/mL}\nelements:"))
    e = _error(p)
    assert e.element == "R1" and "HEMOCIRCUIT_MAX_EXPR" in str(e)


@pytest.mark.parametrize("scale, fragment", [("abc", "must be a number"), ("nan", "out of range"),
                                             (".inf", "out of range"), ("0", "out of range"),
                                             ("-1e-12", "out of range"), ("[1]", "must be a number")])
def test_tracer_pool_scale_is_checked_like_a_parameter(write, scale, fragment):
    p = write(f"extends: {BUNDLED / 'payne06_no_transport.yaml'}\nchange:\n  NOv: {{scale: {scale}}}\n")
    e = _error(p)
    assert e.element == "NOv" and "option 'scale'" in str(e) and fragment in str(e), str(e)
    assert e.file == str(p)


def test_scale_written_as_yaml_string_is_a_number(write):
    p = write(f"extends: {BUNDLED / 'payne06_no_transport.yaml'}\nchange:\n  NOv: {{scale: 1e-20}}\n")
    c = hc.load(str(p))
    assert c.elements["NOv"].opts["scale"] == 1e-20


def test_doubling_and_cyclic_parameters_are_refused(write):
    lines = ["parameters:", "  p0: 1 mmHg"] + [f"  p{i}: ${{p{i - 1}}} + ${{p{i - 1}}}" for i in range(1, 60)]
    p = write("\n".join(lines) + "\n" + RC.replace("value: 80 mmHg", "value: ${p59}"))
    t = time.perf_counter()
    e = _error(p)
    assert time.perf_counter() - t < 5
    assert "HEMOCIRCUIT_MAX_VALUE_CHARS" in str(e) and "parameter 'p" in str(e)
    p = write("parameters: {pa: '${pb}', pb: '${pc}', pc: '${pa}'}\n" + RC)
    assert "cycle: pa -> pb -> pc -> pa" in str(_error(p))
    # references in any order still work
    p = write("parameters: {pa: '${pb} * 2', pb: 40 mmHg}\n" + RC.replace("value: 80 mmHg", "value: ${pa}"))
    assert hc.load(str(p)).parameters.values["Ps.value"][0] == 80.0


def test_yaml_alias_bomb_is_refused(write):
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    p = write("\n".join(lines) + "\nelements: *a9\n")
    t = time.perf_counter()
    e = _error(p)
    assert time.perf_counter() - t < 5 and "alias" in str(e) and e.file == str(p)
    # a few aliases that expand to little are fine (then the netlist is judged on its own)
    p = write("x: &r 1 mmHg*s/mL\n" + RC)
    assert "unknown top-level key" in str(_error(p))


def test_huge_files_are_refused_and_the_limit_can_be_raised(write, monkeypatch):
    p = write(RC + "#" + "x" * (17 * 2 ** 20) + "\n")
    e = _error(p)
    assert "MiB" in str(e) and "HEMOCIRCUIT_MAX_FILE_MB" in str(e)
    monkeypatch.setenv("HEMOCIRCUIT_MAX_FILE_MB", "64")
    assert len(hc.load(str(p)).elements) == 3


def test_element_count_limit(write, monkeypatch):
    monkeypatch.setenv("HEMOCIRCUIT_MAX_ELEMENTS", "5")
    e = _error(PAYNE06)
    assert "8 elements" in str(e) and "HEMOCIRCUIT_MAX_ELEMENTS" in str(e)


def test_integer_powers_are_floats_in_expressions_and_derived(write):
    p = write(RC + "derived:\n  big: {expr: '9**9**9**9', unit: mmHg}\n")
    t = time.perf_counter()
    e = _error(p)
    assert time.perf_counter() - t < 5 and "derived quantity 'big'" in str(e)
    with pytest.raises(NetlistError, match="derived quantity 'x'"):
        evaluate_derived({"x": {"expr": "10**10**10**10 + P(a)"}}, {"P(a)": np.ones(3)})
    p = write(RC.replace("R: 1 mmHg*s/mL", 'R: "= 9**9**9**9 * R0"').replace(
        "elements:", "parameters: {R0: 1 mmHg*s/mL}\nelements:"))
    assert _error(p).element == "R1"


def test_extreme_log_compliance_gives_a_solver_error_not_linalgerror(write):
    for change in ("Cv: {k: 1e300 1/mL}", "Cv: {P0: 1e300 mmHg}"):
        p = write(f"extends: {BUNDLED / 'inertia.yaml'}\nchange:\n  {change}\n")
        with pytest.raises(HemocircuitError) as ei:
            hc.load(str(p)).operating_point()
        assert "Cv" in str(ei.value) or "node 'ic'" in str(ei.value)  # where it failed


# ---------------------------------------------------------------------------- paths ----------
@pytest.fixture
def outside(tmp_path_factory):
    """A secret file outside the netlist's folder (and outside any project)."""
    d = tmp_path_factory.mktemp("outside")
    secret = d / "secret.csv"
    secret.write_text("TOP-SECRET-LINE: do not print\n1,2\n")
    return secret


@pytest.mark.parametrize("form", ["extends: {abs}\n", "extends: ../{rel}\n",
                                  "%RC%".replace("%RC%", "") + "{rc_table}"])
def test_files_outside_the_allowed_folders_are_refused_unread(write, outside, form, capsys):
    rel = f"{outside.parent.name}/{outside.name}"
    rc_table = RC.replace("value: 80 mmHg", f"value: {{pwl: {{file: {outside}}}}}")
    p = write(form.format(abs=outside, rel="../" + rel, rc_table=rc_table), "proj/net.yaml")
    e = _error(p)
    assert "outside the allowed folders" in str(e) and "--allow-path" in str(e)
    assert "TOP-SECRET" not in str(e)
    assert main(["check", str(p)]) == 2
    assert "TOP-SECRET" not in capsys.readouterr().err


def test_etc_files_are_refused(write):
    for target in ("/etc/shadow", "/etc/passwd", "../../../../../../../etc/passwd"):
        e = _error(write(f"extends: {target}\n"))
        assert "outside the allowed folders" in str(e) and "root:" not in str(e)


def test_allow_path_lets_a_folder_in_and_errors_quote_only_an_excerpt(write, outside, capsys):
    rc_table = RC.replace("value: 80 mmHg", f"value: {{pwl: {{file: {outside}}}}}")
    p = write(rc_table, "proj/net.yaml")
    # allowed now: the file is read; its header has no [unit], the error quotes a short excerpt
    e = _error(p, allow_paths=[outside.parent])
    assert "must give each column's unit" in str(e) and "'TOP-SECRET-LINE: do not print,2'" not in str(e)
    assert len(str(e)) < 600
    assert main(["check", str(p), "--allow-path", str(outside.parent)]) == 2
    outside.write_text("time [s],value [mmHg]\n0,80\n10,90\n")
    assert main(["check", str(p), "--allow-path", str(outside.parent)]) == 0
    capsys.readouterr()


def test_project_root_and_bundled_netlists_are_allowed(write):
    write("[project]\n", "pyproject.toml")
    write(RC, "lib/base.yaml")
    v = write("extends: ../../lib/base.yaml\nchange: {R1: {R: 2 mmHg*s/mL}}\n", "models/variants/v.yaml")
    assert hc.load(str(v)).parameters.values["R1.R"][0] == 2.0
    v = write(f"extends: {BUNDLED / 'payne06_passive.yaml'}\nchange: {{Rla: {{R: 1 mmHg*s/mL}}}}\n", "b.yaml")
    assert hc.load(str(v)).parameters.values["Rla.R"][0] == 1.0


def test_table_file_from_a_parameter_is_checked(write, outside):
    p = write(f"parameters: {{f: {outside}}}\n" + RC.replace("value: 80 mmHg", "value: {pwl: {file: ${f}}}"),
              "proj/net.yaml")
    assert "outside the allowed folders" in str(_error(p))


def test_protocol_tables_are_relative_to_the_protocol_and_checked(write, outside, capsys):
    write("time [s],value [mmHg]\n0,70\n10,90\n", "proto/tables/pa.csv")
    pr = write("events:\n  - {at: 5 s, set: {Pa.value: {pwl: {file: tables/pa.csv}}}}\n", "proto/p.yaml")
    assert main(["check", str(PAYNE06), "--protocol", str(pr)]) == 0
    pr = write(f"events:\n  - {{at: 5 s, set: {{Pa.value: {{pwl: {{file: {outside}}}}}}}}}\n", "proto/p2.yaml")
    assert main(["check", str(PAYNE06), "--protocol", str(pr)]) == 2
    err = capsys.readouterr().err
    assert "outside the allowed folders" in err and "TOP-SECRET" not in err


# ------------------------------------------------------- protocol events at t = 0 ----------
def test_protocol_event_at_zero_applies_before_the_start(write, capsys):
    pr = write("events:\n  - {at: 0 s, set: {Pa.value: 90 mmHg}}\n  - {at: 5 s, set: {Pa.value: 70 mmHg}}\n",
               "p.yaml")
    from hemocircuit.loading import load_circuit
    c, proto = load_circuit(PAYNE06, protocol=pr)
    assert c.parameters.values["Pa.value"][0] == 90.0
    op90 = c.operating_point()
    # the same as setting it: P(in) is the source's value
    assert op90["P(in)"] == pytest.approx(90.0, abs=1e-9)
    base = hc.load(str(PAYNE06))
    res = base.simulate(1.0, dt=0.5, protocol=str(pr))
    assert res["P(in)"][0] == pytest.approx(90.0, abs=1e-9)
    assert main(["op", str(PAYNE06), "--protocol", str(pr)]) == 0
    out, err = capsys.readouterr()
    assert "1 later event(s)" in err


def test_event_times_must_be_finite_and_not_negative(write):
    from hemocircuit.protocol import Protocol
    c = hc.load(str(PAYNE06))
    for at in ("-1 s", ".nan", "1e999 s"):
        with pytest.raises(NetlistError, match="event 0 time"):
            Protocol.from_dict({"events": [{"at": at, "set": {"Pa.value": "90 mmHg"}}]}, "p.yaml", c)


# -------------------------------------------------------- CLI: --set, --show, --sweep ------
def test_sweep_values_keep_their_exponents():
    assert range_spacing("10,80,1e8,150 mmHg") == "10,80,1e8,150 mmHg"
    assert range_spacing("20:200:5mmHg") == "20:200:5 mmHg"
    assert range_spacing("1e-3:3e-3:1e-3s") == "1e-3:3e-3:1e-3 s"
    assert unit_spacing("1e300 1/mL") == "1e300 1/mL" and unit_spacing("90mmHg") == "90 mmHg"
    assert unit_spacing("1e8mmHg") == "1e8 mmHg"
    np.testing.assert_array_equal(parse_range(range_spacing("10,80,1e8,150 mmHg"), "mmHg"), [10, 80, 1e8, 150])
    np.testing.assert_allclose(parse_range("1e-3:3e-3:1e-3 s", "s"), [1e-3, 2e-3, 3e-3])
    for bad in ("0:1e9:1e-9 mmHg", "1e999:1:1 mmHg", ",,", "1e.e:1:1"):
        with pytest.raises(NetlistError):
            parse_range(bad, "mmHg")


def test_dc_show_unknown_column(capsys):
    assert main(["dc", str(PAYNE06), "--sweep", "Pa.value=60:80:10mmHg", "--show", "Q(Rxx)"]) == 2
    err = capsys.readouterr().err
    assert "--show 'Q(Rxx)'" in err and "did you mean" in err and "Traceback" not in err


@pytest.mark.parametrize("arg, fragments", [
    ("Rla.R=-1mmHg*s/mL", ["--set Rla.R=-1 mmHg*s/mL", "element 'Rla'", "not physical"]),
    ("Rlaa.R=1mmHg*s/mL", ["--set Rlaa.R", "no element 'Rlaa'", "did you mean 'Rla'"]),
    ("Rla.RR=1mmHg*s/mL", ["--set Rla.RR", "no parameter 'RR'", "did you mean 'Rla.R'"]),
])
def test_set_errors_name_the_set_option(arg, fragments, capsys):
    assert main(["check", str(PAYNE06), "--set", arg]) == 2
    err = capsys.readouterr().err
    for frag in fragments:
        assert frag in err, (frag, err)
    assert str(PAYNE06) not in err  # the netlist is not to blame


def test_errors_in_a_base_netlist_name_the_file_given(write, capsys):
    base = write(RC.replace("R: 1 mmHg*s/mL", "R: ${Rx}").replace("elements:", "parameters: {Rx: 1 mmHg*s/mL}\n"
                                                                  "elements:"), "base.yaml")
    v = write("extends: base.yaml\nparameters: {Rx: -1 mmHg*s/mL}\n", "variant.yaml")
    assert main(["check", str(v)]) == 2
    err = capsys.readouterr().err
    assert str(base) in err and str(v) in err and "extends chain" in err


# ----------------------------------------------------------------- did you mean --------
@pytest.mark.parametrize("change, fragment", [
    ("type: resistr", "did you mean 'resistor'"),
    ("RR: 1 mmHg*s/mL", "did you mean 'R'"),
])
def test_did_you_mean_in_netlists(write, change, fragment):
    p = write(RC.replace("R: 1 mmHg*s/mL", "R: 1 mmHg*s/mL, " + change) if "RR" in change
              else RC.replace("type: resistor", change))
    assert fragment in str(_error(p))


def test_did_you_mean_for_options_and_protocol_paths(write, capsys):
    p = write(RC.replace("Vn: 28 mL", "Vn: 28 mL, clamp_at_zero: maybe"))
    assert "option 'clamp_at_zero' must be true or false" in str(_error(p))
    pr = write("events:\n  - {at: 1 s, set: {Pa.valeu: 90 mmHg}}\n", "p.yaml")
    assert main(["check", str(PAYNE06), "--protocol", str(pr)]) == 2
    assert "did you mean 'Pa.value'" in capsys.readouterr().err


def test_waveform_fields_are_named(write):
    p = write(RC.replace("value: 80 mmHg", "value: {sine: {offset: 80 mmHg, amplitude: .inf, frequency: 1 Hz}}"))
    e = _error(p)
    assert e.element == "Ps" and "sine amplitude" in str(e)
    p = write(RC.replace("value: 80 mmHg", "value: {sine: {offset: 80 mmHg, frequncy: 1 Hz}}"))
    assert "did you mean 'frequency'" in str(_error(p))
    p = write(RC.replace("value: 80 mmHg", "value: {steps: [[0 s, 80 mmHg], [1 s, nan mmHg]]}"))
    assert "every value must be finite" in str(_error(p))


def test_table_file_in_a_constraint_is_checked(write, outside):
    base = (NETLISTS / "bad" / "store_only_node.yaml").read_text()
    p = write(base + f"constraints:\n  - {{node: ic, pressure: 10 mmHg, when: {{Pa.value: {{pwl: {{file: {outside}}}}}}}}}\n",
              "proj/net.yaml")
    e = _error(p)
    assert "outside the allowed folders" in str(e) and "TOP-SECRET" not in str(e)


def test_malformed_constraint_is_a_netlist_error(write):
    base = (NETLISTS / "bad" / "store_only_node.yaml").read_text()
    p = write(base + "constraints:\n  - {node: {pwl: [[0 s, 1 mmHg]]}, volume: 3 mL}\n")
    assert "each constraint is a mapping" in str(_error(p))


def test_alias_bomb_within_the_node_limit_is_not_expanded(write):
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 6)]
    p = write("\n".join(lines) + "\nelements: *a5\n")  # 9**6 = 531,441 values when expanded
    t = time.perf_counter()
    assert "unknown top-level key" in str(_error(p))
    assert time.perf_counter() - t < 3


def test_very_long_quantity_is_refused(write):
    p = write(RC.replace("R: 1 mmHg*s/mL", "R: " + "1" * 5000 + " mmHg*s/mL"))
    e = _error(p)
    assert e.element == "R1" and "HEMOCIRCUIT_MAX_QUANTITY_CHARS" in str(e)
