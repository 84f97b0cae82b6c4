"""index.html: one self-contained page (figures embedded as base64 PNG, no script, no network):
the statements table with verdicts at the top, then the sections in thesis order (figures with
their thesis labels, data files, run time, or the error of a failed section), then the
provenance."""
from __future__ import annotations

import base64
import html
import json
import os

from .statements import THESIS

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:1.5em auto;max-width:1200px;
 padding:0 1em;color:#222}
h1{margin-bottom:.2em} h2{border-bottom:2px solid #ddd;padding-bottom:.2em;margin-top:2em}
.banner{background:#fff3cd;border:1px solid #e0c060;padding:.6em 1em;margin:1em 0;font-weight:600}
table{border-collapse:collapse;font-size:13px;width:100%}
th,td{border:1px solid #ccc;padding:3px 6px;vertical-align:top} th{background:#f2f2f2;text-align:left}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
tr.ok td.v{background:#d9f2d9} tr.bad td.v{background:#f8d7d7} tr.fail td.v{background:#f0c0c0}
tr.skip td.v{background:#eee;color:#666}
.note{color:#7a4b00;font-size:12px}
.fig{display:inline-block;vertical-align:top;width:48%;margin:.5%;}
.fig img{width:100%;border:1px solid #ddd}
.fig p{font-size:12px;margin:.2em 0 1em}
.err{background:#fbeaea;border:1px solid #d99;padding:.5em;white-space:pre-wrap;font-size:12px}
.meta{font-size:12px;color:#555}
code{font-size:12px}
"""


def _e(x):
    return html.escape(str(x))


def _num(v):
    if v is None:
        return ""
    return f"{v:.4g}"


def _img(out, rel):
    with open(os.path.join(out, rel), "rb") as fh:
        return "data:image/png;base64," + base64.b64encode(fh.read()).decode("ascii")


def render(runs, rows, prov, out):
    quick = prov["mode"] == "quick"
    counts = {}
    for r in rows:
        counts[r.verdict.split(" ")[0]] = counts.get(r.verdict.split(" ")[0], 0) + 1
    p = ['<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">',
         '<meta name="viewport" content="width=device-width, initial-scale=1">',
         f"<title>hemocircuit: thesis chapters 4-6 reproduced{' (QUICK)' if quick else ''}</title>",
         f"<style>{CSS}</style></head><body>",
         "<h1>Thesis chapters 4-6, reproduced by hemocircuit</h1>",
         f'<p class="meta">hemocircuit {_e(prov["hemocircuit"])}, {_e(prov["date"])}, '
         f'{len(rows)} statements, {sum(1 for r in runs.values() if r.status == "ok")} of {len(runs)} sections ran'
         f' ({prov["wall_time_s"]:.0f} s). Thesis: <code>{_e(THESIS)}</code>.</p>']
    if quick:
        p.append('<div class="banner" id="quick-banner">QUICK REPORT: coarser grids and shorter runs for the figures '
                 '(the statement values are computed as in the full report). Run without --quick for the full report.'
                 '</div>')
    failed = [r for r in runs.values() if r.status == "failed"]
    if failed:
        p.append(f'<div class="banner">Failed sections: {", ".join(_e(r.key) for r in failed)} (errors below; '
                 "the rest of the report is complete).</div>")
    if prov.get("only"):
        p.append(f'<div class="banner">Partial report: only {_e(", ".join(prov["only"]))} were run (--only).</div>')
    p.append("<h2 id=\"statements\">Quantitative statements</h2>")
    p.append("<p>" + ", ".join(f"{_e(k)}: {v}" for k, v in sorted(counts.items())) +
             ". <em>agrees</em>: the value computed now is within the stated tolerance of the thesis's (or beyond "
             "its bound); rows marked MODEL_NOTES are where the project deliberately differs from the thesis "
             "(<code>shared/MODEL_NOTES.md</code>) and show both readings. Data: "
             '<a href="statements.csv">statements.csv</a>.</p>')
    p.append('<table id="statements-table"><thead><tr><th>#</th><th>thesis line</th><th>statement</th>'
             "<th>thesis</th><th>computed now</th><th>other reading</th><th>rel. diff.</th><th>verdict</th>"
             "<th>how computed</th></tr></thead><tbody>")
    for i, r in enumerate(rows, 1):
        st = r.st
        other = [(k, v) for k, v in r.values.items() if k != st.decides]
        other_txt = "<br>".join(f"{_num(v)} ({_e(k)})" for k, v in other)
        rd = "" if r.rel_diff is None else f"{r.rel_diff * 100:+.2f} %"
        val = "" if r.value is None else f"{_num(r.value)}" + (f" ({_e(st.decides)})" if other else "")
        note = f'<div class="note">MODEL_NOTES: {_e(st.note)}</div>' if st.note else ""
        p.append(f'<tr class="{r.kind}" data-id="{_e(st.id)}"><td>{i}</td><td class="num">{st.line}</td>'
                 f"<td>{_e(st.text)}{note}</td><td class=\"num\">{_e(st.stated)} {_e(st.unit)}</td>"
                 f'<td class="num">{val}</td><td class="num">{other_txt}</td><td class="num">{rd}</td>'
                 f'<td class="v">{_e(r.verdict)}</td><td>{_e(st.how)} <span class="meta">[{_e(st.section)}]</span></td>'
                 "</tr>")
    p.append("</tbody></table>")

    chapter = None
    for key, r in runs.items():
        if r.chapter != chapter:
            chapter = r.chapter
            p.append(f"<h2>Chapter {chapter}</h2>" if chapter else "<h2>Other</h2>")
        p.append(f'<section id="{_e(key)}"><h3>{_e(r.title)} <span class="meta">[{_e(key)}]</span></h3>')
        labels = ", ".join(r.labels)
        p.append(f'<p class="meta">Thesis figures: {_e(labels) or "-"}. Status: <b>{_e(r.status)}</b>'
                 + (f", {r.seconds:.1f} s" if r.status != "not run" else "") + ".</p>")
        if r.status == "failed":
            p.append(f'<div class="err section-error">{_e(r.error)}</div>')
        if r.ctx is not None:
            for text in r.ctx.notes:
                p.append(f"<p>{_e(text)}</p>")
            for label, rel, caption in r.ctx.figures:
                p.append(f'<div class="fig"><img src="{_img(out, rel)}" alt="{_e(label or rel)}">'
                         f"<p><b>{_e(label)}</b> {_e(caption)} <a href=\"{_e(rel)}\">PNG</a></p></div>")
            if r.ctx.data_files:
                p.append('<p class="meta">Data: ' + ", ".join(f'<a href="{_e(d)}">{_e(os.path.basename(d))}</a>'
                                                            for d in r.ctx.data_files) + "</p>")
        p.append("</section>")

    p.append('<h2 id="provenance">Provenance</h2><table>')
    for k in ("hemocircuit", "python", "numpy", "scipy", "date", "mode", "command", "only", "wall_time_s"):
        p.append(f"<tr><th>{_e(k)}</th><td>{_e(prov.get(k))}</td></tr>")
    p.append("<tr><th>netlists (SHA-256 over the file and its extends chain)</th><td>" +
             "<br>".join(f"<code>{_e(n)}</code> {_e(h)}" for n, h in prov["netlists"].items()) + "</td></tr>")
    p.append("</table><h3>Sections</h3><table><tr><th>section</th><th>status</th><th>time [s]</th>"
             "<th>settings</th></tr>")
    for k, s in prov["sections"].items():
        p.append(f"<tr><td>{_e(k)}</td><td>{_e(s['status'])}</td><td class=\"num\">{s['seconds']:.1f}</td>"
                 f"<td><code>{_e(json.dumps(s['settings']))}</code></td></tr>")
    p.append("</table></body></html>")
    return "\n".join(p)
