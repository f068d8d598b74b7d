"""Tables of docs/representative/README.md from the validation reports run.sh writes.

    python3 docs/representative/table.py OUT_DIR/validation
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


if __name__ == "__main__":
    main(sys.argv[1])
