"""Noise-model metrics used by Noise Flow training (numpy only).

Marginal KL as in the Noise Flow code (seed ch. 6.4, DESIGN.md sec. 5): histogram of
signed noise values with edges ``[-1000] + linspace(-0.1, 0.1, 65) + [1000]``
(64 inner bins of width 0.2/64 plus two overflow bins), each histogram normalised
by its sample count, forward KL D(real || model) summed over bins where both are
non-empty.
"""

from __future__ import annotations

import numpy as np

#: bin edges of the marginal KL (66 bins).
KL_EDGES = np.concatenate(([-1000.0], np.linspace(-0.1, 0.1, 65), [1000.0]))
KL_BINNING = "edges [-1000] + linspace(-0.1, 0.1, 65) + [1000] (64 bins of 0.003125 + 2 overflow)"


def marginal_kl(real, model) -> float:
    """Forward KL D(real || model) in nats between the value histograms of two noise arrays."""
    p = np.histogram(np.asarray(real, np.float64).ravel(), KL_EDGES)[0].astype(np.float64)
    q = np.histogram(np.asarray(model, np.float64).ravel(), KL_EDGES)[0].astype(np.float64)
    p /= max(p.sum(), 1.0)
    q /= max(q.sum(), 1.0)
    both = (p > 0) & (q > 0)
    return float(np.sum(p[both] * (np.log(p[both]) - np.log(q[both]))))
