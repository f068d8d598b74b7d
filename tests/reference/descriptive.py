"""Reference quantiles and standard deviation for src/stats/descriptive.rs (numpy)."""
import numpy as np

x = np.array([3.1, -0.4, 7.7, 2.2, 2.2, 10.5, 0.9])
for p in [0.0, 0.05, 0.3, 0.5, 0.95]:
    print(f"({p!r}, {float(np.quantile(x, p))!r}),")
print("SD", repr(float(np.std(x, ddof=1))))
