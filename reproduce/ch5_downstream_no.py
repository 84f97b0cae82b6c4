"""Chapter 5, downstream NO (eqs. dcvdt, dctdt, cinv): venous and tissue NO at Pa = 80 mmHg in the
thesis's units reading (netlists/payne06_no_transport_thesis.yaml) and in the dimensionally
consistent model (payne06_no_transport.yaml), with r_db as fitted and reduced to r_dw
(MODEL_NOTES "Downstream NO"; docs/downstream_no.md)."""
from __future__ import annotations

import numpy as np

from .core import plt

TITLE = "Downstream transport of NO"
CHAPTER = 5
LABELS = ["eq. dcvdt, dctdt (no figure)"]


def run(ctx):
    out, rows = {}, []
    for reading, name in (("thesis reading", "payne06_no_transport_thesis"), ("as implemented", "payne06_no_transport")):
        c = ctx.load(name)
        for case in ("base", "rdb=rdw"):
            cc = c
            if case == "rdb=rdw":
                p = c.parameters.values
                cc = c.with_values({"art.r_db": float(p["art.r_dw"][0] * p["art.no_speed"][0])})
            op = cc.operating_point()
            out[reading, case] = op
            rows.append({"reading": reading, "case": case, "venous": op["NOv.C"], "tissue": op["NOt.C"],
                         "wall": op["art.Cw"]})
            sfx = "" if case == "base" else "_rdw"
            ctx.value(f"ch5.NOv{sfx}", op["NOv.C"], reading)
            ctx.value(f"ch5.NOt{sfx}", op["NOt.C"], reading)
    ctx.value("ch5.NOwall", out["as implemented", "base"]["art.Cw"])
    ctx.rows("concentrations", rows, {"reading": "", "case": "", "venous": "M", "tissue": "M", "wall": "M"})
    pl = plt()
    fig, ax = pl.subplots(figsize=(7.5, 4))
    labels = [f"{r['reading']}\n{r['case']}" for r in rows]
    xx = np.arange(len(rows))
    for k, (key, col) in enumerate((("wall", "0.5"), ("venous", "C0"), ("tissue", "C2"))):
        ax.bar(xx + (k - 1) * 0.27, [r[key] for r in rows], 0.27, color=col, label=f"{key} NO")
    ax.set_yscale("log")
    ax.set_xticks(xx, labels, fontsize=8)
    ax.set_ylabel("[NO] (M)")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    ctx.figure("concentrations", fig, "NO at Pa = 80 mmHg: arteriolar wall, venous blood and tissue, in the thesis's "
                                      "units reading (reproduces its numbers) and the consistent model; r_db as "
                                      "fitted and reduced to r_dw.", "")
