"""Exact Gaussian kernel sums for src/stats/kde.rs (scipy.stats.gaussian_kde), with the
bandwidth that R's bw.nrd0 gives for the same sample (printed by kde.R)."""
import numpy as np
from scipy import stats

x = 25 + 3 * np.sin(0.31 * (np.arange(40) + 1.0))
h = 0.93074629398545816  # R_BW from kde.R
kde = stats.gaussian_kde(x, bw_method=h / x.std(ddof=1))
for g in [25.0, 27.5, 31.0]:
    print(f"({g!r}, {float(kde(g)[0])!r}),")
