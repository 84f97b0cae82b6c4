"""Writing results: 10 001 rows x 36 columns (a 1000 s run at dt 0.1 s of a mid-size circuit)
in each format, median of N writes (after one warm-up), and the old per-cell CSV writer for
comparison.  Run: python benchmarks/bench_write.py [--repeat 7]"""
import argparse
import csv
import io
import os
import statistics
import tempfile
import time

import numpy as np

from hemocircuit.results import Result, _cell


def per_cell_csv(res):
    """The former writer: one Python call per cell (kept here only as the yardstick)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    cols = [res[n].tolist() for n in res.keys()]
    for vals in zip(*cols):
        w.writerow([_cell(v) for v in vals])
    return buf.getvalue()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=7)
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    t = np.arange(10001) * 0.1
    cols = {"time": t, **{f"x{i}": 80 + rng.standard_normal(t.size).cumsum() * 0.01 for i in range(35)}}
    res = Result(cols, {k: "mmHg" for k in cols}, index=["time"], metadata={"analysis": "tran"})
    folder = tempfile.mkdtemp()
    print(f"{t.size} rows x {len(cols)} columns, median of {a.repeat}")
    for ext in (".csv", ".npz", ".json", ".parquet"):
        path = os.path.join(folder, "r" + ext)
        try:
            res.save(path)
        except Exception as exc:  # noqa: BLE001 - parquet without pyarrow
            print(f"  {ext:9s} skipped: {exc}")
            continue
        times = []
        for _ in range(a.repeat):
            t0 = time.perf_counter()
            res.save(path)
            times.append(time.perf_counter() - t0)
        print(f"  {ext:9s} {statistics.median(times) * 1e3:8.1f} ms  ({os.path.getsize(path) / 1e6:.1f} MB)")
    times = []
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        per_cell_csv(res)
        times.append(time.perf_counter() - t0)
    print(f"  per-cell csv (former writer, table only) {statistics.median(times) * 1e3:8.1f} ms")


if __name__ == "__main__":
    main()
