"""Tables of docs/representative/README.md from the validation reports run.sh writes, and
the noise table from those noise.sh writes.

    python3 docs/representative/table.py OUT_DIR/validation
    python3 docs/representative/table.py --noise OUT_DIR/noise
    python3 docs/representative/table.py --variants OUT_DIR/variants
"""
import json
import sys
from pathlib import Path

COHORTS = ["convex-a2", "convex-a4", "convex-a8", "convex-a4-noise1", "pca", "pca-t3",
           "pca-t2", "pca-t1.5", "pca-s1.1", "pca-s1.2", "gmm-k2", "gmm-k4", "gmm-bic"]


def load(directory, name, reference):
    path = Path(directory) / f"{name}-{reference}.json"
    return json.loads(path.read_text()) if path.exists() else None


def shape_row(name, r):
    s = r["shapes"]
    nna, cov, pw, dcr = s["nna"], s["coverage"], s["pairwise"], s["dcr"]
    base = s["baseline"]
    real = f" (real {base['coverage']['cov_subsets']['mean']:.3f})" if base else ""
    rejected = [f["feature"] for f in r["features"] if f["ks"] and f["ks"]["p_value"] < 0.05]
    ratio = dcr["dcr"]["median_ratio"] if dcr else float("nan")
    return (f"| {name} | {nna['mean']:.3f} [{nna['low']:.3f}, {nna['high']:.3f}] "
            f"| {cov['cov_subsets']['mean']:.3f}{real} "
            f"| {pw['median_ratio']:.3f} | {ratio:.3f} | {dcr['near_copies'] if dcr else '—'} "
            f"| {len(rejected)}: {', '.join(rejected) or '—'} | {r['verdict']} |")


def feature(r, name):
    return next((f for f in r["features"] if f["feature"] == name), None)


def ks_p(f):
    return f"{f['ks']['p_value']:.3f}" if f and f["ks"] else "—"


def measurement_row(name, r):
    """Length (mean) and maximum diameter (median), cohort against reference, with KS p;
    area and volume KS p; the features without a KS test (too few shapes measured)."""
    cells = [name]
    for key, stat in [("length_mm", "mean"), ("max_diameter_mm", "median")]:
        f = feature(r, key)
        if f and f["cohort"] and f["reference"]:
            cells.append(f"{f['cohort'][stat]:.1f} / {f['reference'][stat]:.1f} ({ks_p(f)})")
        else:
            cells.append("—")
    cells.append(f"{ks_p(feature(r, 'area_mm2'))}, {ks_p(feature(r, 'volume_mm3'))}")
    withheld = [f["feature"] for f in r["features"] if "ks" in f["not_computed"]]
    cells.append(", ".join(withheld) or "—")
    return "| " + " | ".join(cells) + " |"


def main(directory):
    header = ("| cohort | 1-NNA [90 % interval] | COV (real-vs-real) | pairwise median ratio "
              "| DCR median ratio | near-copies | features KS-rejected at 0.05 | verdict |\n"
              "|---|---|---|---|---|---|---|---|")
    for reference in ["heldout", "training"]:
        print(f"\n### Against the {reference} shapes\n")
        print(header)
        first = None
        for name in COHORTS:
            r = load(directory, name, reference)
            if r is None:
                print(f"| {name} | not run | | | | | | |")
                continue
            first = first or r
            print(shape_row(name, r))
        if first and first["shapes"]["baseline"]:
            b = first["shapes"]["baseline"]
            print(f"\nReal-vs-real baseline ({b['label']}): 1-NNA {b['nna']['mean']:.3f}, "
                  f"COV {b['coverage']['cov_subsets']['mean']:.3f}, "
                  f"pairwise median ratio {b['pairwise_median_ratio']:.3f}; sampling floor "
                  f"{first['shapes']['sampling_floor']:.3e}.")
        print(f"\n#### Measurements against the {reference} shapes\n")
        print("| cohort | length mean mm, cohort / reference (KS p) "
              "| max diameter median mm, cohort / reference (KS p) | area, volume KS p "
              "| KS not computed |\n|---|---|---|---|---|")
        for name in COHORTS:
            r = load(directory, name, reference)
            if r is not None:
                print(measurement_row(name, r))


