"""Reference values for src/stats/wasserstein.rs: scipy.stats.wasserstein_distance on the
deterministic samples offset + amp*sin(freq*(i+1))."""
import numpy as np
from scipy import stats

def wave(n, freq, amp, offset):
    return offset + amp * np.sin(freq * (np.arange(n) + 1.0))

cases = [
    (20, 1.3, 10.0, 50.0, 20, 0.7, 12.0, 52.0),
    (3, 1.0, 1.0, 0.0, 4, 2.0, 1.0, 0.5),
    (20, 1.3, 10.0, 50.0, 35, 0.7, 12.0, 52.0),
    (40, 0.31, 3.0, 25.0, 100, 1.7, 3.5, 25.4),
    (7, 0.5, 2.0, 1.0, 300, 0.05, 2.0, 1.0),
]
for na, fa, aa, oa, nb, fb, ab, ob in cases:
    w = stats.wasserstein_distance(wave(na, fa, aa, oa), wave(nb, fb, ab, ob))
    print(f"({na}, {fa!r}, {aa!r}, {oa!r}, {nb}, {fb!r}, {ab!r}, {ob!r}, {float(w)!r}),")
