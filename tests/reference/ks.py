"""Reference values for src/stats/ks.rs: scipy.stats.ks_2samp on deterministic samples
offset + amp*sin(freq*(i+1)), and scipy.special.kolmogorov."""
import numpy as np
from scipy import special, stats

def wave(n, freq, amp, offset):
    return offset + amp * np.sin(freq * (np.arange(n) + 1.0))

cases = [
    (20, 1.3, 10.0, 50.0, 20, 0.7, 12.0, 52.0),
    (20, 1.3, 10.0, 50.0, 20, 0.9, 10.0, 58.0),
    (3, 1.0, 1.0, 0.0, 4, 2.0, 1.0, 0.5),
    (20, 1.3, 10.0, 50.0, 35, 0.7, 12.0, 52.0),
    (40, 0.31, 3.0, 25.0, 100, 1.7, 3.5, 25.4),
    (100, 2.1, 4.0, 30.0, 80, 0.45, 4.0, 33.0),
    (7, 0.5, 2.0, 1.0, 300, 0.05, 2.0, 1.0),
    (250, 1.1, 5.0, 0.0, 250, 0.37, 5.0, 0.2),
]
for na, fa, aa, oa, nb, fb, ab, ob in cases:
    r = stats.ks_2samp(wave(na, fa, aa, oa), wave(nb, fb, ab, ob))
    print(f"({na}, {fa!r}, {aa!r}, {oa!r}, {nb}, {fb!r}, {ab!r}, {ob!r}, "
          f"{float(r.statistic)!r}, {float(r.pvalue)!r}),")
print("// kolmogorov")
for lam in [0.3, 0.6, 0.9, 1.0, 1.2, 1.8, 3.0]:
    print(f"({lam!r}, {float(special.kolmogorov(lam))!r}),")
