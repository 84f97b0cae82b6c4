"""Dynamic cerebral autoregulation measures on two time series (arterial pressure in, cerebral
blood flow or velocity out), as the clinic computes them: transfer function analysis
(:mod:`.tfa`).  Any two columns of a result file or of a user's own recording."""
from .series import Series, read_series, uniform_series
from .tfa import spectrum, tfa

__all__ = ["Series", "read_series", "uniform_series", "spectrum", "tfa"]
