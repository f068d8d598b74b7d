"""Reference values of the special functions in src/stats/special.rs (scipy.special)."""
from scipy import special, stats

def row(*values):
    return "(" + ", ".join(repr(float(v)) for v in values) + "),"

print("// ln Γ(x): (x, value)")
for x in [1e-3, 0.1, 0.5, 1.0, 1.5, 2.5, 7.25, 33.0, 171.5, 1e4]:
    print(row(x, special.gammaln(x)))
print("// P(a, x) and Q(a, x): (a, x, P, Q)")
for a, x in [(0.5, 0.01), (0.5, 2.0), (1.0, 1.0), (2.5, 1.0), (3.0, 10.0),
             (10.0, 3.0), (10.0, 30.0), (50.0, 45.0), (0.5, 40.0)]:
    print(row(a, x, special.gammainc(a, x), special.gammaincc(a, x)))
print("// χ² quantile: (p, k, quantile)")
for p, k in [(0.05, 1), (0.5, 1), (0.95, 1), (0.001, 3), (0.5, 3), (0.975, 5),
             (0.999, 8), (0.01, 64), (0.5, 128)]:
    print(row(p, k, stats.chi2.ppf(p, k)))
print("// I_x(a, b): (a, b, x, value)")
for a, b, x in [(0.5, 0.5, 0.3), (2.0, 3.0, 0.4), (10.0, 0.5, 0.9), (0.5, 20.0, 0.01),
                (50.0, 60.0, 0.45), (1.0, 1.0, 0.77)]:
    print(row(a, b, x, special.betainc(a, b, x)))
print("// Student t: (t, nu, cdf)")
for t, nu in [(-3.0, 1.0), (0.7, 2.0), (2.1, 5.5), (-1.3, 17.3), (4.0, 40.0), (12.0, 3.0)]:
    print(row(t, nu, stats.t.cdf(t, nu)))
print("// Student t quantile: (p, nu, quantile)")
for p, nu in [(0.95, 1.0), (0.95, 4.7), (0.975, 30.0), (0.05, 12.0), (0.999, 2.0)]:
    print(row(p, nu, stats.t.ppf(p, nu)))
print("// normal: (x, Φ(x))")
for x in [-30.0, -8.5, -3.0, -0.4, 0.0, 1.2, 5.0]:
    print(row(x, special.ndtr(x)))
print("// normal quantile: (p, Φ⁻¹(p))")
for p in [1e-300, 1e-12, 0.001, 0.025, 0.3, 0.5, 0.8, 0.975, 1 - 1e-9]:
    print(row(p, special.ndtri(p)))
