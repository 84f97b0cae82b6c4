"""``hemocircuit reproduce`` (issue 12): the report is built, its statements judged, failures
reported in the page, and the page opened in a real headless Chromium (the Debian package
chromium-headless-shell or chromium; .ci/run installs it when missing).

The browser is driven over the DevTools protocol on a pipe (--remote-debugging-pipe: JSON
messages separated by NUL on file descriptors 3 and 4), so no Python package beyond the
standard library is needed.

Budget: the report built here is the whole --quick report (about 65 s on 2 cores), once for
the module; the other tests use single sections.
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import struct
import subprocess
import zlib

import numpy as np
import pytest

from hemocircuit.cli import main
from hemocircuit.reproduce import build, registry
from hemocircuit.reproduce.statements import STATEMENTS, Row, Statement

@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    return build(str(out), quick=True, progress=False, argv=["reproduce", "--quick"])


# ------------------------------------------------------------------ the report itself -----
def test_every_statement_has_a_row_and_a_section(report):
    assert len(report.rows) == len(STATEMENTS)
    assert len({s.id for s in STATEMENTS}) == len(STATEMENTS)
    for s in STATEMENTS:
        assert s.section in registry.SECTIONS, s.id
        assert 349 <= s.line <= 1362, s.id  # chapters 3-6 of the thesis file
    assert all(r.kind in ("ok", "bad") for r in report.rows)  # every statement computed and judged


def test_statement_lines_point_at_the_stated_value():
    """Each statement's line of the thesis contains its number (as the thesis writes it)."""
    with _thesis() as fh:
        lines = fh.read().splitlines()
    for s in STATEMENTS:
        if s.check in ("rel", "abs") and s.thesis != 0:
            text = lines[s.line - 1]
            assert any(tok in text for tok in _spellings(s.thesis)), (s.id, s.line, _spellings(s.thesis))


def _thesis():
    here = os.path.dirname(os.path.abspath(__file__))
    for cand in (os.path.join(here, "..", "..", "shared"), os.path.join(here, "..", "..", "..", "shared"),
                 "/work/shared"):
        p = os.path.join(cand, "thesis", "000_bf4d7f0361c98477.txt")
        if os.path.isfile(p):
            return open(p, encoding="utf-8")
    pytest.skip("the thesis text (shared/thesis) is not beside this checkout")


def _spellings(v):
    m, e = f"{v:.3e}".split("e")
    e = int(e)
    out = {f"{v:g}", f"{v:.2g}", f"{v:.1f}", f"{v:.0f}"}
    out |= {1 / 3: {"1:3", "one third"}, 2.0: {"twice"}}.get(v, set())  # the thesis's words
    for digits in (1, 2, 3):
        mant = f"{float(m):.{digits - 1}f}" if digits > 1 else f"{float(m):.0f}"
        out.add(f"{mant}\\e{{{e}}}")
        for shift in (1, 2, 3):
            out.add(f"{float(m) * 10 ** shift:.{max(digits - 1 - shift, 0)}f}\\e{{{e - shift}}}")
    return out


def test_verdicts_judge_the_value():
    st = Statement("x", "ch4_steady", 670, "t", 60.0, "um", "h", "rel", 0.02)
    assert Row(st, {"as implemented": 61.0}, True, False).kind == "ok"
    assert Row(st, {"as implemented": 62.0}, True, False).kind == "bad"
    assert Row(st, {}, True, True).kind == "fail"
    assert Row(st, {}, False, False).kind == "skip"
    two = Statement("y", "ch4_steady", 1, "t", 1.0, "1", "h", "rel", 0.1, note="n", decides="thesis reading")
    r = Row(two, {"as implemented": 2.0, "thesis reading": 1.05}, True, False)
    assert r.kind == "ok" and "as implemented: differs" in r.verdict and "MODEL_NOTES" in r.verdict
    assert Row(Statement("z", "s", 1, "t", 0.0, "um", "h", "<"), {"as implemented": -1.0}, True, False).kind == "ok"


