"""The command line of the dynamic-autoregulation measures (:mod:`hemocircuit.dca`):
``hemocircuit tfa RECORDING --input ABP --output CBFV``."""
from __future__ import annotations

import argparse


def register_cli(sub, common):
    sp = sub.add_parser("tfa", help="transfer function analysis of two series (CARNet white paper): gain, phase, "
                                    "coherence in VLF/LF/HF")
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
    sp.add_argument("--window", type=float, default=100.0, help="Welch window length [s] (default 100)")
    sp.add_argument("--overlap", type=float, default=0.5, help="window overlap, a fraction (default 0.5)")
    sp.add_argument("--detrend", choices=("constant", "linear"), default="constant",
                    help="what each window loses before its FFT: its mean (default) or its linear trend")
    sp.add_argument("--smoothing", type=int, default=3,
                    help="points of triangular spectral smoothing (default 3, as the CARNet script; 1: none)")
    sp.add_argument("--keep-negative-phase", action="store_true",
                    help="count negative phases below 0.1 Hz (left out by default as wrap-around)")
    sp.add_argument("--out", help="a row per band: .csv, .json, .npz or .parquet")
    sp.add_argument("--plot", help="gain, phase and coherence against frequency (.png, .pdf or .svg)")
    sp.add_argument("--quiet", action="store_true", help=argparse.SUPPRESS)
    sp.set_defaults(func=cmd_tfa)


def cmd_tfa(args):
    from ..commands import record
    from ..dca.series import read_series, uniform_series
    from ..dca.tfa import plot_tfa, tfa
    from ..results import file_format

    if args.out:
        file_format(args.out)  # before computing
    t, x, y, names, units = read_series(args.recording, args.input, args.output, args.time)
    series = uniform_series(t, x, y, fs=args.fs, beats=args.beat_average, names=names, units=units)
    res, sp = tfa(series, args.window, args.overlap, args.detrend, args.smoothing, args.keep_negative_phase)
    st = res.metadata["settings"]
    print(f"TFA {args.input} -> {args.output}: {st['duration_s']:.4g} s at {series.fs:g} Hz, {sp.windows} windows of "
          f"{args.window:g} s, coherence threshold {sp.threshold:.2f}")
    for note in res.metadata["notes"]:
        print(f"note: {note}")
    print(res.summary(max_rows=8))
    record(args, res)
    if args.out:
        print(f"wrote {res.save(args.out)}")
    if args.plot:
        plot_tfa(sp, res, args.plot)
        print(f"wrote {args.plot}")
