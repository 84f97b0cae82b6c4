"""The command line of the dynamic-autoregulation measures (:mod:`hemocircuit.dca`):
``hemocircuit tfa|ari|mx RECORDING --input ABP --output CBFV``."""
from __future__ import annotations

import argparse


def _series_options(sp):
    """The two series every measure reads, and how they reach a uniform grid."""
    sp.add_argument("recording", help="a result file (--out of tran) or a recording: CSV with a header row "
                                      "('name' or 'name [unit]'), .json, .npz or .parquet")
    sp.add_argument("--input", required=True, help="column of the input (arterial pressure), e.g. ABP or Pa.P")
    sp.add_argument("--output", required=True, help="column of the output (cerebral flow or velocity), e.g. CBFV")
    sp.add_argument("--time", help="time column [s] (default: the result's index, or 'time' or 't')")
    sp.add_argument("--beat-average", action="store_true",
                    help="average each heart beat first (beats found on the input's systolic upstrokes), then "
                         "interpolate at --fs: for pulsatile signals")
    sp.add_argument("--fs", type=float, help="resampling rate [Hz] for beat means and irregular series "
                                             "(default 10; a uniform series keeps its own rate)")
    sp.add_argument("--out", help="the result: .csv, .json, .npz or .parquet")
    sp.add_argument("--plot", help="figure (.png, .pdf or .svg)")
    sp.add_argument("--quiet", action="store_true", help=argparse.SUPPRESS)


def _series(args):
    from ..dca.series import read_series, uniform_series
    from ..results import file_format

    if args.out:
        file_format(args.out)  # before computing
    t, x, y, names, units = read_series(args.recording, args.input, args.output, args.time)
    return uniform_series(t, x, y, fs=args.fs, beats=args.beat_average, names=names, units=units)


def _write(args, res, plot):
    from ..commands import record

    for note in res.metadata.get("notes", []):
        print(f"note: {note}")
    record(args, res)
    if args.out:
        print(f"wrote {res.save(args.out)}")
    if args.plot:
        plot(args.plot)
        print(f"wrote {args.plot}")


def register_cli(sub, common):
    sp = sub.add_parser("tfa", help="transfer function analysis of two series (CARNet white paper): gain, phase, "
                                    "coherence in VLF/LF/HF")
    _series_options(sp)
    sp.add_argument("--window", type=float, default=100.0, help="Welch window length [s] (default 100)")
    sp.add_argument("--overlap", type=float, default=0.5, help="window overlap, a fraction (default 0.5)")
    sp.add_argument("--detrend", choices=("constant", "linear"), default="linear",
                    help="what each window loses before its FFT: its linear trend (default) or its mean")
    sp.add_argument("--smoothing", type=int, default=1,
                    help="points of triangular spectral smoothing (default 1: none; 3 as the CARNet script)")
    sp.add_argument("--keep-negative-phase", action="store_true",
                    help="count negative phases below 0.1 Hz (left out by default as wrap-around)")
    sp.set_defaults(func=cmd_tfa)

    sp = sub.add_parser("ari", help="autoregulation index (Tiecks 0-9) of the response to a pressure drop "
                                    "(thigh-cuff release)")
    _series_options(sp)
    sp.add_argument("--release", type=float, help="time of the release [s] (default: the steepest pressure fall)")
    sp.add_argument("--baseline", type=float, default=10.0, help="seconds before the release for the baselines "
                                                                 "(default 10)")
    sp.add_argument("--duration", type=float, default=30.0, help="seconds after the release fitted (default 30)")
    sp.add_argument("--ccp", type=float, default=12.0, help="critical closing pressure [mmHg] (default 12)")
    sp.set_defaults(func=cmd_ari)

    sp = sub.add_parser("mx", help="mean flow index Mx: moving correlation of flow with pressure")
    _series_options(sp)
    sp.add_argument("--block", type=float, default=10.0, help="block of the means [s] (default 10)")
    sp.add_argument("--window", type=float, default=300.0, help="correlation window [s] (default 300: 30 blocks)")
    sp.add_argument("--step", type=float, default=60.0, help="the window's step [s] (default 60)")
    sp.set_defaults(func=cmd_mx)


