"""Transfer function analysis (TFA) of dynamic cerebral autoregulation, with the CARNet white
paper's settings (Claassen et al. 2016, J Cereb Blood Flow Metab 36:665; 2nd ed. Panerai et
al. 2023) and the choices of its reference script (D. Simpson's ``tfa_car``, CARNet 2015):

* Welch estimates of the auto- and cross-spectra by :func:`scipy.signal.welch` and
  :func:`scipy.signal.csd`: Hanning windows of 100 s, 50 % overlap, each window detrended
  (its linear trend removed; ``detrend="constant"``: its mean only);
* no spectral smoothing by default: the script's 3-point triangular smoothing (``smoothing=3``)
  biases the VLF gain of a high-pass by ~2 % (measured: 2.2 % against 0.7-1.4 % without);
* H(f) = Pxy/Pxx, gain |H| [output unit per input unit], phase arg H [deg], coherence
  |Pxy|^2/(Pxx Pyy); normalised gain = gain / mean(output) * 100 [% per input unit];
* band means over VLF [0.02, 0.07), LF [0.07, 0.20), HF [0.20, 0.50) Hz: gain and phase over
  the frequencies whose coherence reaches the 95 % threshold for the number of windows
  (the script's table, 3-15 windows; outside it every frequency counts and a note says so),
  with negative phases below 0.1 Hz left out as wrap-around (the script's default);
  coherence over every frequency of the band.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import HemocircuitError

BANDS = (("VLF", 0.02, 0.07), ("LF", 0.07, 0.20), ("HF", 0.20, 0.50))
#: 95 % coherence thresholds by number of windows (Hanning, 50 % overlap; CARNet script)
COHERENCE_THRESHOLD = {3: 0.51, 4: 0.40, 5: 0.34, 6: 0.29, 7: 0.25, 8: 0.22, 9: 0.20, 10: 0.18, 11: 0.17,
                       12: 0.15, 13: 0.14, 14: 0.13, 15: 0.12}
#: below this frequency a negative phase is taken as wrap-around and left out [Hz]
NEGATIVE_PHASE_BELOW = 0.1


@dataclass
class Spectrum:
    """The transfer function estimate at each frequency ``f`` [Hz]."""
    f: np.ndarray
    H: np.ndarray            # complex, output unit per input unit
    coherence: np.ndarray    # magnitude-squared, 0-1
    windows: int
    threshold: float         # NaN when the number of windows has none
    used: np.ndarray         # bool: counts toward band gain and phase

    @property
    def gain(self):
        return np.abs(self.H)

    @property
    def phase_deg(self):
        return np.degrees(np.angle(self.H))


def spectrum(x, y, fs, window=100.0, overlap=0.5, detrend="linear", smoothing=1,
             keep_negative_phase=False) -> Spectrum:
    """TFA spectrum of output ``y`` against input ``x``, both sampled uniformly at ``fs`` [Hz]."""
    from scipy.signal import csd, welch

    n = int(round(window * fs))
    if n < 4:
        raise HemocircuitError(f"--window {window:g} s holds {n} samples at {fs:g} Hz; use a longer window")
    if len(x) < n:
        raise HemocircuitError(f"the series last {len(x) / fs:.4g} s, shorter than one {window:g} s window; "
                               "record (or simulate) at least 5 minutes, or shorten --window")
    if not 0 <= overlap < 1:
        raise HemocircuitError(f"--overlap {overlap}: must be in [0, 1) (0.5: 50 %)")
    if detrend not in ("constant", "linear"):
        raise HemocircuitError(f"--detrend {detrend!r}: use 'constant' (each window's mean) or 'linear'")
    nov = int(round(overlap * n))
    opts = dict(fs=fs, window="hann", nperseg=n, noverlap=nov, detrend=detrend, scaling="density")
    f, pxx = welch(x, **opts)
    _, pyy = welch(y, **opts)
    _, pxy = csd(x, y, **opts)  # conj(X) Y: H = Pxy / Pxx
    if smoothing > 1:
        pxx, pyy, pxy = (_smooth(p, smoothing) for p in (pxx, pyy, pxy))
    with np.errstate(divide="ignore", invalid="ignore"):
        H = pxy / pxx
        coh = np.abs(pxy) ** 2 / (pxx * pyy)
    windows = 1 + (len(x) - n) // (n - nov)
    threshold = COHERENCE_THRESHOLD.get(windows, np.nan)
    used = np.isfinite(H) & (coh >= threshold if np.isfinite(threshold) else True)
    if not keep_negative_phase:
        used &= ~((f < NEGATIVE_PHASE_BELOW) & (np.angle(H) < 0))
    return Spectrum(f, H, coh, int(windows), float(threshold), used)


def _smooth(p, points):
    """The CARNet script's spectral smoothing: a moving average of (points + 1) // 2 values run
    forward and backward (a triangular filter; 3 points: weights 1/4, 1/2, 1/4), the 0 Hz value
    kept out of it."""
    from scipy.signal import filtfilt

    h = np.ones((points + 1) // 2)
    h /= h.sum()
    q = p.copy()
    q[0] = p[1]
    real = filtfilt(h, [1.0], q.real)
    out = real + 1j * filtfilt(h, [1.0], q.imag) if np.iscomplexobj(p) else real
    out[0] = p[0]
    return out


def band_table(sp: Spectrum, mean_output, bands=BANDS):
    """One row per band: gain, normalised gain [%], phase [deg], coherence and the counts of
    frequencies in it and used for gain and phase (a band without one gets NaN)."""
    rows = []
    for name, lo, hi in bands:
        inside = (sp.f >= lo) & (sp.f < hi)
        use = inside & sp.used
        gain = float(np.mean(sp.gain[use])) if use.any() else np.nan
        rows.append({"band": name, "f_low": lo, "f_high": hi, "gain": gain,
                     "gain_norm": gain / mean_output * 100.0 if mean_output else np.nan,
                     "phase": float(np.mean(np.angle(sp.H[use]))) * 180 / np.pi if use.any() else np.nan,
                     "coherence": float(np.mean(sp.coherence[inside])) if inside.any() else np.nan,
                     "points": int(inside.sum()), "points_used": int(use.sum())})
    return rows


def tfa(series, window=100.0, overlap=0.5, detrend="linear", smoothing=1, keep_negative_phase=False):
    """TFA of a :class:`~hemocircuit.dca.series.Series`: (Result with a row per band, Spectrum)."""
    from ..results import Result

    sp = spectrum(series.x, series.y, series.fs, window, overlap, detrend, smoothing, keep_negative_phase)
    mean_y = float(np.mean(series.y))
    rows = band_table(sp, mean_y)
    (xin, xout), (uin, uout) = series.names, series.units
    gain_unit = f"{uout or '1'}/{uin or '1'}" if (uin or uout) else ""
    cols = {k: np.array([r[k] for r in rows], dtype=object if k == "band" else None) for k in rows[0]}
    units = {"f_low": "Hz", "f_high": "Hz", "gain": gain_unit, "gain_norm": f"%/{uin}" if uin else "%",
             "phase": "deg", "coherence": "1"}
    notes = list(series.notes)
    if not np.isfinite(sp.threshold):
        notes.append(f"no coherence threshold for {sp.windows} window(s) (the CARNet table has 3-15): "
                     "every frequency counts toward gain and phase")
    md = {"analysis": "tfa",
          "settings": {"input": xin, "output": xout, "fs_hz": series.fs, "window_s": window, "overlap": overlap,
                       "detrend": detrend, "smoothing_points": smoothing, "windows": sp.windows,
                       "coherence_threshold": sp.threshold, "negative_phase_below_0.1Hz": keep_negative_phase,
                       "duration_s": float(series.t[-1] - series.t[0]), "mean_input": float(np.mean(series.x)),
                       "mean_output": mean_y},
          "notes": notes}
    return Result(cols, units, index=["band"], metadata=md), sp


def plot_tfa(sp: Spectrum, res, path, f_max=0.5):
    """Gain, phase and coherence against frequency; bands shaded, frequencies below the
    coherence threshold hollow, band means as horizontal bars."""
    from ..io import pyplot, save_figure

    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(6.4, 7.2), sharex=True)
    keep = (sp.f > 0) & (sp.f <= f_max)
    f, used = sp.f[keep], sp.used[keep]
    st = res.metadata["settings"]
    for ax, values, label, col in ((axes[0], sp.gain[keep], f"gain [{res.units['gain'] or '1'}]", "gain"),
                                   (axes[1], sp.phase_deg[keep], "phase [deg]", "phase"),
                                   (axes[2], sp.coherence[keep], "coherence", "coherence")):
        ax.plot(f, values, color="0.6", lw=0.8)
        ax.plot(f[used], values[used], "o", ms=3, color="C0", label="used")
        ax.plot(f[~used], values[~used], "o", ms=3, mfc="none", color="C0", label="left out")
        for k, (name, lo, hi) in enumerate(BANDS):
            ax.axvspan(lo, hi, color=f"C{k + 1}", alpha=0.08)
            v = res[col][k]
            if np.isfinite(v):
                ax.hlines(v, lo, hi, color=f"C{k + 1}", lw=2)
            if ax is axes[0]:
                ax.text((lo + hi) / 2, 1.02, name, transform=ax.get_xaxis_transform(), ha="center", fontsize=8)
        ax.set_ylabel(label)
    if np.isfinite(sp.threshold):
        axes[2].axhline(sp.threshold, color="k", ls="--", lw=0.8, label=f"95 % threshold ({sp.windows} windows)")
    axes[2].set_ylim(0, 1.05)
    axes[2].legend(fontsize=7, loc="lower right")
    axes[2].set_xlabel("frequency [Hz]")
    axes[0].set_title(f"TFA {st['input']} -> {st['output']}", fontsize=10, pad=14)
    save_figure(fig, path)