# (row label, report stem, cohort seed, mesh resolution, evaluation seed) of noise.sh's reports;
# a stem of None is run.sh's own report at 10 000 points, found in VALIDATION_10K.
NOISE_ROWS = [
    ("gmm-k2", "gmm-k2-c2027-v2026", 2027, 64, 2026),
    ("gmm-k2", "gmm-k2-c2028-v2026", 2028, 64, 2026),
    ("gmm-k2", "gmm-k2-r128-v2026", 2026, 128, 2026),
    ("gmm-k2", "gmm-k2-v2027", 2026, 64, 2027),
    ("gmm-k2", "gmm-k2-v2028", 2026, 64, 2028),
    ("pca", "pca-c2027-v2026", 2027, 64, 2026),
    ("pca", "pca-c2028-v2026", 2028, 64, 2026),
    ("pca-s1.1", "pca-s1.1-c2027-v2026", 2027, 64, 2026),
    ("pca-s1.1", "pca-s1.1-c2028-v2026", 2028, 64, 2026),
    ("pca-s1.1", "pca-s1.1-r128-v2026", 2026, 128, 2026),
    ("pca-s1.1", "pca-s1.1-v2027", 2026, 64, 2027),
    ("pca-s1.1", "pca-s1.1-v2028", 2026, 64, 2028),
    ("pca-t1.5, σ × 1.346", "pca-t1.5-s1.346-v2026", 2026, 64, 2026),
    ("pca-t2, σ × 1.137", "pca-t2-s1.137-v2026", 2026, 64, 2026),
    ("training reconstructions", "reconstructions-64-v2026", "—", 64, 2026),
    ("training reconstructions", "reconstructions-64-v2027", "—", 64, 2027),
    ("training reconstructions", "reconstructions-64-v2028", "—", 64, 2028),
    ("training reconstructions", "reconstructions-128-v2026", "—", 128, 2026),
]


NOISE_HEADER = ("| cohort | cohort seed | mesh | evaluation seed | 1-NNA | COV | real-vs-real COV "
                "| pairwise median ratio | DCR median ratio | lowest KS p |\n"
                "|---|---|---|---|---|---|---|---|---|---|")


def noise_row(label, cohort_seed, resolution, evaluation_seed, path):
    if not path.exists():
        return (f"| {label} | {cohort_seed} | {resolution}³ | {evaluation_seed} | not run "
                "| | | | | |")
    r = json.loads(path.read_text())
    s = r["shapes"]
    ks = [f["ks"]["p_value"] for f in r["features"] if f["ks"]]
    return (f"| {label} | {cohort_seed} | {resolution}³ | {evaluation_seed} "
            f"| {s['nna']['mean']:.3f} | {s['coverage']['cov_subsets']['mean']:.3f} "
            f"| {s['baseline']['coverage']['cov_subsets']['mean']:.3f} "
            f"| {s['pairwise']['median_ratio']:.3f} | {s['dcr']['dcr']['median_ratio']:.3f} "
            f"| {min(ks):.3f} |")


def noise(directory):
    print(NOISE_HEADER)
    for label, stem, cohort_seed, resolution, evaluation_seed in NOISE_ROWS:
        path = Path(directory) / f"{stem}.json"
        print(noise_row(label, cohort_seed, resolution, evaluation_seed, path))


def variants(directory):
    """Every report variants.sh writes (NAME-cSEED-v2026.json), in the noise table's form."""
    print(NOISE_HEADER)
    for path in sorted(Path(directory).glob("*-c*-v2026.json")):
        name, cohort_seed = path.stem.removesuffix("-v2026").rsplit("-c", 1)
        print(noise_row(name, cohort_seed, 64, 2026, path))


if __name__ == "__main__":
    if sys.argv[1] == "--noise":
        noise(sys.argv[2])
    elif sys.argv[1] == "--variants":
        variants(sys.argv[2])
    else:
        main(sys.argv[1])
