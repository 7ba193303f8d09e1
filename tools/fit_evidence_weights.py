#!/usr/bin/env python3
"""Fits the recognizer's verification score (vision::EvidenceScore) to labelled hypotheses.

Input: the rows that `TEACHSIM_RECOGNIZE_FEATURES=FILE teachsim bench recognize` appends, one per
fitted hypothesis, with the evidence at its fitted pose and the mean distance of its projected
vertices to the nearest true block of its model (a hypothesis is true when that is < 3 px).
Output: the logistic regression's weights, as the C++ constants of EvidenceScore, and how the score
separates true from false hypotheses on every file given (the first is the training set; the rest
are held out). Pure Python (no numpy): L2-regularised logistic regression by Newton's method, the
same objective as scikit-learn's LogisticRegression(C=1, class_weight={0: 1, 1: W}).

Usage: tools/fit_evidence_weights.py [--set render|dev|all] [--true-weight W] TRAIN.tsv [HELD_OUT.tsv ...]
"""
import argparse
import math
import sys

COLUMNS = ("set case model kind outcome accepted best visible matched support coverage supported_px rms "
           "rms_closest matches cont long_cont fixed_share free_support free_coverage free_supported_px "
           "polarity edges_supported edges_visible score step_supported_px centre_x centre_y").split()
NUMERIC = [c for c in COLUMNS[3:] if c != "outcome"]
# The features, in EvidenceScore's order (recognition_stages.h): what the score is a function of.
FEATURES = ["matched", "support", "coverage", "rms", "rms_closest", "cont", "long_cont", "fixed_share",
            "free_support", "free_coverage", "polarity", "edges_supported_fraction", "edges_visible",
            "edges_supported"]
OUTCOME_IMPLAUSIBLE = "implausible"  # culled whatever the score (RecognitionTrace::Outcome::kImplausible)


def features(row):
    visible = max(row["edges_visible"], 1)
    return [row["matched"], row["support"], row["coverage"], min(row["rms"], 4.0), min(row["rms_closest"], 4.0),
            row["cont"], row["long_cont"], row["fixed_share"], row["free_support"], row["free_coverage"],
            row["polarity"], row["edges_supported"] / visible, row["edges_visible"], row["edges_supported"]]


def load(path, which):
    rows = []
    try:
        f = open(path)
    except OSError as e:
        sys.exit(f"{path}: cannot read: {e.strerror}")
    with f:
        for number, line in enumerate(f, 1):
            fields = line.rstrip("\n").split("\t")
            if len(fields) != len(COLUMNS):
                sys.exit(f"{path}:{number}: {len(fields)} fields, expected {len(COLUMNS)}")
            row = dict(zip(COLUMNS, fields))
            for key in NUMERIC:
                try:
                    row[key] = float(row[key])
                except ValueError:
                    sys.exit(f"{path}:{number}: column '{key}' is '{row[key]}', not a number")
            if which != "all" and row["set"] != which:
                continue
            if row["outcome"] == OUTCOME_IMPLAUSIBLE:
                continue
            rows.append(row)
    return rows


def solve(a, b):
    """Gaussian elimination with partial pivoting: a x = b (a is n x n)."""
    n = len(b)
    m = [list(a[i]) + [b[i]] for i in range(n)]
    for c in range(n):
        p = max(range(c, n), key=lambda r: abs(m[r][c]))
        m[c], m[p] = m[p], m[c]
        for r in range(c + 1, n):
            f = m[r][c] / m[c][c]
            for k in range(c, n + 1):
                m[r][k] -= f * m[c][k]
    x = [0.0] * n
    for r in range(n - 1, -1, -1):
        x[r] = (m[r][n] - sum(m[r][k] * x[k] for k in range(r + 1, n))) / m[r][r]
    return x


def fit(xs, ys, true_weight, c=1.0):
    """Minimises 0.5 |w|^2 / c + sum_i s_i log(1 + exp(-y_i (w x_i + b))), y in {-1, 1}; b unpenalised."""
    n = len(xs[0])
    w = [0.0] * (n + 1)  # last: the intercept
    for _ in range(50):
        grad = [wi / c for wi in w[:n]] + [0.0]
        hess = [[(1.0 / c if i == j and i < n else 0.0) for j in range(n + 1)] for i in range(n + 1)]
        for x, y in zip(xs, ys):
            s = true_weight if y > 0 else 1.0
            z = sum(wi * xi for wi, xi in zip(w, x)) + w[n]
            p = 1 / (1 + math.exp(-z))
            g = s * (p - (1 if y > 0 else 0))
            h = s * p * (1 - p)
            xe = x + [1.0]
            for i in range(n + 1):
                grad[i] += g * xe[i]
                hi = h * xe[i]
                row = hess[i]
                for j in range(n + 1):
                    row[j] += hi * xe[j]
        step = solve(hess, grad)
        w = [wi - si for wi, si in zip(w, step)]
        if max(abs(si) for si in step) < 1e-10:
            break
    return w


def score(w, x):
    z = sum(wi * xi for wi, xi in zip(w, x)) + w[-1]
    return 1 / (1 + math.exp(-z))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", default="render", choices=["render", "dev", "all"], help="rows used for fitting")
    parser.add_argument("--true-weight", type=float, default=5.0, help="class weight of the true hypotheses")
    parser.add_argument("train")
    parser.add_argument("held_out", nargs="*")
    args = parser.parse_args()
    rows = load(args.train, args.set)
    if not rows or all(r["best"] >= 3 for r in rows) or all(r["best"] < 3 for r in rows):
        sys.exit(f"{args.train}: no rows of set '{args.set}' with both true and false hypotheses to fit")
    xs = [features(r) for r in rows]
    ys = [1 if r["best"] < 3 else -1 for r in rows]
    print(f"fitting on {len(rows)} hypotheses ({sum(y > 0 for y in ys)} true) of {args.train} [{args.set}]")
    w = fit(xs, ys, args.true_weight)
    print("// EvidenceScore's weights (tools/fit_evidence_weights.py):")
    for name, wi in zip(FEATURES, w):
        print(f"//   {name:26s} {wi:+.4f}")
    print(f"//   {'intercept':26s} {w[-1]:+.4f}")
    print("{" + ", ".join(f"{wi:.4f}" for wi in w[:-1]) + "}, intercept " + f"{w[-1]:.4f}")
    for path in [args.train] + args.held_out:
        for which in ("render", "dev"):
            test = load(path, which)
            if not test:
                continue
            true_rows = [r for r in test if r["best"] < 3]
            false_rows = [r for r in test if r["best"] >= 10]
            line = [f"{path} [{which}]: {len(true_rows)} true, {len(false_rows)} false (>= 10 px off)"]
            for t in (0.2, 0.5, 0.8):
                tp = sum(score(w, features(r)) > t for r in true_rows)
                fp = sum(score(w, features(r)) > t for r in false_rows)
                line.append(f"score > {t}: {tp} true, {fp} false")
            print("; ".join(line))


if __name__ == "__main__":
    main()