def test_files_and_provenance(report):
    out = report.out
    prov = json.load(open(os.path.join(out, "provenance.json")))
    assert prov["mode"] == "quick"
    assert prov["sections"]["ch4_steady"]["status"] == "ok" and prov["sections"]["ch4_steady"]["seconds"] > 0
    assert any(n.endswith("isolated_arteriole.yaml") for n in prov["netlists"])
    assert all(len(h) == 64 for h in prov["netlists"].values())
    from hemocircuit.results import Result
    st = Result.load(os.path.join(out, "statements.csv"))
    assert st.n_rows == len(STATEMENTS)
    data = Result.load(os.path.join(out, "data", "ch4_steady_curves.csv"))
    assert data.metadata["reproduce"]["section"] == "ch4_steady"
    assert data.metadata["provenance"]["netlist_sha256"]
    # the physics in the data: the passive radius exceeds the active one at every pressure
    rows = data.rows()
    pas = np.array([r["r"] for r in rows if r["preset"] == "kuo91" and r["case"] == "passive"])
    act = np.array([r["r"] for r in rows if r["preset"] == "kuo91" and r["case"] == "active_no_flow"])
    assert np.all(pas > act)


def test_failed_section_is_reported_and_the_rest_written(tmp_path, monkeypatch):
    mod = registry.load("ch4_steady")

    def boom(ctx):
        raise RuntimeError("deliberate failure for the test")

    monkeypatch.setattr(mod, "run", boom)
    rep = build(str(tmp_path), quick=True, only=["ch4_steady"], progress=False)
    assert rep.runs["ch4_steady"].status == "failed"
    page = open(rep.index, encoding="utf-8").read()
    assert "deliberate failure for the test" in page and "Failed sections" in page
    assert all(r.kind == "fail" for r in rep.rows if r.st.section == "ch4_steady")
    assert os.path.isfile(os.path.join(tmp_path, "statements.csv"))


def test_cli_unknown_section_is_a_clear_error(tmp_path, capsys):
    assert main(["reproduce", "--out", str(tmp_path), "--only", "ch9_nothing"]) == 2
    err = capsys.readouterr().err
    assert "unknown section" in err and "ch4_steady" in err


