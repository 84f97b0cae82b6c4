"""The quantitative statements of thesis chapters 4-6 that the model can check: the value and
its line in the thesis (/work/shared/thesis, LaTeX line numbers), how the value is computed
now, the tolerance, and -- where the project deliberately differs (MODEL_NOTES) -- the note and
which reading reproduces the thesis.

Checks: ``rel`` |computed - thesis| <= tol |thesis|; ``abs`` |computed - thesis| <= tol;
``>`` / ``<`` computed beyond the thesis's bound (statements such as "over 130 times",
"all eigenvalues have negative real parts").  Tolerances are set by what the thesis's own
wording allows ("approximately", two significant digits), never widened to make a row agree.
A section computes each value with settings that do not depend on --quick (a targeted solve,
not a coarse grid), so a quick and a full report give the same verdicts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

THESIS = "../shared/thesis/000_bf4d7f0361c98477.txt"
AS_IMPLEMENTED = "as implemented"
THESIS_READING = "thesis reading"


@dataclass(frozen=True)
class Statement:
    id: str
    section: str      # the reproduce section that computes it
    line: int         # line of the thesis file
    text: str         # what the thesis says (shortened)
    thesis: float     # the stated value (or bound)
    unit: str
    how: str          # how the value is computed now
    check: str = "rel"
    tol: float = 0.05
    note: str = ""    # MODEL_NOTES: why the project differs, both readings shown
    decides: str = AS_IMPLEMENTED  # the reading whose value is judged against the thesis

    def judge(self, value):
        """True when ``value`` agrees with the statement."""
        if value is None or not math.isfinite(value):
            return False
        if self.check == "rel":
            return abs(value - self.thesis) <= self.tol * abs(self.thesis)
        if self.check == "abs":
            return abs(value - self.thesis) <= self.tol
        if self.check == ">":
            return value > self.thesis
        if self.check == "<":
            return value < self.thesis
        raise ValueError(f"statement {self.id}: unknown check {self.check!r}")

    @property
    def stated(self):
        """The thesis value as text, with the check's form ('> 130', '60 +/- 2 %')."""
        v = f"{self.thesis:.4g}"
        if self.check in (">", "<"):
            return f"{self.check} {v}"
        tol = f"{self.tol * 100:g} %" if self.check == "rel" else f"{self.tol:g}"
        return f"{v} (tol. {tol})"


def S(*args, **kw):
    return Statement(*args, **kw)


STATEMENTS = [
    # ------------------------------------------------------------------ chapter 4 ----------
    S("ch4.set_point", "ch4_steady", 670,
      "set point r = 60 um at P = 60 mmHg, active, no flow (Kuo91)", 60.0, "um",
      "operating point of netlists/isolated_arteriole.yaml (kuo91) at Pup = Pdown = 60 mmHg", "rel", 0.02),
    S("ch4.plateau", "ch4_steady", 749,
      "active autoregulation: radius does not rise with P over the active range (Kuo91, no flow)", 0.0, "um",
      "r(120 cmH2O) - r(60 cmH2O) on the active no-flow curve", "<"),
    S("ch4.flow_dilates", "ch4_steady", 749,
      "flow significantly reduces the myogenic constriction (Kuo91, dP = 4 cmH2O)", 3.0, "um",
      "smallest radius difference (with flow - without) over P = 20..140 cmH2O", ">"),
]

BY_ID = {s.id: s for s in STATEMENTS}


def for_section(key):
    return [s for s in STATEMENTS if s.section == key]


class Row:
    """One row of the table: the statement, the values computed now per reading, the verdict."""

    def __init__(self, st, values, ran, failed):
        self.st, self.values = st, dict(values or {})
        decisive = self.values.get(st.decides)
        if not ran:
            self.verdict, self.kind = "not run (--only)", "skip"
        elif failed and decisive is None:
            self.verdict, self.kind = "not computed: section failed", "fail"
        elif decisive is None:
            self.verdict, self.kind = "not computed", "fail"
        elif st.judge(decisive):
            self.verdict, self.kind = "agrees", "ok"
        else:
            self.verdict, self.kind = "differs", "bad"
        if st.note and self.kind in ("ok", "bad"):
            other = [r for r in self.values if r != st.decides]
            if other:
                o = self.values[other[0]]
                self.verdict += f" ({st.decides}); {other[0]}: {'agrees' if st.judge(o) else 'differs'} - MODEL_NOTES"
            else:
                self.verdict += " - MODEL_NOTES"

    @property
    def value(self):
        return self.values.get(self.st.decides)

    @property
    def rel_diff(self):
        v = self.value
        if v is None or self.st.check in (">", "<") or self.st.thesis == 0:
            return None
        return (v - self.st.thesis) / abs(self.st.thesis)


def evaluate(runs):
    """Rows for every statement, given {section key: SectionRun}."""
    rows = []
    for st in STATEMENTS:
        run = runs.get(st.section)
        ran = run is not None and run.status != "not run"
        values = run.ctx.values.get(st.id, {}) if ran and run.ctx is not None else {}
        rows.append(Row(st, values, ran, ran and run.status == "failed"))
    return rows
