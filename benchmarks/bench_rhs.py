"""Right-hand-side and Jacobian cost per evaluation, for single runs and batches.

    python benchmarks/bench_rhs.py
"""
import os
import time

import numpy as np

import hemocircuit as hc

NET = os.path.join(os.path.dirname(__file__), "..", "netlists")


def timeit(fn, min_time=0.5):
    fn()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < min_time:
        fn()
        n += 1
    return (time.perf_counter() - t0) / n


def main():
    print(f"{'netlist':<22}{'states':>7}{'rows':>7}{'rhs [us]':>12}{'us/row':>10}{'jacobian [us]':>15}")
    for name in ["payne06_passive", "isolated_arteriole", "payne06", "vasomotion"]:
        c = hc.load(os.path.join(NET, f"{name}.yaml"))
        x = np.atleast_2d(c.operating_point().x)[0]
        tj = timeit(lambda: c.jacobian(0.0, x))
        for rows in (1, 10, 100, 1000):
            X = np.repeat(x[None], rows, axis=0)
            t = timeit(lambda: c.evaluate(0.0, X))
            print(f"{name:<22}{c.nx:>7}{rows:>7}{t * 1e6:>12.1f}{t * 1e6 / rows:>10.2f}"
                  f"{(tj * 1e6 if rows == 1 else float('nan')):>15.1f}")


if __name__ == "__main__":
    main()