# ------------------------------------------------------------------ headless Chromium -----
def _browser():
    for name in ("chromium-headless-shell", "chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    for path in ("/usr/lib/chromium/chromium-headless-shell", "/usr/lib/chromium/chromium"):
        if os.path.isfile(path):
            return path
    return None


class DevTools:
    """Minimal DevTools-protocol client over --remote-debugging-pipe."""

    def __init__(self, exe, user_dir):
        r_cmd, w_cmd = os.pipe()    # we write commands, the browser reads them on fd 3
        r_resp, w_resp = os.pipe()  # the browser writes responses on fd 4

        def fds():
            os.dup2(r_cmd, 3)
            os.dup2(w_resp, 4)

        args = [exe, "--headless", "--remote-debugging-pipe", "--no-sandbox", "--disable-gpu",
                "--no-first-run", "--disable-extensions", f"--user-data-dir={user_dir}", "about:blank"]
        self.proc = subprocess.Popen(args, preexec_fn=fds, pass_fds=(3, 4, r_cmd, w_resp),
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(r_cmd)
        os.close(w_resp)
        self.w, self.r = os.fdopen(w_cmd, "wb", buffering=0), os.fdopen(r_resp, "rb", buffering=0)
        self.buf, self.next_id, self.events = b"", 0, []

    def _read(self):
        while b"\0" not in self.buf:
            chunk = self.r.read(1 << 16)
            if not chunk:
                raise RuntimeError("the browser closed the DevTools pipe")
            self.buf += chunk
        msg, self.buf = self.buf.split(b"\0", 1)
        return json.loads(msg)

    def send(self, method, params=None, session=None):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        self.w.write(json.dumps(msg).encode() + b"\0")
        while True:
            m = self._read()
            if m.get("id") == self.next_id:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m["result"]
            self.events.append(m)

    def wait_event(self, method, limit=2000):
        for _ in range(limit):
            for k, m in enumerate(self.events):
                if m.get("method") == method:
                    return self.events.pop(k)
            self.events.append(self._read())
        raise RuntimeError(f"no {method} event")

    def close(self):
        try:
            self.send("Browser.close")
        except Exception:  # noqa: BLE001 - already gone
            pass
        self.proc.wait(timeout=20)


def _png_pixels(data):
    """(width, height, distinct colours) of an 8-bit RGB/RGBA PNG (what matplotlib writes)."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, w, h, bpp = 8, b"", 0, 0, 3
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and ctype in (2, 6)
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    stride = w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line))
        prev = line
    px = np.frombuffer(b"".join(rows), np.uint8).reshape(h, w, bpp)
    return w, h, len(np.unique(px.reshape(-1, bpp), axis=0))


def test_report_in_headless_chromium(report, tmp_path):
    exe = _browser()
    if exe is None:
        pytest.skip("no Chromium found (apt-get install chromium-headless-shell; .ci/run installs it)")
    dt = DevTools(exe, str(tmp_path / "profile"))
    try:
        target = dt.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        sid = dt.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Runtime", "Log", "Page"):
            dt.send(f"{domain}.enable", session=sid)
        dt.send("Emulation.setDeviceMetricsOverride",
                {"width": 1280, "height": 1000, "deviceScaleFactor": 1, "mobile": False}, session=sid)
        dt.send("Page.navigate", {"url": "file://" + os.path.abspath(report.index)}, session=sid)
        dt.wait_event("Page.loadEventFired")

        def js(expr):
            r = dt.send("Runtime.evaluate", {"expression": expr, "returnByValue": True, "awaitPromise": True},
                        session=sid)
            assert "exceptionDetails" not in r, r
            return r["result"]["value"]

        info = js("""(async () => {
            const imgs = [...document.images];
            await Promise.all(imgs.map(i => i.decode().catch(() => null)));
            return imgs.map(i => {
                const c = document.createElement('canvas');
                c.width = i.naturalWidth; c.height = i.naturalHeight;
                let colours = 0;
                if (c.width > 0) {
                    const g = c.getContext('2d'); g.drawImage(i, 0, 0);
                    const d = g.getImageData(0, 0, c.width, c.height).data, seen = new Set();
                    for (let k = 0; k < d.length && seen.size < 50; k += 4 * 97)
                        seen.add((d[k] << 16) | (d[k + 1] << 8) | d[k + 2]);
                    colours = seen.size;
                }
                return {alt: i.alt, complete: i.complete, w: i.naturalWidth, h: i.naturalHeight, colours};
            });
        })()""")
        n_fig = sum(len(r.ctx.figures) for r in report.runs.values() if r.ctx)
        assert len(info) == n_fig >= 3
        for im in info:
            assert im["complete"] and im["w"] > 100 and im["h"] > 100, im
            assert im["colours"] > 3, im  # not blank: a plot has axes, lines, text
        rows = js("[...document.querySelectorAll('#statements-table tbody tr')].map(r => r.dataset.id)")
        assert rows == [s.id for s in STATEMENTS]
        assert js("!!document.getElementById('quick-banner')")
        shot = dt.send("Page.captureScreenshot", {"format": "png"}, session=sid)["data"]
        png = base64.b64decode(shot)
        path = tmp_path / "report_top.png"
        path.write_bytes(png)
        print(f"screenshot of the report's top: {path}")
        w, h, colours = _png_pixels(png)
        assert (w, h) == (1280, 1000) and colours > 10
        errors = [m for m in dt.events
                  if (m.get("method") == "Runtime.consoleAPICalled" and m["params"]["type"] in ("error", "assert"))
                  or m.get("method") == "Runtime.exceptionThrown"
                  or (m.get("method") == "Log.entryAdded" and m["params"]["entry"]["level"] == "error")]
        assert errors == []
    finally:
        dt.close()
