"""Reference values for src/stats/multivariate.rs and src/stats/rank.rs (scipy)."""
import numpy as np
from scipy import stats
from scipy.spatial.distance import mahalanobis

def rows(n, shift):
    t = np.arange(1, n + 1, dtype=float)
    a = np.sin(1.1 * t)
    return np.column_stack([a + shift, np.cos(0.7 * t) + 0.3 * a, np.sin(0.37 * t) ** 2])

ref = rows(30, 0.0)
vi = np.linalg.inv(np.cov(ref.T))
mu = ref.mean(axis=0)
print("Q_REFERENCE", [float(mahalanobis(y, mu, vi) ** 2) for y in rows(6, 0.5)])

# Spearman matrix of rows(30, 0) rounded to 1 decimal (ties), scipy.stats.spearmanr
tied = np.round(rows(30, 0.0), 1)
print("SPEARMAN", stats.spearmanr(tied).statistic.tolist())
print("RANKS", stats.rankdata(tied[:, 0]).tolist())
