"""Reference values for src/stats/tost.rs: statsmodels' Welch TOST and 90 % interval on the
deterministic samples offset + amp*sin(freq*(i+1))."""
import numpy as np
from statsmodels.stats.weightstats import CompareMeans, DescrStatsW, ttost_ind

def wave(n, freq, amp, offset):
    return offset + amp * np.sin(freq * (np.arange(n) + 1.0))

cases = [
    (20, 1.3, 10.0, 50.0, 20, 0.7, 12.0, 52.0, 3.0),
    (40, 0.31, 3.0, 25.0, 100, 1.7, 3.5, 25.4, 1.0),
    (40, 0.31, 3.0, 25.0, 100, 1.7, 3.5, 25.4, 2.0),
    (12, 0.9, 1.0, 22.0, 60, 0.4, 4.0, 21.5, 0.5),
    (80, 2.2, 2.5, 24.0, 20, 1.1, 2.5, 27.0, 2.0),
]
for na, fa, aa, oa, nb, fb, ab, ob, m in cases:
    a, b = wave(na, fa, aa, oa), wave(nb, fb, ab, ob)
    p, lower, upper = ttost_ind(a, b, -m, m, usevar="unequal")
    cm = CompareMeans(DescrStatsW(a), DescrStatsW(b))
    lo, hi = cm.tconfint_diff(alpha=0.1, usevar="unequal")
    vals = [p, lower[0], lower[1], upper[0], upper[1], lower[2], lo, hi]
    print(f"({na}, {fa!r}, {aa!r}, {oa!r}, {nb}, {fb!r}, {ab!r}, {ob!r}, {m!r}, "
          + ", ".join(repr(float(v)) for v in vals) + "),")