def cmd_tfa(args):
    from ..dca.tfa import plot_tfa, tfa

    series = _series(args)
    res, sp = tfa(series, args.window, args.overlap, args.detrend, args.smoothing, args.keep_negative_phase)
    st = res.metadata["settings"]
    print(f"TFA {args.input} -> {args.output}: {st['duration_s']:.4g} s at {series.fs:g} Hz, {sp.windows} windows of "
          f"{args.window:g} s, coherence threshold {sp.threshold:.2f}")
    print(res.summary(max_rows=8))
    _write(args, res, lambda path: plot_tfa(sp, res, path))


def cmd_ari(args):
    import numpy as np

    from ..dca.ari import fit_ari, release_time
    from ..results import Result

    s = _series(args)
    release = args.release if args.release is not None else release_time(s.t, s.x)
    ari, grid, errors, fitted, tf = fit_ari(s.t, s.x, s.y, release, args.baseline, args.duration, args.ccp)
    print(f"ARI {ari:.1f} (release at {release:.4g} s{'' if args.release is not None else ', found'}; fit over "
          f"{args.duration:g} s; CCP {args.ccp:g} mmHg; normalised squared error {errors.min():.3g})")
    res = Result({"ari": grid, "error": errors}, {"ari": "1", "error": "1"}, index=["ari"],
                 metadata={"analysis": "ari", "ari": ari, "notes": list(s.notes),
                           "settings": {"input": args.input, "output": args.output, "release_s": release,
                                        "baseline_s": args.baseline, "duration_s": args.duration,
                                        "ccp_mmHg": args.ccp, "fs_hz": s.fs}})

    def plot(path):
        from ..io import pyplot, save_figure
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(6.4, 4))
        keep = (s.t >= release - args.baseline) & (s.t <= release + args.duration)
        ax.plot(s.t[keep] - release, s.y[keep], color="0.4", label=f"{args.output} (measured)")
        ax.plot(tf - release, fitted, color="C3", label=f"Tiecks model, ARI {ari:.1f}")
        ax.axvline(0, color="k", ls=":", lw=0.8)
        ax.set_xlabel("time from release [s]")
        ax.set_ylabel(f"{args.output} [{s.units[1] or '1'}]")
        ax.legend(fontsize=8)
        save_figure(fig, path)

    _write(args, res, plot)
    return 0 if np.isfinite(ari) else 1


def cmd_mx(args):
    import numpy as np

    from ..dca.mx import moving_correlation
    from ..results import Result

    s = _series(args)
    starts, r = moving_correlation(s.t, s.x, s.y, args.block, args.window, args.step)
    mx = float(np.nanmean(r)) if np.isfinite(r).any() else float("nan")
    print(f"Mx {mx:.3f} ({len(r)} windows of {args.window:g} s, blocks of {args.block:g} s, step {args.step:g} s)")
    res = Result({"t_start": starts, "t_end": starts + args.window, "r": r}, {"t_start": "s", "t_end": "s", "r": "1"},
                 index=["t_start"], metadata={"analysis": "mx", "mx": mx, "notes": list(s.notes),
                                              "settings": {"input": args.input, "output": args.output,
                                                           "block_s": args.block, "window_s": args.window,
                                                           "step_s": args.step}})

    def plot(path):
        from ..io import pyplot, save_figure
        plt = pyplot()
        fig, ax = plt.subplots(figsize=(6.4, 3.2))
        ax.plot(starts + args.window / 2, r, "o-", ms=3)
        ax.axhline(mx, color="C3", label=f"Mx {mx:.2f}")
        ax.set_ylim(-1.05, 1.05)
        ax.set_xlabel("window centre [s]")
        ax.set_ylabel("r")
        ax.legend(fontsize=8)
        save_figure(fig, path)

    _write(args, res, plot)
